"""Unity's step semantics for one behavior: decisions, actions by position, episodes, stats.

One decision step, as the Academy runs it with a DecisionRequester on every agent:

1. ``collect_infos`` - what Unity puts in the next message: first the done infos of agents
   whose episode ended since the last message (in the order they ended), then one decision
   request per agent (agent order) with the reward collected since its last decision. A
   finished agent therefore appears twice in one message: its terminal info (old episode id)
   and the first info of its new episode (a new id).
2. ``apply_actions`` - the trainer's actions, matched BY POSITION to the decision requests.
3. ``advance`` - ``decision_period`` control steps; agents that finish mid-way are reset at
   once (Unity's EndEpisode -> OnEpisodeBegin) and act with zero actions until the next
   decision, as Unity's ActuatorManager.ResetData leaves them.

``environment_reset`` is the RESET command: every agent starts a new episode (new ids), no
terminal infos are sent, pending rewards are dropped.

A task may expose several behaviors sharing its physics (``Task.behaviors``, e.g. one per team
of ``soccer``): each gets its own list of infos and its own actions (``collect_batches``,
``apply_action_list(..., behavior=i)``), and one ``advance`` steps them all together.
"""
from __future__ import annotations

import itertools
import logging
import operator
from typing import Sequence

import numpy as np

from protos import records
from protos.communicator_objects import agent_action_pb2, agent_info_pb2
from unity_stub_env.agents import EncodedInfos, EpisodeIdCounter, encode_agent_infos
from unity_stub_env.tasks.base import Stat, Task

logger = logging.getLogger("unity_stub_env")
_CONTINUOUS = operator.attrgetter("continuous_actions")
_DISCRETE = operator.attrgetter("discrete_actions")


class ActionCountError(RuntimeError):
    """The trainer sent a different number of actions than there were decision requests."""


