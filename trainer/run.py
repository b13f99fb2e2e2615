"""The one training loop: simulators → decisions → trajectories → updates of each behavior's
trainer (PPO, SAC or POCA) → outputs.

Per iteration (each simulator has just sent its message):
  1. new behaviors get a ``BehaviorRunner`` (trainer, checkpoint bookkeeping);
  2. ONE batched forward pass per behavior computes actions for all deciding agents across all
     envs (the brain's policy, or with self-play a team's snapshot: ``BehaviorRunner.policy_for``);
  3. the actions go out at once, so the simulators step while we work;
  4. meanwhile every agent's experience is assembled (rollout.AgentTracker), trajectories go to
     the behavior's trainer (which updates when it has enough), summaries, checkpoints,
     curriculum; then we wait for the simulators' next messages.

Its helpers: the results folder (results_dir.py), the side-channel payloads
(side_channel_payloads.py), the checks and settings made before the loop (run_setup.py);
``--capture-spec`` runs capture.py instead.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
# numpy 2 loads numpy.ma on first use, which np.union1d (RunState.ensure_runner) needs: imported
# here, with the run's modules while the simulators boot, not between the handshake and the first
# actions (with numpy.random in numpy_policy.py: 30-50 ms of CPU)
import numpy.ma  # noqa: F401

from protos import side_channels as sc
from protos.types import ActionTuple, DecisionSteps, StatsAggregationMethod, StepResult, TerminalSteps, brain_name_of
from trainer import crash_points
from trainer.artifacts.atomic import WRITE_ERRNOS, results_write_error
from trainer.artifacts.behaviors import BehaviorRecorder
from trainer.artifacts.clips import ClipRecorder
from trainer.artifacts.console import ConsoleWriter, ProgressLine
from trainer.artifacts.stats import PROPERTY_HYPERPARAMETERS, PROPERTY_SELF_PLAY, GaugeWriter, StatsReporter
from trainer.artifacts.tensorboard import TensorboardWriter
from trainer.artifacts.timers import TimerTree
from trainer.artifacts.training_status import TrainingStatus
from trainer.config.env_vars import EnvVars
from trainer.config.legacy import log_agent_steps
from trainer.config.loader import write_run_options
from trainer.config.settings import settings_as_dict
from trainer.config.support import goal_conditioning_note
from trainer.curriculum import EnvironmentParameterManager
from trainer import warmup
from trainer.distributed import RankLost, Ranks
from trainer.envs.pool import EnvPool
from trainer.first_steps import StartingBehavior
from trainer.errors import ResultsWriteError, UnityCommunicatorStoppedError
from trainer.protocol.codec import NON_FINITE_STAT
from trainer.rollout import AgentTracker, GroupTracker, concat_masks
from trainer.run_setup import (
    Launched, behavior_recorder, check_torch_device, configure_torch_threads, launch_simulators,
)
from trainer.selfplay import TeamController
from trainer.side_channel_payloads import engine_config_messages, environment_parameter_messages, make_routers
from trainer.stop import EXIT_STOPPED, STOP

if TYPE_CHECKING:  # torch is imported only once the simulators are launched (see run_training)
    from trainer.behavior import BehaviorRunner

logger = logging.getLogger("mlagents_like")


class EnvRows(NamedTuple):
    """One simulator's part of a behavior's step: its deciding agents are rows ``rows`` of the
    behavior's one batched forward pass."""

    env_id: int
    decision: DecisionSteps
    terminal: TerminalSteps
    rows: slice


