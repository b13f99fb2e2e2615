"""One seeded session of ``<package>.environment.UnityEnvironment`` with a stub build, step by step.

Runs under EITHER package, named in the options: the real ``mlagents_envs`` 1.1.0 (in
.venv-interop, with no project code on its path) or ``mlagents_like_envs`` (in the project's
venv). Every module is imported by ``<package>.<mlagents_envs' module path>``, so the script is
also a check that the two have the same module paths and names.

The actions come from ``numpy.random.default_rng(action_seed)``, drawn per behavior in name
order, so both runs send the same actions as long as they see the same agents. Every third step
one agent's action is set again with ``set_action_for_agent``.

Prints one JSON object on the last stdout line:
  specs_before_reset, specs   {name: spec} after construction and after reset
  steps       per reset/step: {behavior: {"decision": {...}, "terminal": {...}}} with every field
              as lists (agent_id, reward, obs, group_id, group_reward, action_mask / interrupted)
  dtypes      {field: dtype name} of the first behavior's first non-empty DecisionSteps/TerminalSteps
  stats       {key: [[value, aggregation], ...]} from the StatsSideChannel
  errors      the exception class names of deliberate mistakes (see MISTAKES)

Usage: python envs_api_episode.py '{"package": "mlagents_envs", "file_name": ".../StubBall3d.x86_64",
        "base_port": 5123, "seed": 3, "steps": 60, "action_seed": 7,
        "float_parameters": {"gravity": 9.81}, "time_scale": 20.0}'
"""
import importlib
import json
import sys

import numpy as np

options = json.loads(sys.argv[1])
package = options["package"]


def module(path):
    return importlib.import_module(f"{package}.{path}")


environment = module("environment")
base_env = module("base_env")
exception = module("exception")
engine = module("side_channel.engine_configuration_channel")
parameters = module("side_channel.environment_parameters_channel")
stats_module = module("side_channel.stats_side_channel")
ActionTuple = base_env.ActionTuple


def spec_json(spec):
    return {"observation_specs": [{"shape": list(o.shape), "dimension_property": [int(p) for p in o.dimension_property],
                                   "observation_type": int(o.observation_type.value), "name": o.name}
                                  for o in spec.observation_specs],
            "action_spec": {"continuous_size": spec.action_spec.continuous_size,
                            "discrete_branches": list(spec.action_spec.discrete_branches),
                            "discrete_size": spec.action_spec.discrete_size}}


def as_list(value):
    return np.asarray(value).tolist()


def steps_json(steps, terminal):
    out = {"len": len(steps), "agent_id": as_list(steps.agent_id), "reward": as_list(steps.reward),
           "obs": [as_list(o) for o in steps.obs], "group_id": as_list(steps.group_id),
           "group_reward": as_list(steps.group_reward)}
    if terminal:
        out["interrupted"] = as_list(steps.interrupted)
    else:
        # mlagents_envs sends no mask list when no agent decides; compare the masks of deciding agents
        out["action_mask"] = None if steps.action_mask is None or len(steps) == 0 else [
            as_list(m) for m in steps.action_mask]
    # indexing by agent id: the first agent's single step must match its row
    if len(steps):
        first = steps[steps.agent_id[0]]
        out["first"] = {"reward": float(first.reward), "obs": [as_list(o) for o in first.obs],
                        "group_id": int(first.group_id), "agent_id": int(first.agent_id)}
        if terminal:
            out["first"]["interrupted"] = bool(first.interrupted)
    out["ids_iterated"] = [int(a) for a in steps]
    return out


def dtypes_of(decision, terminal):
    return {"decision.agent_id": str(np.asarray(decision.agent_id).dtype),
            "decision.reward": str(decision.reward.dtype),
            "decision.obs": str(decision.obs[0].dtype),
            "decision.group_id": type(decision.group_id).__name__ + ":" + str(np.asarray(decision.group_id).dtype),
            "decision.group_reward": str(decision.group_reward.dtype),
            "terminal.interrupted": str(terminal.interrupted.dtype)}


engine_channel = engine.EngineConfigurationChannel()
parameter_channel = parameters.EnvironmentParametersChannel()
stats_channel = stats_module.StatsSideChannel()
engine_channel.set_configuration_parameters(time_scale=options.get("time_scale", 20.0))
for key, value in options.get("float_parameters", {}).items():
    parameter_channel.set_float_parameter(key, value)

env = environment.UnityEnvironment(file_name=options["file_name"], base_port=options["base_port"],
                                   seed=options["seed"], no_graphics=True, timeout_wait=60,
                                   side_channels=[engine_channel, parameter_channel, stats_channel])
result = {"specs_before_reset": {name: spec_json(spec) for name, spec in env.behavior_specs.items()},
          "steps": [], "errors": {}}
rng = np.random.default_rng(options["action_seed"])
dtypes = None
env.reset()
result["specs"] = {name: spec_json(spec) for name, spec in sorted(env.behavior_specs.items())}
for step in range(options["steps"] + 1):
    record = {}
    for name in sorted(env.behavior_specs):
        decision, terminal = env.get_steps(name)
        record[name] = {"decision": steps_json(decision, False), "terminal": steps_json(terminal, True)}
        if dtypes is None and len(decision) and len(terminal):
            dtypes = dtypes_of(decision, terminal)
    result["steps"].append(record)
    if step == options["steps"]:
        break
    for name in sorted(env.behavior_specs):
        spec = env.behavior_specs[name].action_spec
        n = len(env.get_steps(name)[0])
        continuous = rng.uniform(-1.0, 1.0, size=(n, spec.continuous_size)).astype(np.float32)
        discrete = np.column_stack([rng.integers(0, b, size=n) for b in spec.discrete_branches]).astype(np.int32) \
            if spec.discrete_branches else np.zeros((n, 0), np.int32)
        env.set_actions(name, ActionTuple(continuous=continuous, discrete=discrete))
        if n and step % 3 == 0:
            agent = env.get_steps(name)[0].agent_id[-1]
            one = ActionTuple(continuous=-continuous[-1:], discrete=discrete[-1:])
            env.set_action_for_agent(name, agent, one)
    env.step()

# MISTAKES: what each package raises for the same misuse
name = sorted(env.behavior_specs)[0]
spec = env.behavior_specs[name].action_spec
n = len(env.get_steps(name)[0])
for label, call in {
    "unknown behavior": lambda: env.get_steps("NoSuchBehavior?team=0"),
    "wrong continuous shape": lambda: env.set_actions(
        name, ActionTuple(continuous=np.zeros((n + 1, spec.continuous_size + 1), np.float32),
                          discrete=np.zeros((n + 1, spec.discrete_size), np.int32))),
    "agent not deciding": lambda: env.set_action_for_agent(name, 10 ** 6, spec.empty_action(1)),
}.items():
    try:
        call()
        result["errors"][label] = None
    except Exception as error:  # noqa: BLE001 - the class is what is compared
        result["errors"][label] = sorted({cls.__name__ for cls in type(error).__mro__} - {"object", "BaseException"})
result["dtypes"] = dtypes
result["stats"] = {key: [[float(v), int(agg.value)] for v, agg in values]
                   for key, values in stats_channel.get_and_reset_stats().items()}
env.close()
try:
    env.close()
    result["errors"]["second close"] = None
except Exception as error:  # noqa: BLE001
    result["errors"]["second close"] = type(error).__name__
print(json.dumps(result))