class Academy:
    def __init__(self, task: Task, decision_period: int | None = None,
                 episode_counter: EpisodeIdCounter | None = None) -> None:
        self.task = task
        self.decision_period = int(decision_period or task.decision_period)
        if self.decision_period < 1:
            raise ValueError(f"decision_period must be >= 1, got {self.decision_period}")
        self.behaviors = task.behaviors()  # [(behavior key, rows of its agents)]
        self.behavior_key = self.behaviors[0][0]
        # one counter per process (Unity's is static): pass the same one to every academy
        self.episode_counter = episode_counter or EpisodeIdCounter()
        n = task.num_agents
        self.episode_ids = np.zeros(n, dtype=np.int64)
        self.pending_reward = np.zeros(n, dtype=np.float32)
        self.pending_group_reward = np.zeros(n, dtype=np.float32)  # tasks with TaskStep.group_rewards
        self.continuous = np.zeros((n, task.action_spec.continuous_size), dtype=np.float32)
        self.discrete = np.zeros((n, len(task.action_spec.discrete_branches)), dtype=np.int32)
        self.pending_done_infos = EncodedInfos()
        self.pending_done_by_behavior: list[EncodedInfos] = [EncodedInfos() for _ in self.behaviors]
        self.pending_stats: list[Stat] = []
        self.completed_episodes = 0
        self.environment_reset()

    # ----------------------------------------------------------------------------------------
    def environment_reset(self) -> None:
        """The RESET command: every agent begins a new episode with a fresh episode id."""
        self.task.reset()
        self.episode_ids[:] = self.episode_counter.take(self.task.num_agents)
        self.pending_reward[:] = 0.0
        self.pending_group_reward[:] = 0.0
        self.continuous[:] = 0.0
        self.discrete[:] = 0
        self.pending_done_infos = EncodedInfos()
        self.pending_done_by_behavior = [EncodedInfos() for _ in self.behaviors]

    def collect_batches(self) -> list[tuple[str, EncodedInfos]]:
        """``collect_encoded`` per behavior of the task: [(behavior key, its infos)]."""
        if len(self.behaviors) == 1:
            return [(self.behavior_key, self.collect_encoded())]
        task = self.task
        observations, mask, groups = task.observe(), task.action_mask(), task.group_ids()
        batches = []
        for i, (key, rows) in enumerate(self.behaviors):
            decisions = encode_agent_infos(
                task.observation_specs, [o[rows] for o in observations], self.pending_reward[rows],
                self.episode_ids[rows], done=False, action_mask=None if mask is None else mask[rows],
                compressions=task.observation_compressions, group_ids=None if groups is None else groups[rows],
                group_rewards=self.pending_group_reward[rows])
            batches.append((key, self.pending_done_by_behavior[i] + decisions))
        self.pending_done_by_behavior = [EncodedInfos() for _ in self.behaviors]
        self.pending_reward[:] = 0.0
        self.pending_group_reward[:] = 0.0
        return batches

    def collect_encoded(self) -> EncodedInfos:
        """Terminal infos since the last message, then one decision request per agent
        (serialized; see ``agents.encode_agent_infos``)."""
        task = self.task
        decisions = encode_agent_infos(
            task.observation_specs, task.observe(), self.pending_reward, self.episode_ids,
            done=False, action_mask=task.action_mask(), compressions=task.observation_compressions,
            group_ids=task.group_ids(), group_rewards=self.pending_group_reward,
        )
        infos = self.pending_done_infos + decisions
        self.pending_done_infos = EncodedInfos()
        self.pending_reward[:] = 0.0
        self.pending_group_reward[:] = 0.0
        return infos

    def collect_infos(self) -> list[agent_info_pb2.AgentInfoProto]:
        """``collect_encoded`` as AgentInfoProto objects."""
        return self.collect_encoded().protos()

    def take_stats(self) -> list[Stat]:
        stats, self.pending_stats = self.pending_stats, []
        return stats

    def apply_actions(self, actions: Sequence[agent_action_pb2.AgentActionProto], behavior: int = 0) -> None:
        """Actions for the decision requests of the last message, by position (``behavior``: the
        index in ``behaviors`` they are for).

        An empty list means "no actions" (the agents act with zeros), as in Unity.
        """
        key, rows = self.behaviors[behavior]
        n = self.task.num_agents if isinstance(rows, slice) else len(rows)
        if len(actions) == 0:
            self.continuous[rows] = 0.0
            self.discrete[rows] = 0
            return
        if len(actions) != n:
            raise ActionCountError(
                f"The trainer sent {len(actions)} actions for behavior {key!r} but "
                f"{n} agents requested a decision; it must send one action per non-done agent info, "
                "in the same order."
            )
        spec = self.task.action_spec
        if spec.continuous_size:
            self.continuous[rows] = _action_rows(list(map(_CONTINUOUS, actions)), spec.continuous_size,
                                                 "continuous", np.float32)
        if spec.discrete_branches:
            self.discrete[rows] = _action_rows(list(map(_DISCRETE, actions)), len(spec.discrete_branches),
                                               "discrete", np.int32)

    def apply_action_list(self, actions, behavior: int = 0) -> None:
        """``apply_actions`` for a ListAgentActionProto (or None): many agents are read from its
        serialized bytes at once (``protos.records``), few or unusual ones one by one."""
        if actions is None:
            self.apply_actions([], behavior)
            return
        key, rows = self.behaviors[behavior]
        n = len(actions.value)
        if n == self.task.num_agents and n >= records.MIN_ROWS and isinstance(rows, slice):
            spec = self.task.action_spec
            decoded = records.decode_actions(key, actions.SerializeToString(),
                                             spec.continuous_size, len(spec.discrete_branches))
            if decoded is not None:
                self.continuous[:], self.discrete[:] = decoded
                return
        self.apply_actions(actions.value, behavior)

    def advance(self) -> None:
        """Run ``decision_period`` control steps; finished agents are reset on the spot."""
        task = self.task
        restarted = None  # bool [n] once some agent has been reset during this decision period
        for _ in range(self.decision_period):
            result = task.step(self.continuous, self.discrete)
            if task.sets_reward:
                self.pending_reward[:] = result.rewards
            else:
                self.pending_reward += result.rewards
            self.pending_stats.extend(result.stats)
            if result.group_rewards is not None:  # AddGroupReward: summed until the next decision
                self.pending_group_reward += result.group_rewards
            done = result.done if restarted is None else result.done & ~restarted
            if done.any():
                self._end_episodes(done, result.interrupted)
                restarted = done if restarted is None else restarted | done

    def _end_episodes(self, done: np.ndarray, interrupted: np.ndarray) -> None:
        """Queue the terminal infos of ``done`` [n] agents, then start their next episode."""
        task = self.task
        self._queue_terminal_infos(done, interrupted)
        finished = int(done.sum())
        self.completed_episodes += finished
        if self.completed_episodes // 100 != (self.completed_episodes - finished) // 100:
            logger.info("%d episodes completed", self.completed_episodes)
        self.pending_reward[done] = 0.0
        self.pending_group_reward[done] = 0.0
        task.reset(done)
        self.episode_ids[done] = self.episode_counter.take(finished)
        self.continuous[done] = 0.0
        self.discrete[done] = 0

    def _queue_terminal_infos(self, done: np.ndarray, interrupted: np.ndarray) -> None:
        """What the trainer will learn of the ``done`` [n] agents' last step (observations, the
        reward pending, ``interrupted``), read before they are reset: here the terminal infos of
        the next message; the in-process envs (``unity_stub_env.gym``) keep the arrays instead."""
        task = self.task
        if len(self.behaviors) == 1:
            observations = [obs[done] for obs in task.observe()]
            groups = task.group_ids()
            self.pending_done_infos += encode_agent_infos(
                task.observation_specs, observations, self.pending_reward[done], self.episode_ids[done],
                done=True, interrupted=interrupted[done], compressions=task.observation_compressions,
                group_ids=None if groups is None else groups[done],
                group_rewards=self.pending_group_reward[done],
            )
        else:
            self._queue_done_by_behavior(done, interrupted)

    def _queue_done_by_behavior(self, done: np.ndarray, interrupted: np.ndarray) -> None:
        """``_end_episodes``' terminal infos for a task with several behaviors, each to its own list."""
        task = self.task
        observations, groups = task.observe(), task.group_ids()
        for i, (_, rows) in enumerate(self.behaviors):
            mine = np.zeros(task.num_agents, dtype=bool)
            mine[rows] = True
            mine &= done
            if mine.any():
                self.pending_done_by_behavior[i] += encode_agent_infos(
                    task.observation_specs, [o[mine] for o in observations], self.pending_reward[mine],
                    self.episode_ids[mine], done=True, interrupted=interrupted[mine],
                    compressions=task.observation_compressions, group_ids=None if groups is None else groups[mine],
                    group_rewards=self.pending_group_reward[mine])


def _action_rows(rows: list, width: int, kind: str, dtype) -> np.ndarray:
    """[n, width] array from n repeated proto fields; raises ActionCountError on a bad width."""
    widths = set(map(len, rows))
    if widths != {width}:
        raise ActionCountError(
            f"The trainer sent {kind} actions of length(s) {sorted(widths)} but the action spec "
            f"has {width} {kind} action(s) per agent."
        )
    flat = np.fromiter(itertools.chain.from_iterable(rows), dtype=dtype, count=len(rows) * width)
    return flat.reshape(len(rows), width)
