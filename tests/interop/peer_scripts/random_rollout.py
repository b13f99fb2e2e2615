"""Runs INSIDE .venv-interop (the real mlagents_envs 1.1.0). Never import project code here.

Launches an executable through ``UnityEnvironment``, resets, steps with random actions and prints
one JSON object on the last stdout line:

  behavior_specs  {name: {observation_specs: [{shape, dimension_property, observation_type, name}],
                          action_spec: {continuous_size, discrete_branches}}}
  decision_steps / terminal_steps / interrupted   totals over the reset and all steps
  id_errors       list of id-contract violations seen (empty = fine)
  stats           {key: [[value, aggregation int], ...]} read from the StatsSideChannel
  first_obs       {name: obs[0] of the DecisionSteps after the first env.step(), as nested lists}
  pid, returncode the simulator process and its exit code after env.close()

Usage: python random_rollout.py '{"file_name": ..., "base_port": ..., "steps": 500,
        "env_float_parameters": {"gravity": 0.0}, "engine_config": {"time_scale": 7.0},
        "additional_args": ["-logFile", "/tmp/x.log"], "zero_actions": false}'
("zero_actions": true sends all-zero actions instead of random ones)
"""
import json
import sys
import time

import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.side_channel.engine_configuration_channel import EngineConfigurationChannel
from mlagents_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel
from mlagents_envs.side_channel.stats_side_channel import StatsSideChannel


def spec_as_json(spec):
    return {
        "observation_specs": [
            {"shape": list(o.shape), "dimension_property": [int(p.value) for p in o.dimension_property],
             "observation_type": int(o.observation_type.value), "name": o.name}
            for o in spec.observation_specs
        ],
        "action_spec": {"continuous_size": spec.action_spec.continuous_size,
                        "discrete_branches": list(spec.action_spec.discrete_branches)},
    }


class IdChecker:
    """Episode-id contract: unique ids per step, terminal ids were deciding, ended ids never return."""

    def __init__(self):
        self.deciding = {}  # behavior -> ids that asked for a decision last time
        self.ended = {}
        self.errors = []

    def check(self, name, decision_ids, terminal_ids):
        if len(set(decision_ids)) != len(decision_ids):
            self.errors.append(f"{name}: duplicate decision ids {decision_ids}")
        if len(set(terminal_ids)) != len(terminal_ids):
            self.errors.append(f"{name}: duplicate terminal ids {terminal_ids}")
        previous = self.deciding.get(name, set())
        ended = self.ended.setdefault(name, set())
        for agent_id in terminal_ids:
            if agent_id not in previous:
                self.errors.append(f"{name}: terminal id {agent_id} was not deciding before")
        ended.update(terminal_ids)
        back = ended.intersection(decision_ids)
        if back:
            self.errors.append(f"{name}: ended ids {sorted(back)} asked for a decision again")
        self.deciding[name] = set(decision_ids)


def main():
    options = json.loads(sys.argv[1])
    stats_channel = StatsSideChannel()
    channels = [stats_channel]
    if options.get("env_float_parameters"):
        env_params = EnvironmentParametersChannel()
        for key, value in options["env_float_parameters"].items():
            env_params.set_float_parameter(key, value)
        channels.append(env_params)
    if options.get("engine_config"):
        engine = EngineConfigurationChannel()
        engine.set_configuration_parameters(**options["engine_config"])
        channels.append(engine)
    started = time.monotonic()
    env = UnityEnvironment(
        file_name=options["file_name"], base_port=options["base_port"], no_graphics=True,
        seed=options.get("seed", 1), timeout_wait=options.get("timeout_wait", 60),
        side_channels=channels, additional_args=options.get("additional_args"),
    )
    process = env._process  # kept: close() sets it to None
    try:
        env.reset()
        names = list(env.behavior_specs.keys())
        result = {"behavior_specs": {n: spec_as_json(env.behavior_specs[n]) for n in names},
                  "decision_steps": 0, "terminal_steps": 0, "interrupted": 0, "first_obs": {},
                  "pid": process.pid if process is not None else None}
        checker = IdChecker()
        stats = {}
        for step in range(options.get("steps", 500) + 1):  # the last pass only reads the final steps
            for name in names:
                decision, terminal = env.get_steps(name)
                checker.check(name, [int(i) for i in decision.agent_id], [int(i) for i in terminal.agent_id])
                result["decision_steps"] += len(decision)
                result["terminal_steps"] += len(terminal)
                result["interrupted"] += int(np.sum(terminal.interrupted))
                if step == 1:
                    result["first_obs"][name] = decision.obs[0].tolist()
                if len(decision) > 0:
                    spec = env.behavior_specs[name].action_spec
                    make = spec.empty_action if options.get("zero_actions") else spec.random_action
                    env.set_actions(name, make(len(decision)))
            if step == options.get("steps", 500):
                break
            env.step()
            for key, values in stats_channel.get_and_reset_stats().items():
                stats.setdefault(key, []).extend([float(v), int(agg.value)] for v, agg in values)
        result["seconds"] = time.monotonic() - started
    finally:
        env.close()  # an exception must not leave the simulator and gRPC server running
    result["returncode"] = process.returncode if process is not None else None
    result["id_errors"] = checker.errors[:20]
    result["stats"] = stats
    print(json.dumps(result))


if __name__ == "__main__":
    main()