class Decision(NamedTuple):
    """What ``RunState.decide`` did for one behavior, handed to ``RunState.record`` once the
    actions are sent. ``out`` (the policy's output), ``masks`` and ``memories`` are None when no
    agent of the behavior decided this step (only terminal steps arrived)."""

    runner: BehaviorRunner
    behavior: str
    steps: list[EnvRows]
    out: Any  # PolicyOutput (trainer/common/policy.py)
    masks: np.ndarray | None  # bool [n, sum(branches)], True = masked
    memories: np.ndarray | None  # float32 [n, memory_size]: the LSTM state each agent acted from


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
    clips: ClipRecorder | None = None  # --record-video (trainer/artifacts/clips.py)
    start_time: float = field(default_factory=time.time)
    _last_progress: float = float("-inf")
    # behaviors deciding before torch is loaded (trainer/first_steps.py), and whether that may be
    # tried: one rank on the CPU starting afresh (``run_training``)
    starting: dict[str, StartingBehavior] = field(default_factory=dict)
    first_steps: bool = False
    torch_loaded: bool = False
    stepped: bool = False  # the first actions were sent (a start-up mark: bench/startup.py)
    updated: bool = False  # the first update was made (likewise)

    # ------------------------------------------------------------------ behaviors
    def load_torch(self) -> None:
        """Wait for the background import of torch and the trainer's modules (trainer/warmup.py)."""
        if self.torch_loaded:
            return
        configure_torch_threads(self.env_vars.torch_threads)
        check_torch_device(self.options.torch_settings.device)
        import trainer.behavior  # noqa: F401
        self.torch_loaded = True
        logger.debug("Start-up: torch and the trainer's modules imported.")

    def ensure_runner(self, behavior_name: str, first_contact: tuple[DecisionSteps, TerminalSteps] | None = None
                      ) -> BehaviorRunner | StartingBehavior:
        """The behavior's runner, created at its first contact; the agents of ``first_contact`` (one
        simulator's steps of it, then) convert a 0.x file's step counts (RunOptions.behavior_settings).
        Counted only for a new runner: this runs every step, for one agent as often as not. Before
        torch is loaded, a StartingBehavior decides instead, where it can (trainer/first_steps.py)."""
        brain, _team = brain_name_of(behavior_name)
        runner = self.runners.get(brain) or self.starting.get(brain)
        if runner is not None:
            return runner
        agents = None if first_contact is None else len(np.union1d(first_contact[0].agent_id,
                                                                    first_contact[1].agent_id))
        spec = self.pool.behavior_specs()[behavior_name]  # merged over the workers: only for a new brain
        opts = self.options
        logger.info("Connected new brain: %s", behavior_name)
        settings = opts.behavior_settings(brain, agents)
        if opts.legacy_env_steps and agents is not None:
            log_agent_steps(brain, agents, opts.behavior_settings(brain), settings)
            # configuration.yaml is a modern file: from now on it carries the agent-step counts
            self.options = opts.with_agent_steps(brain, agents)
            if self.ranks.is_main:
                write_run_options(self.options, self.run_dir)
        if settings.threaded:
            logger.warning("%s: threaded: true is accepted but has no effect here; updates run between "
                           "environment steps, as with threaded: false (same results, no policy lag).",
                           brain)
        note = goal_conditioning_note(spec.observation_specs, settings)
        if note:
            logger.warning("%s: %s", brain, note)
        seed = opts.env_settings.seed + len(self.runners) + len(self.starting)
        if self.first_steps and not self.torch_loaded:
            starting = StartingBehavior.create(behavior_name, agents, brain, spec, settings, seed)
            if starting is not None:
                self.starting[brain] = starting
                return starting
        return self._create_runner(brain, spec, settings, seed)

    def promote(self, trajectories: list, wait: bool) -> None:
        """The behaviors that decided without torch get their real runners (``wait``: waiting
        for torch; else only if it is loaded already), their policies continuing from the
        first-steps policies; ``trajectories`` then point at the real runners. Called before any
        trajectory is processed, so nothing learned differs (trainer/first_steps.py)."""
        if not self.starting or not (wait or self.torch_loaded or warmup.finished()):
            return
        self.load_torch()
        for brain, first in list(self.starting.items()):
            runner = self._create_runner(brain, first.spec, first.settings, first.seed)
            runner.trainer.policy.take_over(first.policy)
            runner.add_episodes(first.episode_returns)
            del self.starting[brain]
            logger.debug("Start-up: %s: the trainer takes over from the first-steps policy.", brain)
        trajectories[:] = [(self.runners[runner.brain], traj) for runner, traj in trajectories]

    def _create_runner(self, brain: str, spec, settings, seed: int) -> BehaviorRunner:
        from trainer.behavior import BehaviorRunner

        self.load_torch()
        opts = self.options
        ck = opts.checkpoint_settings
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
        if self.clips is not None and runner.training:
            runner.on_checkpoint = self.clips.after_checkpoint
        self.reporter.add_property(brain, PROPERTY_HYPERPARAMETERS, settings_as_dict(settings))
        if runner.self_play is not None:
            self.reporter.add_property(brain, PROPERTY_SELF_PLAY, True)
        return runner

    # ------------------------------------------------------------------ decisions
    def decide(self, results: list[StepResult]) -> tuple[list[dict[str, ActionTuple]], list[Decision]]:
        """Actions for every deciding agent: ONE forward pass per behavior across all envs.

        Returns (actions per env, the decisions to ``record`` once the actions are sent). Nothing
        here touches the experience trackers, so the simulators wait only for the policy.
        """
        actions: list[dict[str, ActionTuple]] = [{} for _ in results]
        decided: list[Decision] = []
        by_behavior: dict[str, list[int]] = {}
        for env_id, res in enumerate(results):
            for behavior in res.steps:
                by_behavior.setdefault(behavior, []).append(env_id)
        for behavior, env_ids in by_behavior.items():
            runner = self.ensure_runner(behavior, results[env_ids[0]].steps[behavior])
            policy = runner.policy_for(brain_name_of(behavior)[1])  # self-play: maybe a snapshot
            # each env's deciding agents are the rows [start, end) of the one batched forward pass
            steps, start = [], 0
            for env_id in env_ids:
                decision, terminal = results[env_id].steps[behavior]
                steps.append(EnvRows(env_id, decision, terminal, slice(start, start + len(decision))))
                start += len(decision)
            out = masks = memories = None
            if start:
                out, masks, memories = self._act(runner, policy, behavior, [s for s in steps if len(s.decision)])
                for env_id, decision, _, rows in steps:
                    if len(decision):
                        actions[env_id][behavior] = ActionTuple(out.env_actions.continuous[rows],
                                                                out.env_actions.discrete[rows])
            decided.append(Decision(runner, behavior, steps, out, masks, memories))
        return actions, decided

    def _act(self, runner: BehaviorRunner, policy, behavior: str, steps: list[EnvRows]):
        """One forward pass of ``policy`` for the deciding agents of ``steps``. Returns (policy
        output, masks, the memories it started from or None)."""
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
            kind = GroupTracker if runner.trainer.uses_groups else AgentTracker  # POCA
            tracker = kind(runner.spec, runner.settings.time_horizon, memory_size=runner.trainer.policy.memory_size)
            self.trackers[(env_id, behavior)] = tracker
        return tracker

    def record(self, decided: list[Decision], trajectories: list) -> None:
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
                self._episode_stats(runner, tracker)
                if len(decision):
                    tracker.on_actions(slots, out.continuous_raw[rows], out.discrete[rows],
                                       out.log_probs[rows], None if masks is None else masks[rows],
                                       None if memories is None else memories[rows],
                                       None if memories is None else out.memories[rows])

    def _episode_stats(self, runner: BehaviorRunner | StartingBehavior, tracker: AgentTracker) -> None:
        brain = runner.brain
        eps = tracker.drain_episodes()
        if eps.rewards:
            rewards = np.asarray(eps.rewards, dtype=np.float64)
            self.reporter.add_many(brain, "Environment/Cumulative Reward", rewards, StatsAggregationMethod.AVERAGE)
            self.reporter.add_many(brain, "Environment/Episode Length", np.asarray(eps.lengths, np.float64),
                                   StatsAggregationMethod.AVERAGE)
            extrinsic = runner.settings.reward_signals.get("extrinsic")
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

    def environment_side_channel(self) -> bytes:
        """The current lessons' environment parameters as side-channel messages (--record-video's clips)."""
        return sc.pack_messages(environment_parameter_messages(self.params))

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
        if self.options.checkpoint_settings.inference or not self.runners or self.starting:
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


