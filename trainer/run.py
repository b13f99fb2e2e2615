"""The one training loop: simulators → decisions → trajectories → PPO updates → outputs.

Per iteration (each simulator has just sent its message):
  1. new behaviors get a ``BehaviorRunner`` (trainer, checkpoint bookkeeping);
  2. ONE batched forward pass per behavior computes actions for all deciding agents across all
     envs (the brain's policy, or with self-play a team's snapshot: ``BehaviorRunner.policy_for``);
  3. the actions go out at once, so the simulators step while we work;
  4. meanwhile every agent's experience is assembled (rollout.AgentTracker), trajectories go to
     PPO (GAE, update when the buffer is full), summaries, checkpoints, curriculum; then we wait
     for the simulators' next messages.
"""
from __future__ import annotations

import ipaddress
import logging
import os
import re
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from protos import side_channels as sc
from protos.types import ActionTuple, StatsAggregationMethod, StepResult, brain_name_of
from trainer import crash_points
from trainer.artifacts.atomic import WRITE_ERRNOS, results_write_error
from trainer.artifacts.behaviors import BehaviorRecorder
from trainer.artifacts.console import ConsoleWriter, ProgressLine
from trainer.artifacts.stats import PROPERTY_HYPERPARAMETERS, PROPERTY_SELF_PLAY, GaugeWriter, StatsReporter
from trainer.artifacts.tensorboard import TensorboardWriter
from trainer.artifacts.timers import TimerTree
from trainer.artifacts.training_status import TrainingStatus
from trainer.config.env_params import ConstantSampler, HmmSampler, hmm_model, hmm_sequences
from trainer.config.env_vars import EnvVars
from trainer.config.loader import write_run_options
from trainer.config.settings import settings_as_dict
from trainer.config.support import goal_conditioning_note
from trainer.curriculum import EnvironmentParameterManager
from trainer import warmup
from trainer.distributed import RankLost, Ranks, check_split
from trainer.envs.pool import DEFAULT_EDITOR_PORT, EnvPool, PoolSettings
from trainer.errors import ConfigError, ResultsWriteError, UnityCommunicatorStoppedError, UserError
from trainer.protocol.codec import NON_FINITE_STAT
from trainer.rollout import AgentTracker, GroupTracker, concat_masks
from trainer.selfplay import TeamController
from trainer.stop import EXIT_STOPPED, STOP

if TYPE_CHECKING:  # torch is imported only once the simulators are launched (see run_training)
    from trainer.behavior import BehaviorRunner

logger = logging.getLogger("mlagents_like")


# --------------------------------------------------------------------------------- results dir
def run_dir_of(options) -> str:
    ck = options.checkpoint_settings
    return os.path.join(ck.results_dir, ck.run_id)


_STARTUP_FILES = re.compile(r"configuration\.yaml|run_logs/(timers\.json|training_status\.json|behaviors\.json|Player-\d+\.log)")


def only_startup_files(run_dir: str) -> bool:
    """True if ``run_dir`` holds nothing but what a run writes before its first step (the
    configuration, timers, training status, simulator logs) and no checkpoint, model or
    TensorBoard data: every run that trained leaves those (Ctrl-C and a simulator that stops
    included; they end with a final checkpoint)."""
    for folder, _, files in os.walk(run_dir):
        for name in files:
            relative = os.path.relpath(os.path.join(folder, name), run_dir).replace(os.sep, "/")
            if not _STARTUP_FILES.fullmatch(relative):
                return False
    return True


def prepare_run_dir(options) -> str:
    """results/<run-id>: refuse to clobber an earlier run unless --resume or --force."""
    ck = options.checkpoint_settings
    run_dir = run_dir_of(options)
    exists = os.path.isdir(run_dir) and bool(os.listdir(run_dir))
    if not exists and ck.resume:
        raise UserError(f"--resume was given but {run_dir} does not exist. Start a new run without --resume.")
    if exists and not (ck.resume or ck.force or ck.inference):
        if not only_startup_files(run_dir):
            raise UserError(
                f"Previous data from this run ID was found in {run_dir}. Either use --resume to continue "
                "that run, --force to overwrite it, or pick another --run-id."
            )
        # e.g. a simulator that failed at start: nothing to lose
        logger.info("%s holds only the files of an earlier start that never trained; using it again.", run_dir)
    try:
        os.makedirs(os.path.join(run_dir, "run_logs"), exist_ok=True)
        for folder, _, _ in os.walk(run_dir):  # a folder we cannot write stops us now, not mid-run
            tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        if error.errno in WRITE_ERRNOS:
            raise results_write_error(error.filename or run_dir, error) from None
        raise
    if ck.resume:
        remove_leftover_temp_files(run_dir)
    return run_dir


