"""``unity-stub-env --task T --play POLICY --video FILE``: play a policy in-process and film it.

No trainer and no socket: the task is built here (one area, ``--seed``, ``--env-param``), stepped
with Unity's decision semantics (a decision every ``decision_period`` control steps, the action held
in between; an agent whose episode ends starts the next at once) and filmed at ``--fps`` frames
per second of simulated time by a camera on agent ``--agent``. POLICY: a trained ``.onnx``
(onnxruntime; the deterministic actions unless ``--stochastic``), ``zero``, ``random`` or
``scripted`` (a task's hand-written expert, ``unity_stub_env.record_demo.SCRIPTED``).

The caption: task, simulated time, the followed agent's episode count, its step in the episode and
its return so far (the sum of the rewards a trainer would see: its own plus its group's; for a task
that sets its reward every step, the last one of each decision period, as the academy sends it).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from unity_stub_env.render import RenderError
from unity_stub_env.render.video import VideoWriter, caption, check_output

DEFAULT_SECONDS = 10.0
MAX_SECONDS = 600.0  # --episodes: stop here even if the agent is still in its episode


@dataclass
class PlayResult:
    frames: int = 0
    steps: int = 0
    episode_returns: list[float] = field(default_factory=list)  # the followed agent's finished episodes


def make_policy(policy: str, task, seed: int, stochastic: bool = False) -> Callable:
    """act(obs list, mask or None) -> (continuous float32 [n, c], discrete int32 [n, b])."""
    from unity_stub_env.record_demo import SCRIPTED, RecordError, onnx_policy

    spec, n = task.action_spec, task.num_agents
    branches = list(spec.discrete_branches)
    if policy == "zero":
        return lambda obs, mask: (np.zeros((n, spec.continuous_size), np.float32), np.zeros((n, len(branches)), np.int32))
    if policy == "random":
        rng = np.random.default_rng(seed)

        def act(obs, mask):
            continuous = rng.uniform(-1.0, 1.0, (n, spec.continuous_size)).astype(np.float32)
            discrete = np.zeros((n, len(branches)), np.int32)
            start = 0
            for b, size in enumerate(branches):  # uniform over each branch's allowed actions
                allowed = np.ones((n, size), bool) if mask is None else ~np.asarray(mask, bool)[:, start:start + size]
                allowed[~allowed.any(axis=1)] = True
                weights = allowed / allowed.sum(axis=1, keepdims=True)
                discrete[:, b] = (weights.cumsum(axis=1) < rng.random((n, 1))).sum(axis=1)
                start += size
            return continuous, discrete
        return act
    if policy == "scripted":
        if task.name not in SCRIPTED:
            raise RenderError(f"--play scripted: task {task.name!r} has no scripted expert (tasks with one: "
                              f"{', '.join(sorted(SCRIPTED))}); pass a trained .onnx, zero or random")
        return SCRIPTED[task.name](task)
    if not policy.endswith(".onnx") and not Path(policy).is_file():
        raise RenderError(f"--play {policy!r}: unknown policy; pass a trained MODEL.onnx, zero, random or scripted")
    try:
        return onnx_policy(policy, task, stochastic)
    except RecordError as error:
        raise RenderError(str(error).replace("--policy", "--play")) from None


def make_view(task, agent: int, width: int, height: int, samples: int = 4):
    if task.name == "runner":
        from unity_stub_env.render.runner_view import RunnerView

        return RunnerView(task, agent, width, height)
    from unity_stub_env.render.scene import SHOTS, MujocoView

    if task.name not in SHOTS:
        raise RenderError(f"task {task.name!r} has no scene to film; tasks with one: "
                          f"{', '.join(sorted([*SHOTS, 'runner']))}")
    return MujocoView(task, agent, width, height, samples)


def _control_dt(task) -> float | None:
    """Simulated seconds per control step: runner's DT; None for a MuJoCo task, whose clock
    (``data.time``) is read around the first step (each task sets its own substeps)."""
    if task.name == "runner":
        from unity_stub_env.tasks.runner import DT

        return DT
    return None


class Player:
    """Steps a task with a policy and hands out captioned frames of one agent."""

    def __init__(self, task, act: Callable, agent: int, width: int, height: int, label: str,
                 samples: int = 4, decision_period: int | None = None) -> None:
        if not 0 <= agent < task.num_agents:
            raise RenderError(f"--agent {agent}: task {task.name!r} has agents 0..{task.num_agents - 1} in one area")
        if decision_period is not None and decision_period < 1:
            raise RenderError(f"--decision-period must be 1 or more, got {decision_period}")
        self.task, self.act, self.agent, self.label = task, act, agent, label
        self.period = int(decision_period or task.decision_period)  # the stub's --decision-period, as the academy
        self.view = make_view(task, agent, width, height, samples)
        spec = task.action_spec
        self.continuous = np.zeros((task.num_agents, spec.continuous_size), np.float32)
        self.discrete = np.zeros((task.num_agents, len(spec.discrete_branches)), np.int32)
        self.dt = _control_dt(task)
        self.time = 0.0
        self.steps = 0
        self.episode, self.episode_step, self.episode_return, self.pending = 1, 0, 0.0, 0.0
        self.returns: list[float] = []

    def step(self) -> None:
        task, k = self.task, self.agent
        if self.steps % self.period == 0:
            self.continuous[:], self.discrete[:] = self.act(task.observe(), task.action_mask())
        clock = getattr(getattr(task, "data", None), "time", None)
        result = task.step(self.continuous, self.discrete)
        if self.dt is None:
            self.dt = float(task.data.time - clock)
        self.time += self.dt
        self.steps += 1
        self.episode_step += 1
        reward = float(result.rewards[k]) + (0.0 if result.group_rewards is None else float(result.group_rewards[k]))
        self.pending = reward if task.sets_reward else self.pending + reward
        decision_end = self.steps % self.period == 0
        if decision_end or result.done[k]:
            self.episode_return += self.pending
            self.pending = 0.0
        if result.done.any():
            if result.done[k]:
                self.returns.append(self.episode_return)
                self.episode, self.episode_step, self.episode_return = self.episode + 1, 0, 0.0
            task.reset(result.done)
            self.continuous[result.done] = 0.0
            self.discrete[result.done] = 0

    def frame(self) -> np.ndarray:
        text = (f"{self.label}  t {self.time:5.2f} s  episode {self.episode}  step {self.episode_step}  "
                f"return {self.episode_return:+.2f}")
        return caption(self.view.frame(), text)

    def close(self) -> None:
        self.view.close()


def film(player: Player, writer, fps: float, seconds: float | None = None, episodes: int | None = None,
         on_frame: Callable | None = None) -> PlayResult:
    """Frames at ``fps`` per simulated second until ``seconds`` or the followed agent's ``episodes``."""
    total = None if seconds is None else max(1, int(round(seconds * fps)))
    result = PlayResult()
    index = 0
    while True:
        while player.time < index / fps - 1e-9:
            player.step()
            if episodes is not None and len(player.returns) >= episodes:
                break
        if episodes is not None and len(player.returns) >= episodes and index > 0:
            break
        frame = player.frame()
        writer.append(frame)
        if on_frame is not None:
            on_frame(index, frame)
        index += 1
        if total is not None and index >= total:
            break
        if episodes is not None and player.time >= MAX_SECONDS:
            break
    result.frames, result.steps, result.episode_returns = index, player.steps, list(player.returns)
    return result


