"""``unity-stub-env --task T --record-demo OUT.demo --policy MODEL.onnx|scripted``: a demonstration.

Plays the task without a trainer, the way Unity's Demonstration Recorder records an agent
driven by its heuristic or by a trained model, and writes Unity's ``.demo`` format
(``protos.demo_file``; docs/demonstrations.md). The agent infos are the ones the task would send
a trainer (``Academy.collect_infos``), so a trainer reads them exactly as it reads the wire.

Each file holds one agent stream: every agent's episodes are buffered and written whole, one
after another, so record t's action is the one taken at record t and a record with ``done``
closes its episode. Recording stops after the first whole episode that brings the file to
``--demo-steps`` records; unfinished episodes are dropped.

Policies: ``scripted`` is a hand-written expert (``SCRIPTED``): ``basic`` walks right to the
large goal (the optimal return 0.93), ``ball3d`` is a proportional-derivative controller that
tilts the plate under the ball, ``mimic`` sets the PD targets on the reference clip (the "reference PD"
of ``--evaluate``), and for ``stand`` balances against pushes (``BalanceExpert``, ``--evaluate
scripted``). ``--env-param KEY=NUMBER`` sets environment parameters, e.g. mimic's ``motion``.
``--demo-noise SIGMA`` (continuous actions): the agents act with the policy's action plus Gaussian
noise of std SIGMA (clipped to [-1, 1]) while the file records the policy's own action, as DART
(Laskey et al. 2017) does: the demonstration then also shows how the expert recovers from the
small errors a clone makes (a clone of noise-free mimic demonstrations drifts off the states it
saw and falls; bench/RESULTS.md, mimic2). Rewards are those of the noisy actions.
``MODEL.onnx`` is a model exported by a trainer in the ML-Agents
ONNX contract, run through onnxruntime with its deterministic outputs (the mean / the argmax).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable

import numpy as np

from protos.communicator_objects.agent_action_pb2 import AgentActionProto
from protos.demo_file import DemoWriter
from unity_stub_env.academy import Academy
from unity_stub_env.agents import build_brain_parameters
from unity_stub_env.tasks import EnvironmentParameters, make_task
from unity_stub_env.tasks.ball3d import TILT_RATE
from unity_stub_env.tasks.base import Task

# obs list, action mask (True = masked) or None -> (continuous float32 [n, c], discrete int32 [n, b])
Act = Callable[[list[np.ndarray], "np.ndarray | None"], tuple[np.ndarray, np.ndarray]]

DEFAULT_STEPS = 1000

# ball3d's controller: the target tilt that rolls the ball back to the centre, from its offset and
# velocity (rad per m, rad per m/s); a tilt about x raises the +y edge, a tilt about y lowers +x
BALL3D_POSITION_GAIN = 0.08
BALL3D_VELOCITY_GAIN = 0.12


class RecordError(ValueError):
    """Bad --record-demo arguments: the message names the argument and what to do."""


def _basic_expert(task: Task) -> Act:
    def act(obs, mask):
        n = len(obs[0])
        return np.zeros((n, 0), np.float32), np.full((n, 1), 2, np.int32)  # always right
    return act


def _ball3d_expert(task: Task) -> Act:
    step = task.decision_period * TILT_RATE  # the most the target tilt moves in one decision

    def act(obs, mask):
        o = obs[0]
        tilt, position, velocity = o[:, 0:2], o[:, 2:4], o[:, 5:7]
        want_x = BALL3D_POSITION_GAIN * position[:, 1] + BALL3D_VELOCITY_GAIN * velocity[:, 1]
        want_y = -(BALL3D_POSITION_GAIN * position[:, 0] + BALL3D_VELOCITY_GAIN * velocity[:, 0])
        want = np.stack([want_x, want_y], axis=1)
        continuous = np.clip((want - tilt) / step, -1.0, 1.0).astype(np.float32)
        return continuous, np.zeros((len(o), 0), np.int32)
    return act


def _mimic_expert(task: Task) -> Act:
    """The reference PD: each decision the PD targets are the reference clip's joint angles at the
    frame the decision leads to, through the inverse of the task's action map (the ``motion``
    environment parameter chooses the clip: ``--env-param motion=2``). Agents standing (motion 0)
    in the default absolute mode act with ``BalanceExpert`` instead, the stand pose plus an ankle
    strategy against pushes (``--env-param push_impulse=15``)."""
    from unity_stub_env.tasks.mimic import BalanceExpert

    balance = BalanceExpert()

    def act(obs, mask):
        continuous = task.reference_actions().astype(np.float32)
        standing = (task.motion == 0) & (task.residual == 0)
        if standing.any():
            continuous[standing] = balance(obs[0][standing])
        return continuous, np.zeros((len(continuous), 0), np.int32)
    return act


SCRIPTED: dict[str, Callable[[Task], Act]] = {"basic": _basic_expert, "ball3d": _ball3d_expert,
                                              "mimic": _mimic_expert}


def onnx_policy(path: str, task: Task, stochastic: bool = False) -> Act:
    """The deterministic actions of an exported model (ML-Agents ONNX contract); ``stochastic``:
    the sampled ones instead (the contract's ``continuous_actions`` / ``discrete_actions``)."""
    if not Path(path).is_file():
        raise RecordError(f"--policy {path!r} is neither 'scripted' nor an existing .onnx file")
    try:
        import onnxruntime
    except ImportError:
        raise RecordError("--policy MODEL.onnx needs onnxruntime: pip install onnxruntime") from None
    try:
        session = onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
    except Exception as error:  # onnxruntime raises its own exception types for bad files
        raise RecordError(f"--policy {path!r}: not a loadable ONNX model ({error})") from None
    inputs = {i.name for i in session.get_inputs()}
    outputs = {o.name for o in session.get_outputs()}
    expected = {f"obs_{i}" for i in range(len(task.observation_specs))}
    spec = task.action_spec
    prefix = "" if stochastic else "deterministic_"
    wanted = ([f"{prefix}continuous_actions"] if spec.continuous_size else []) + (
        [f"{prefix}discrete_actions"] if spec.discrete_branches else [])
    if not expected <= inputs or "recurrent_in" in inputs or not set(wanted) <= outputs:
        raise RecordError(f"--policy {path!r} does not fit task {task.name!r}: it takes {sorted(inputs)} and "
                          f"gives {sorted(outputs)}, the task needs inputs {sorted(expected)} and outputs "
                          f"{wanted} (a model without memory, trained on this task)")

    def act(obs, mask):
        feed = {f"obs_{i}": np.asarray(o, np.float32) for i, o in enumerate(obs)}
        if "action_masks" in inputs:
            n = len(obs[0])
            feed["action_masks"] = (np.ones((n, sum(spec.discrete_branches)), np.float32) if mask is None
                                    else (~np.asarray(mask, bool)).astype(np.float32))
        result = dict(zip(wanted, session.run(wanted, feed)))
        n = len(obs[0])
        continuous = np.asarray(result.get(f"{prefix}continuous_actions", np.zeros((n, 0))), np.float32)
        discrete = np.asarray(result.get(f"{prefix}discrete_actions", np.zeros((n, 0))), np.int32)
        return continuous.reshape(n, spec.continuous_size), discrete.reshape(n, len(spec.discrete_branches))
    return act


def _action_proto(continuous: np.ndarray, discrete: np.ndarray) -> AgentActionProto:
    return AgentActionProto(continuous_actions=continuous.tolist(), discrete_actions=discrete.tolist())


def parse_env_params(pairs: list[str] | None) -> EnvironmentParameters:
    """``["motion=2"]`` -> environment parameters holding those constants (as a trainer's
    ``environment_parameters`` would send them); RecordError for anything but KEY=NUMBER."""
    params = EnvironmentParameters()
    for pair in pairs or []:
        key, sep, text = pair.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = None
        if not sep or not key or value is None:
            raise RecordError(f"--env-param {pair!r}: write KEY=NUMBER, e.g. --env-param motion=2")
        params.set(key, lambda value=value: value)
    return params


def record(task_name: str, out_path: str, policy: str, steps: int = DEFAULT_STEPS, seed: int = 0,
           num_areas: int = 1, env_params: list[str] | None = None, noise: float = 0.0) -> tuple[int, int, float]:
    """Write ``out_path``; returns (records, episodes, mean episode return). ``env_params``: KEY=NUMBER
    environment parameters the task reads (``--env-param``); ``noise`` (``--demo-noise``): see the
    module docstring."""
    if steps < 1:
        raise RecordError(f"--demo-steps must be at least 1, got {steps}")
    if not out_path.endswith(".demo"):
        raise RecordError(f"--record-demo {out_path!r}: the file name must end in .demo (trainers read "
                          "only those)")
    if not noise >= 0:
        raise RecordError(f"--demo-noise must be 0 or more, got {noise}")
    rng = np.random.default_rng(seed)
    params = parse_env_params(env_params)
    try:
        task = make_task(task_name, num_areas=num_areas, seed=seed, env_params=params)
    except ValueError as error:  # a task refusing a parameter's value names it
        raise RecordError(f"--env-param: {error}") from None
    folder = os.path.dirname(out_path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    if policy == "scripted":
        if task_name not in SCRIPTED:
            raise RecordError(f"no scripted expert for task {task_name!r} (there is one for "
                              f"{', '.join(sorted(SCRIPTED))}); pass --policy MODEL.onnx")
        act = SCRIPTED[task_name](task)
    else:
        act = onnx_policy(policy, task)
    academy = Academy(task)
    spec = task.action_spec
    no_action = _action_proto(np.zeros(spec.continuous_size, np.float32),
                              np.zeros(len(spec.discrete_branches), np.int32))
    episodes: dict[int, list] = {}  # episode id -> [(agent info, action)] so far
    brain = build_brain_parameters(academy.behavior_key, spec)
    name = Path(out_path).stem
    with DemoWriter(out_path, name, brain) as writer:
        while writer.steps < steps:
            obs, mask = task.observe(), task.action_mask()
            infos = academy.collect_infos()
            continuous, discrete = act(obs, mask)
            actions = [_action_proto(continuous[i], discrete[i]) for i in range(task.num_agents)]
            executed = actions
            if noise > 0 and spec.continuous_size:  # DART: act with noise, record the expert's label
                noisy = np.clip(continuous + rng.normal(0.0, noise, continuous.shape), -1.0, 1.0)
                executed = [_action_proto(noisy[i].astype(np.float32), discrete[i]) for i in range(task.num_agents)]
            deciding = [info for info in infos if not info.done]
            for info in infos:
                if info.done:  # the terminal record closes the episode: the whole episode goes out
                    for pair in episodes.pop(info.id, []):
                        writer.record(*pair)
                    writer.record(info, no_action)
                    if writer.steps >= steps:
                        break
            for info, action in zip(deciding, actions):
                episodes.setdefault(info.id, []).append((info, action))
            academy.apply_actions(executed)
            academy.advance()
        mean = writer.total_reward / writer.episodes if writer.episodes else 0.0
        return writer.steps, writer.episodes, mean


def run(task_name: str, out_path: str, policy: str, steps: int | None, seed: int, num_areas: int | None,
        env_params: list[str] | None = None, noise: float = 0.0) -> int:
    """The CLI's --record-demo: one line of result on stdout; exit code 2 for bad arguments."""
    try:
        count, episodes, mean = record(task_name, out_path, policy, steps or DEFAULT_STEPS, seed, num_areas or 1,
                                       env_params, noise)
    except RecordError as error:
        print(f"unity-stub-env: {error}", file=sys.stderr)
        return 2
    print(f"Recorded {count} steps, {episodes} episodes (mean reward per episode {mean:.3f}) of task "
          f"{task_name!r} with policy {policy!r} to {out_path}")
    return 0