# the temp files of trainer.artifacts.atomic (tempfile.mkstemp: 8 random letters, digits or _)
_LEFTOVER_TMP = re.compile(r"\..+-[A-Za-z0-9_]{8}\.tmp")


def remove_leftover_temp_files(run_dir: str) -> None:
    """--resume: delete the temp files of writes a killed run did not finish (never read)."""
    removed = []
    for folder, _, files in os.walk(run_dir):
        for name in files:
            if _LEFTOVER_TMP.fullmatch(name):
                os.remove(os.path.join(folder, name))
                removed.append(os.path.relpath(os.path.join(folder, name), run_dir))
    if removed:
        logger.info("Removed %d unfinished temp file(s) of the previous run: %s", len(removed), ", ".join(removed))


def warn_if_not_loopback(bind: str, ports: str) -> None:
    """One warning when the server listens beyond this machine: the gRPC protocol of Unity ML-Agents
    has no authentication, so whoever reaches the port can connect as a simulator."""
    host = bind.strip().strip("[]")
    if host == "localhost":
        return
    try:
        if ipaddress.ip_address(host).is_loopback:
            return
    except ValueError:
        pass
    logger.warning(
        "--bind %s: the trainer listens beyond this machine on port(s) %s. Unity simulators cannot "
        "authenticate, so anyone who can reach these ports can connect and send steps. Keep the default "
        "127.0.0.1 and reach simulators on other nodes through an SSH tunnel or a private network "
        "(README: Simulators on other machines).", bind, ports)


def environment_parameter_messages(manager: EnvironmentParameterManager) -> list[tuple]:
    msgs = []
    for key, sampler in manager.current_samplers().items():
        if isinstance(sampler, HmmSampler):
            codes = hmm_sequences(sampler)
            num_labels = hmm_model(sampler).num_labels
            msgs += [(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, payload)
                     for payload in sc.encode_env_sequences(key, codes, num_labels)]
            continue
        if isinstance(sampler, ConstantSampler):
            payload = sc.encode_env_float(key, sampler.value)
        elif sampler.sampler_type == "uniform":
            payload = sc.encode_env_sampler(key, "uniform", sampler.seed, (sampler.min_value, sampler.max_value))
        elif sampler.sampler_type == "gaussian":
            payload = sc.encode_env_sampler(key, "gaussian", sampler.seed, (sampler.mean, sampler.st_dev))
        else:
            payload = sc.encode_env_sampler(key, "multirangeuniform", sampler.seed, sampler.intervals)
        msgs.append((sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, payload))
    return msgs


def engine_config_messages(engine) -> list[tuple]:
    payloads = sc.encode_engine_config(engine.width, engine.height, engine.quality_level, engine.time_scale,
                                       engine.target_frame_rate, engine.capture_frame_rate)
    return [(sc.ENGINE_CONFIG_CHANNEL_ID, p) for p in payloads]