def play(task_name: str, policy: str, video: str, seconds: float | None = None, episodes: int | None = None,
         width: int = 640, height: int = 480, fps: float = 30.0, seed: int = 0, env_params: list[str] | None = None,
         agent: int = 0, stochastic: bool = False, tensorboard: tuple[str, str, int] | None = None,
         samples: int = 4, side_channel: bytes = b"", agents_per_area: int | None = None,
         decision_period: int | None = None) -> PlayResult:
    """Film ``policy`` playing ``task_name`` to ``video``; RenderError for anything unusable.
    ``tensorboard`` (folder, tag, step): also write the clip as an animated image summary there.
    ``side_channel``: side-channel messages as a trainer sends them (a training run's environment
    parameters, applied after ``env_params``); ``agents_per_area`` and ``decision_period``: the
    stub's options of those names."""
    from protos.errors import ProtocolError
    from unity_stub_env.communicator import SideChannelState
    from unity_stub_env.record_demo import RecordError, parse_env_params
    from unity_stub_env.tasks import make_task

    if width < 16 or height < 16 or width % 2 or height % 2:
        raise RenderError(f"--width {width} --height {height}: both must be even and at least 16")
    if not fps > 0:
        raise RenderError(f"--fps must be positive, got {fps}")
    if seconds is not None and not seconds > 0:
        raise RenderError(f"--seconds must be positive, got {seconds}")
    if episodes is not None and episodes < 1:
        raise RenderError(f"--episodes must be 1 or more, got {episodes}")
    if seconds is None and episodes is None:
        seconds = DEFAULT_SECONDS
    check_output(video)
    try:
        params = parse_env_params(env_params)
        SideChannelState(params).apply(side_channel)
        task = make_task(task_name, num_areas=1, seed=seed, env_params=params, agents_per_area=agents_per_area)
    except (RecordError, ProtocolError, ValueError) as error:
        raise RenderError(str(error)) from None
    act = make_policy(policy, task, seed, stochastic)
    label = f"{task_name} / {Path(policy).stem if policy.endswith('.onnx') else policy}"
    player = Player(task, act, agent, width, height, label, samples, decision_period)
    writer = VideoWriter(video, fps)
    gif = None
    if tensorboard is not None:
        from unity_stub_env.render.tensorboard_clip import GifFrames

        gif = GifFrames()
    try:
        result = film(player, writer, fps, seconds, episodes, on_frame=gif)
    finally:
        writer.close()
        player.close()
    if tensorboard is not None:
        from unity_stub_env.render.tensorboard_clip import write_clip_summary

        write_clip_summary(*tensorboard, gif.frames, fps)
    return result


def run(args) -> int:
    """The CLI's ``--play``: one line of result; exit 2 with one message for bad input."""
    import sys

    try:
        tensorboard = None if args.tensorboard is None else (args.tensorboard, args.tensorboard_tag,
                                                             args.tensorboard_step)
        result = play(args.tasks[0], args.play, args.video, args.seconds, args.episodes, args.width, args.height,
                      args.fps, args.seed or 0, args.env_params, args.agent, args.stochastic, tensorboard,
                      args.antialias)
    except RenderError as error:
        print(f"unity-stub-env: {error}", file=sys.stderr)
        return 2
    finished = ", ".join(f"{r:+.2f}" for r in result.episode_returns) or "none finished"
    print(f"Wrote {args.video}: {result.frames} frames ({result.frames / args.fps:.1f} s at {args.fps:g} fps), "
          f"{result.steps} control steps; agent {args.agent}'s episode returns: {finished}")
    return 0