def run_training(options, env_vars: EnvVars | None = None, launched: Launched | None = None) -> int:
    """Train (or run inference) as configured; ``env_vars``: the MLAGENTS_LIKE_* choices read at
    start (trainer/cli.py; the defaults if None); ``launched``: the simulators trainer/cli.py
    launched before importing this module (launched here if None). Returns the process exit code."""
    env_vars = env_vars or EnvVars()
    crash_points.arm(env_vars.crash_at)
    ck = options.checkpoint_settings
    env = options.env_settings
    main = env_vars.ranks.rank == 0  # data-parallel ranks: rank 0 alone writes files (trainer/distributed.py)
    state: RunState | None = None
    # the simulators boot from here on, while this thread sets up the results folder's files; it
    # answers the handshake and the first RESET before it needs torch (docs/performance.md,
    # "Start-up and exit")
    pool, run_dir = launched or launch_simulators(options, env_vars)
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
        pool.initial_side_channel = state.initial_side_channel  # for a restarted simulator
        if ck.record_video and main:
            state.clips = ClipRecorder.for_env(env.env_path, env.seed, run_dir, state.environment_side_channel,
                                               env.env_args or ())
        pool.serve()  # the gRPC server takes over the ports the launch bound (trainer/envs/pool.py)
    except BaseException:
        pool.close()
        raise
    for line in params.describe():
        logger.info(line)
    stopped = write_failed = False
    # torch, the networks and the exporter are imported in the background from here on, while this
    # thread waits for the handshake: started earlier, the import would share the CPUs with the
    # simulator's boot and this thread's set-up above, both of which the first step waits for
    warmup.start()
    try:
        STOP.check()
        pool.connect()
        with timers.scope("env.reset"):
            results = pool.reset(state.initial_side_channel())
        # one rank on the CPU starting afresh decides its first actions before torch is loaded
        # (trainer/first_steps.py); otherwise the run waits for torch here
        state.first_steps = (env_vars.ranks.world_size == 1 and options.torch_settings.device in (None, "cpu")
                             and not ck.resume and not ck.inference)
        if not state.first_steps:
            state.load_torch()
        state.ranks = Ranks.start(env_vars, options.torch_settings.device, options.batch_per_rank)
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
            state.promote(trajectories, wait=bool(trajectories))
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
            if state.clips is not None:
                state.clips.finish()
    # Asked again after the final save and the simulators' exit: scancel and a preemption signal
    # every process of the job in turn, so the simulator's TERM can close the connection before the
    # trainer's own TERM arrives (seen in CI). Until the trainer exits, a stop signal still means
    # "unfinished, resume me" (docs/cluster.md "Stop, preempt, resume").
    stopped = stopped or STOP.requested is not None
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