# --------------------------------------------------------------------------------- the loop
@dataclass
class RunState:
    options: object
    run_dir: str
    pool: EnvPool
    params: EnvironmentParameterManager
    reporter: StatsReporter
    status: TrainingStatus
    timers: TimerTree
    progress: ProgressLine
    routers: list[sc.SideChannelRouter]
    env_vars: EnvVars = field(default_factory=EnvVars)
    recorder: BehaviorRecorder | None = None  # run_logs/behaviors.json
    ranks: Ranks = field(default_factory=Ranks)  # data-parallel ranks (trainer/distributed.py)
    runners: dict[str, BehaviorRunner] = field(default_factory=dict)
    trackers: dict[tuple[int, str], AgentTracker] = field(default_factory=dict)
    pending_reset: bool = False
    teams: TeamController = field(default_factory=TeamController)  # self-play's learning team
    start_time: float = field(default_factory=time.time)
    _last_progress: float = float("-inf")
    stepped: bool = False  # the first actions were sent (a start-up mark: bench/startup.py)
    updated: bool = False  # the first update was made (likewise)

    # ------------------------------------------------------------------ behaviors
    def ensure_runner(self, behavior_name: str) -> BehaviorRunner:
        brain, _team = brain_name_of(behavior_name)
        runner = self.runners.get(brain)
        if runner is not None:
            return runner
        spec = self.pool.behavior_specs()[behavior_name]  # merged over the workers: only for a new brain
        from trainer.behavior import BehaviorRunner

        opts = self.options
        logger.info("Connected new brain: %s", behavior_name)
        settings = opts.behavior_settings(brain)
        if settings.threaded:
            logger.warning("%s: threaded: true is accepted but has no effect here; updates run between "
                           "environment steps, as with threaded: false (same results, no policy lag).",
                           brain)
        note = goal_conditioning_note(spec.observation_specs, settings)
        if note:
            logger.warning("%s: %s", brain, note)
        ck = opts.checkpoint_settings
        seed = opts.env_settings.seed + len(self.runners)
        # with data-parallel ranks, this rank's share of buffer_size and batch_size (trainer/distributed.py)
        runner = BehaviorRunner.create(brain, spec, self.ranks.settings_for(settings, brain), self.run_dir, seed,
                                       opts.torch_settings.device or "cpu", training=not ck.inference,
                                       use_numpy_update=self.env_vars.numpy_update, teams=self.teams)
        if not self.ranks.is_main:
            pass  # rank 0 restores and sends its state to this rank (Ranks.agree)
        elif ck.resume and not ck.inference:
            runner.resume(self.status)  # the newest checkpoint that verifies; the folder tidied for it
            self.save_status()
        elif ck.resume or (ck.inference and os.path.isfile(runner.paths.latest)):
            runner.restore(runner.paths.latest, reset_step=False)
        elif settings.init_path:
            runner.restore(settings.init_path, reset_step=True)
        runner.schedule_from_step()
        self.ranks.adopt(runner)
        if ck.resume and not ck.inference:
            # what a run killed without warning wrote after its last checkpoint is void
            self.reporter.resume_from(brain, runner.next_summary - 1)
        self.runners[brain] = runner
        self.reporter.add_property(brain, PROPERTY_HYPERPARAMETERS, settings_as_dict(settings))
        if runner.self_play is not None:
            self.reporter.add_property(brain, PROPERTY_SELF_PLAY, True)
        return runner

    # ------------------------------------------------------------------ decisions
    def decide(self, results: list[StepResult]) -> tuple[list[dict[str, ActionTuple]], list]:
        """Actions for every deciding agent: ONE forward pass per behavior across all envs.

        Returns (actions per env, the decisions to ``record`` once the actions are sent). Nothing
        here touches the experience trackers, so the simulators wait only for the policy.
        """
        actions: list[dict[str, ActionTuple]] = [{} for _ in results]
        decided: list = []
        by_behavior: dict[str, list[int]] = {}
        for env_id, res in enumerate(results):
            for behavior in res.steps:
                by_behavior.setdefault(behavior, []).append(env_id)
        for behavior, env_ids in by_behavior.items():
            runner = self.ensure_runner(behavior)
            policy = runner.policy_for(brain_name_of(behavior)[1])  # self-play: maybe a snapshot
            # each env's deciding agents are the rows [start, end) of the one batched forward pass
            steps, start = [], 0
            for env_id in env_ids:
                decision, terminal = results[env_id].steps[behavior]
                steps.append((env_id, decision, terminal, slice(start, start + len(decision))))
                start += len(decision)
            out = masks = memories = None
            if start:
                out, masks, memories = self._act(runner, policy, behavior, [s for s in steps if len(s[1])])
                for env_id, decision, _, rows in steps:
                    if len(decision):
                        actions[env_id][behavior] = ActionTuple(out.env_actions.continuous[rows],
                                                                out.env_actions.discrete[rows])
            decided.append((runner, behavior, steps, out, masks, memories))
        return actions, decided

    def _act(self, runner: BehaviorRunner, policy, behavior: str, steps: list):
        """One forward pass of ``policy`` for the deciding agents of ``steps`` (each env's (env_id,
        decision, terminal, rows)). Returns (policy output, masks, the memories it started from or None)."""
        spec = runner.spec
        branches = spec.action_spec.discrete_branches
        deciding = [decision for _, decision, _, _ in steps]
        if len(deciding) == 1:
            obs = deciding[0].obs
            masks = concat_masks(deciding[0], branches)
        else:
            obs = [np.concatenate([d.obs[i] for d in deciding]) for i in range(len(spec.observation_specs))]
            ms = [concat_masks(d, branches) for d in deciding]
            masks = None if ms[0] is None else np.concatenate(ms)
        memories = None
        crash_points.reached("act")
        if policy.memory_size:  # each agent continues from its own LSTM state
            memories = np.concatenate([self._tracker(env_id, behavior, runner).memories_for(decision.agent_id)
                                       for env_id, decision, _, _ in steps])
        with self.timers.scope("policy.act"):
            out = policy.act(obs, masks, deterministic=runner.settings.network_settings.deterministic,
                             memories=memories)
        return out, masks, memories

    def _tracker(self, env_id: int, behavior: str, runner: BehaviorRunner) -> AgentTracker:
        tracker = self.trackers.get((env_id, behavior))
        if tracker is None:
            kind = GroupTracker if getattr(runner.trainer, "uses_groups", False) else AgentTracker  # POCA
            tracker = kind(runner.spec, runner.settings.time_horizon, memory_size=runner.trainer.policy.memory_size)
            self.trackers[(env_id, behavior)] = tracker
        return tracker

    def record(self, decided: list, trajectories: list) -> None:
        """Experience assembly for the decisions of ``decide`` (after their actions went out):
        rewards paired with the previous actions, finished trajectories appended to
        ``trajectories``, the new observations and actions remembered, episode statistics."""
        for runner, behavior, steps, out, masks, memories in decided:
            learns = runner.learns_from(brain_name_of(behavior)[1])
            if learns:
                emit = lambda t, r=runner: trajectories.append((r, t))  # noqa: E731
            else:  # a self-play team playing a snapshot: its experience is only counted
                emit = lambda t, r=runner: r.self_play.count_ghost_steps(len(t))  # noqa: E731
            for env_id, decision, terminal, rows in steps:
                tracker = self._tracker(env_id, behavior, runner)
                slots = tracker.on_step(terminal, decision, emit)
                if learns:
                    runner.add_episodes(tracker.episodes.rewards)
                self._episode_stats(runner.brain, tracker)
                if len(decision):
                    tracker.on_actions(slots, out.continuous_raw[rows], out.discrete[rows],
                                       out.log_probs[rows], None if masks is None else masks[rows],
                                       None if memories is None else memories[rows],
                                       None if memories is None else out.memories[rows])

    def _episode_stats(self, brain: str, tracker: AgentTracker) -> None:
        eps = tracker.drain_episodes()
        if eps.rewards:
            rewards = np.asarray(eps.rewards, dtype=np.float64)
            self.reporter.add_many(brain, "Environment/Cumulative Reward", rewards, StatsAggregationMethod.AVERAGE)
            self.reporter.add_many(brain, "Environment/Episode Length", np.asarray(eps.lengths, np.float64),
                                   StatsAggregationMethod.AVERAGE)
            extrinsic = self.runners[brain].settings.reward_signals.get("extrinsic")
            if extrinsic is not None:  # as ML-Agents: what the extrinsic signal paid, group rewards included
                paid = extrinsic.strength * (rewards + np.asarray(eps.group_rewards, dtype=np.float64))
                self.reporter.add_many(brain, "Policy/Extrinsic Reward", paid, StatsAggregationMethod.AVERAGE)
        if eps.group_returns:  # GroupTracker (POCA): agents whose whole group had finished with them
            self.reporter.add_many(brain, "Environment/Group Cumulative Reward", np.asarray(eps.group_returns, np.float64),
                                   StatsAggregationMethod.HISTOGRAM)  # as the reference: the mean and a histogram

    # ------------------------------------------------------------------ learning
    def learn(self, trajectories: list) -> None:
        for runner, traj in trajectories:
            before = runner.last_checkpoint_step
            with self.timers.scope("process_trajectory"):
                stats = runner.add_trajectory(traj, self.status)
            if runner.last_checkpoint_step != before:
                self.save_status()  # with every checkpoint: a kill right after loses nothing
                crash_points.reached("checkpoint.status")
            for key, value in stats.items():
                self.reporter.add(runner.brain, key, float(value), StatsAggregationMethod.AVERAGE)
        updates = self.ranks.agree(self.runners)  # {brain: rows} to update now; alone: who is ready
        for brain, runner in sorted(self.runners.items()):  # one order on every rank
            if brain in updates:
                crash_points.reached("update")
                with self.timers.scope("update"):
                    stats = runner.trainer.update(updates[brain])
                if not self.updated:
                    self.updated = True
                    logger.debug("Start-up: first update done.")
                crash_points.reached("update.done")
                self.ranks.after_update(runner)
                for key, value in stats.items():
                    self.reporter.add(runner.brain, key, float(value), StatsAggregationMethod.AVERAGE)
            if runner.self_play is not None and not runner.done and runner.self_play.advance(runner.trainer.step):
                self.pending_reset = True  # a new learning team starts from fresh episodes
            self._maybe_summarize(runner)
        self._update_curriculum()

    def save_status(self) -> None:
        """training_status.json with the checkpoints and the curriculum's lessons as they are now.
        Written with every periodic checkpoint too: a run killed without warning (SIGKILL, a node
        failure) resumes from its last checkpoint with the lessons it had then."""
        for name, lesson in self.params.lesson_numbers().items():
            self.status.set_lesson_num(name, lesson)
        self.status.save(os.path.join(self.run_dir, "run_logs", "training_status.json"))

    def _maybe_summarize(self, runner: BehaviorRunner) -> None:
        step = runner.trainer.step
        if step >= runner.next_summary:
            self._summarize(runner)
            while runner.next_summary <= step:
                runner.next_summary += runner.settings.summary_freq

    def _summarize(self, runner: BehaviorRunner) -> None:
        for name, lesson in self.params.lesson_numbers().items():
            self.reporter.add(runner.brain, f"Environment/Lesson Number/{name}", float(lesson),
                              StatsAggregationMethod.MOST_RECENT)
        self.reporter.set(runner.brain, "Step", float(runner.trainer.step))  # hidden from TensorBoard, a gauge
        self.ranks.gather_stats(self.reporter, runner.brain)
        self.reporter.write(runner.brain, runner.next_summary, is_training=runner.training and not runner.done)

    def summarize_partial(self) -> None:
        """A stop before max_steps: the summary of the unfinished period now, under its label, so
        the resumed run (which starts with the next period) neither repeats nor skips a label."""
        for _, runner in sorted(self.runners.items()):  # one order on every rank
            period_start = runner.next_summary - runner.settings.summary_freq
            if runner.training and not runner.done and runner.trainer.step > period_start:
                logger.info("%s: summary of the unfinished period up to step %d, labelled %d.",
                            runner.brain, runner.trainer.step, runner.next_summary)
                self._summarize(runner)
                runner.next_summary += runner.settings.summary_freq

    def _update_curriculum(self) -> None:
        if not self.params.settings:
            return
        steps = {b: r.trainer.step for b, r in self.runners.items()}
        max_steps = {b: r.max_steps for b, r in self.runners.items()}
        buffers = {b: list(r.reward_buffer) for b, r in self.runners.items()}
        updated, must_reset = self.params.update_lessons(steps, max_steps, buffers)
        if updated:
            for r in self.runners.values():
                r.reward_buffer.clear()
            for router in self.routers:
                for cid, payload in environment_parameter_messages(self.params):
                    router.queue(cid, payload)
            self.pending_reset = self.pending_reset or must_reset

    def count_dropped(self, results: list[StepResult], trajectories: list) -> None:
        """Agent steps the codec left out for NaN/Inf (trainer/protocol/codec.py), summed into
        each brain's summaries; the episodes whose last step was one of them are ended
        (``AgentTracker.on_lost_terminal``), their last trajectory appended to ``trajectories``."""
        for env_id, res in enumerate(results):
            for behavior, dropped in res.dropped.items():
                self.reporter.add(brain_name_of(behavior)[0], NON_FINITE_STAT, dropped.count,
                                  StatsAggregationMethod.SUM)
                tracker = self.trackers.get((env_id, behavior)) if len(dropped.ended) else None
                if tracker is not None:
                    runner = self.ensure_runner(behavior)
                    tracker.on_lost_terminal(dropped.ended, lambda t, r=runner: trajectories.append((r, t)))

    # ------------------------------------------------------------------ side channels
    def side_channel_in(self, results: list[StepResult]) -> None:
        brains = None  # the brains of this step, once some simulator sent stats
        for env_id, res in enumerate(results):
            if not res.side_channel:
                continue
            incoming = self.routers[env_id].dispatch(res.side_channel)
            if incoming.stats and self.recorder is not None:
                self.recorder.observe_stats(key for key, _, _ in incoming.stats)
            if incoming.stats:
                if brains is None:
                    brains = {brain_name_of(b)[0] for r in results for b in r.steps}
                env_stats: dict[str, list] = {}
                for key, value, agg in incoming.stats:
                    env_stats.setdefault(key, []).append((value, agg))
                self.reporter.record_environment_stats(brains, env_stats, env_id)

    def initial_side_channel(self, env_id: int = 0) -> bytes:
        msgs = environment_parameter_messages(self.params) + engine_config_messages(self.options.engine_settings)
        return sc.pack_messages(msgs)

    def drain_side_channels(self) -> list[bytes]:
        return [r.drain() for r in self.routers]

    def drop_trajectories(self) -> None:
        for t in self.trackers.values():
            t.drop_all()
        for runner in self.runners.values():
            runner.trainer.forget_episodes()

    @property
    def finished(self) -> bool:
        if self.options.checkpoint_settings.inference or not self.runners:
            return False
        return all(r.done for r in self.runners.values())

    def report_progress(self) -> None:
        """Feed the live progress line; at most every 0.1 s (it renders far less often)."""
        now = time.monotonic()
        if now - self._last_progress < 0.1:
            return
        self._last_progress = now
        for r in self.runners.values():
            rewards = r.reward_buffer
            self.progress.update(r.brain, r.trainer.step, r.max_steps if r.training else None,  # inference: no end
                                 float(np.mean(list(rewards)[-100:])) if rewards else None)


def make_routers(num_envs: int) -> list[sc.SideChannelRouter]:
    """One side-channel router per simulator; an unknown channel id is warned about once per run."""
    warned: set = set()
    return [sc.SideChannelRouter(warned) for _ in range(num_envs)]


def configure_torch_threads(threads: int) -> None:
    """``threads`` intra-op threads: one unless MLAGENTS_LIKE_TORCH_THREADS says otherwise. The
    simulators run in other processes on the same cores, and for the small networks RL uses,
    torch's thread pool costs more in hand-offs than it gains (measured: act for 256 agents
    3.2 ms with 2 threads, 0.8 ms with 1 on a 2-core machine)."""
    import torch

    torch.set_num_threads(threads)


def check_torch_device(device: str | None) -> None:
    """A --torch-device (torch_settings.device) that torch cannot parse or this machine cannot
    use is a user error, reported before the first network is built on it. None means the CPU."""
    if device is None:
        return
    import torch

    try:
        torch.zeros(1, device=torch.device(device))
    except (RuntimeError, AssertionError, ValueError) as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ConfigError(
            f"--torch-device / torch_settings.device {device!r} cannot be used here ({reason}). "
            f"Use cpu, or a device this torch build and machine have (cuda / cuda:N needs a CUDA "
            f"build of torch and a GPU)."
        ) from error


def pool_settings_of(options, env_vars: EnvVars) -> PoolSettings:
    env = options.env_settings
    rank, world = env_vars.ranks.rank, env_vars.ranks.world_size
    if world > 1 and not env.env_path:
        raise UserError(f"{world} data-parallel ranks need --env: each rank launches its own simulators "
                        "(the Unity Editor is one environment).")
    configured = [options.default_settings, *options.behaviors.values()]
    not_ppo = sorted({s.trainer_type for s in configured if s is not None and s.trainer_type != "ppo"})
    if world > 1 and not_ppo:
        raise UserError(f"{world} data-parallel ranks average PPO gradients only; this config uses "
                        f"trainer_type {', '.join(not_ppo)}. Run it as one rank (srun -n 1, or without "
                        "torchrun), or use PPO (docs/cluster.md).")
    if world > 1 and any(s is not None and s.self_play is not None for s in configured):
        raise UserError(f"{world} data-parallel ranks cannot share one self-play schedule; run a config with "
                        "self_play as one rank (srun -n 1, or without torchrun).")
    check_split(options, world)
    return PoolSettings(
        env_path=env.env_path, env_args=tuple(env.env_args or ()), base_port=env.base_port,
        num_envs=env.num_envs, num_areas=env.num_areas, seed=env.seed, timeout_wait=env.timeout_wait,
        bind=env.bind, no_graphics=options.engine_settings.no_graphics,
        no_graphics_monitor=options.engine_settings.no_graphics_monitor,
        log_folder=os.path.abspath(os.path.join(run_dir_of(options), "run_logs")),
        max_lifetime_restarts=env.max_lifetime_restarts, restarts_rate_limit_n=env.restarts_rate_limit_n,
        restarts_rate_limit_period_s=env.restarts_rate_limit_period_s, debug=options.debug,
        spin_wait_s=env_vars.spin_wait_s, transport=env_vars.transport, first_worker=rank * env.num_envs,
    )


def behavior_recorder(options) -> BehaviorRecorder:
    env = options.env_settings
    return BehaviorRecorder(env.num_areas, env.env_path or "editor", tuple(options.environment_parameters))


CAPTURE_STEPS = 20  # exchanges --capture-spec watches before it writes the file


def capture_spec(options, env_vars: EnvVars | None = None, steps: int = CAPTURE_STEPS) -> int:
    """``--capture-spec FILE``: connect to the simulator(s), step ``steps`` times with zero
    actions, write what was seen to FILE (docs/mirror.md) and exit without training."""
    env_vars = env_vars or EnvVars()
    path = options.capture_spec
    params = EnvironmentParameterManager(options.environment_parameters, options.env_settings.seed, {})
    side_channel = sc.pack_messages(environment_parameter_messages(params)
                                    + engine_config_messages(options.engine_settings))
    pool = EnvPool(pool_settings_of(options, env_vars), initial_side_channel=lambda: side_channel)
    recorder = behavior_recorder(options)
    routers = make_routers(pool.num_envs)
    try:
        pool.start()
        results = pool.reset(side_channel)
        for _ in range(steps):
            STOP.check()
            recorder.observe(results)
            for router, res in zip(routers, results):
                if res.side_channel:
                    recorder.observe_stats(key for key, _, _ in router.dispatch(res.side_channel).stats)
            results = pool.step([{} for _ in results], b"").results
        recorder.observe(results)
    except KeyboardInterrupt:
        logger.info("Stopped before the capture finished; nothing written.")
        return EXIT_STOPPED
    finally:
        pool.close()
    if not recorder.write(path):
        raise UserError(f"--capture-spec: the simulator sent no agent in {steps} steps, so there is no "
                        "behavior spec to record; check that the scene's agents request decisions.")
    spec = recorder.spec_file()
    logger.info("Wrote the specs of %d behavior(s) to %s: %s", len(spec.behaviors), path,
                ", ".join(f"{b.name} ({b.agents} agents)" for b in spec.behaviors))
    return 0


def run_training(options, env_vars: EnvVars | None = None) -> int:
    """Train (or run inference) as configured; ``env_vars``: the MLAGENTS_LIKE_* choices read at
    start (trainer/cli.py; the defaults if None). Returns the process exit code."""
    env_vars = env_vars or EnvVars()
    crash_points.arm(env_vars.crash_at)
    ck = options.checkpoint_settings
    env = options.env_settings
    pool_settings = pool_settings_of(options, env_vars)
    main = env_vars.ranks.rank == 0  # data-parallel ranks: rank 0 alone writes files (trainer/distributed.py)
    state: RunState | None = None
    # resolves --env first: a wrong path must not leave a results folder that blocks the rerun
    pool = EnvPool(pool_settings, initial_side_channel=lambda: state.initial_side_channel())
    if main:
        run_dir = prepare_run_dir(options)  # refuses before anything starts; the simulators log into it
    else:
        run_dir = run_dir_of(options)
        os.makedirs(os.path.join(run_dir, "run_logs"), exist_ok=True)  # this rank's simulators' logs
    warn_if_not_loopback(env.bind, str(DEFAULT_EDITOR_PORT) if env.env_path is None else
                         f"{env.base_port}" + (f"-{env.base_port + env.num_envs - 1}" if env.num_envs > 1 else ""))
    # the simulators boot from here on; meanwhile torch, the networks and the ONNX exporter are
    # imported in the background, and this thread sets up the results folder's files and answers
    # the handshake and the first RESET before it needs torch (docs/performance.md, "Start-up and exit")
    pool.launch()
    warmup.start()
    try:
        status_path = os.path.join(run_dir, "run_logs", "training_status.json")
        keep_status = (ck.resume or ck.inference) and os.path.isfile(status_path)
        status = TrainingStatus.load(status_path) if keep_status else TrainingStatus()
        restore = {p: status.get_lesson_num(p) for p in options.environment_parameters} if ck.resume else None
        params = EnvironmentParameterManager(options.environment_parameters, env.seed,
                                             {k: v for k, v in (restore or {}).items() if v is not None})
        progress = ProgressLine(sys.stderr if main else open(os.devnull, "w"))
        timers = TimerTree(argv=sys.argv)
        writers = []
        if main:
            tb = TensorboardWriter(run_dir, clear_past_data=ck.force and not ck.resume)
            # as mlagents-learn: every summary also lands in timers.json as gauges (<Behavior>.<tag>.mean/.sum)
            writers = [tb, ConsoleWriter(logger, progress=progress), GaugeWriter(timers)]
            write_run_options(options, run_dir)
        reporter = StatsReporter(writers)
        state = RunState(options, run_dir, pool, params, reporter, status, timers, progress,
                         make_routers(env.num_envs), env_vars, behavior_recorder(options))
    except BaseException:
        pool.close()
        raise
    for line in params.describe():
        logger.info(line)
    stopped = write_failed = False
    try:
        STOP.check()
        pool.connect()
        with timers.scope("env.reset"):
            results = pool.reset(state.initial_side_channel())
        configure_torch_threads(env_vars.torch_threads)  # waits for the background import of torch
        check_torch_device(options.torch_settings.device)
        state.ranks = Ranks.start(env_vars, options.torch_settings.device, options.batch_per_rank)
        import trainer.behavior  # noqa: F401
        logger.debug("Start-up: torch and the trainer's modules imported.")
        while True:
            STOP.check()  # stop signals take effect here, between steps (trainer.stop)
            state.recorder.observe(results)
            state.side_channel_in(results)
            trajectories: list = []
            state.count_dropped(results, trajectories)
            actions, decided = state.decide(results)
            if state.finished:
                state.record(decided, trajectories)
                break
            with timers.scope("env.send"):
                pool.send_step(actions, state.drain_side_channels())
            if not state.stepped:
                state.stepped = True
                logger.debug("Start-up: first actions sent.")
            # the simulators step now; meanwhile: experience, PPO, summaries
            with timers.scope("record"):
                state.record(decided, trajectories)
            state.learn(trajectories)
            state.report_progress()
            with timers.scope("env.wait"):
                step = pool.receive()
            if step.restarted:
                state.drop_trajectories()
            results = step.results
            if state.pending_reset:
                state.pending_reset = False
                state.drop_trajectories()
                results = pool.reset(state.drain_side_channels())
    except KeyboardInterrupt:  # a stop signal (trainer.stop)
        stopped = True
        logger.info("Learning was interrupted. Please wait while the graph is generated.")
    except UnityCommunicatorStoppedError:
        logger.info("The simulator closed the connection. Learning was interrupted. "
                    "Please wait while the graph is generated.")
    except RankLost as lost:  # trainer/distributed.py: handled like a stop signal
        stopped = True
        logger.warning("%s. Learning was interrupted; rank 0 writes the final checkpoint.", lost)
    except ResultsWriteError:
        write_failed = True  # a final checkpoint would fail the same way: the last good one stays
        raise
    except OSError as error:
        if error.errno not in WRITE_ERRNOS:
            raise
        write_failed = True
        raise results_write_error(error.filename or run_dir, error) from None
    finally:
        state.progress.close()
        # a stop signal also counts when the simulators, signalled with the trainer (scancel, a
        # preemption), closed the connection before the trainer reached its next safe point
        stopped = stopped or STOP.requested is not None
        try:
            if not write_failed:
                if stopped and not ck.inference:
                    state.summarize_partial()
                try:
                    finish_run(state)
                except OSError as error:
                    if error.errno not in WRITE_ERRNOS:
                        raise
                    raise results_write_error(error.filename or run_dir, error) from None
        finally:
            pool.close()
            state.ranks.close()
    if stopped and not ck.inference and not state.finished:
        logger.info("Stopped before max_steps (exit status %d); continue this run with --resume.", EXIT_STOPPED)
        return EXIT_STOPPED
    return 0


def finish_run(state: RunState) -> None:
    """Final checkpoint + ONNX per brain, training_status.json, timers.json, configuration.yaml,
    behaviors.json."""
    if not state.ranks.is_main:
        return  # rank 0 writes every file
    run_dir = state.run_dir
    for runner in state.runners.values():
        if runner.training and runner.trainer.step > 0:
            runner.save_checkpoint(state.status, final=True)
    if not state.options.checkpoint_settings.inference:  # inference leaves the training record alone
        state.save_status()
    if state.recorder is not None:
        state.recorder.write(os.path.join(run_dir, "run_logs", "behaviors.json"))
    state.timers.write(os.path.join(run_dir, "run_logs", "timers.json"))
    state.reporter.close()
    write_run_options(state.options, run_dir)
