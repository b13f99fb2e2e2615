"""Experience assembly: decision/terminal steps of one env's behavior → trajectories.

ML-Agents keeps one Python object per agent and appends to lists per step. Here every agent of a
(env, behavior) pair owns a *slot* in preallocated arrays of ``time_horizon`` rows, and each step
writes all agents at once with fancy indexing. A decision's observation and action go straight
into the slot's next row; when its reward arrives with the next step, only the reward is
written and the row counted. Episode ids map to slots through a sorted index (searchsorted),
so Python touches an agent only when its episode starts or a trajectory is emitted (once per
``time_horizon`` steps or episode end), not every step.

Rules (docs/ppo.md, "Experience assembly"):
- the reward that arrives with observation t+1 is paired with the observation and action of t;
  the reward on an agent's very first decision of an episode is dropped;
- extrinsic reward = reward + group_reward;
- a trajectory is cut at ``time_horizon`` experiences (next_obs = the current observation, not done)
  or when the episode ends (next_obs = the terminal observation, done, interrupted if max_step);
- episode ids change every episode, so a slot lives for exactly one episode;
- with a recurrent policy, each slot also keeps the agent's memory (zero when its episode starts)
  and each experience the memory its action was computed from.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from protos.types import BehaviorSpec, DecisionSteps, TerminalSteps
from trainer.common.trajectory import GroupColumns, Trajectory


@dataclass
class EpisodeStats:
    """Finished episodes since the last drain: env reward (the return), the group rewards the
    episode received, lengths in decisions."""

    rewards: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)
    group_rewards: list[float] = field(default_factory=list)
    # GroupTracker: the group rewards of each agent whose whole group had finished when it did
    group_returns: list[float] = field(default_factory=list)


class AgentTracker:
    """Slot-array experience builder for one behavior in one env connection."""

    def __init__(self, spec: BehaviorSpec, time_horizon: int, capacity: int = 16, memory_size: int = 0):
        self.spec = spec
        self.time_horizon = int(time_horizon)
        self.memory_size = int(memory_size)
        self._slot_of: dict[int, int] = {}
        self._index: tuple[np.ndarray, np.ndarray] | None = None  # _slot_of sorted by id
        self._free: list[int] = []
        self._cap = 0
        self.episodes = EpisodeStats()
        self._alloc(max(1, capacity))

    # ---------------------------------------------------------------- storage
    def _alloc(self, cap: int) -> None:
        """Grow every per-slot array to ``cap`` slots, keeping existing contents."""
        h = self.time_horizon
        a = self.spec.action_spec
        n_mask = int(sum(a.discrete_branches))
        shapes = [tuple(o.shape) for o in self.spec.observation_specs]

        def grow(old: np.ndarray | None, shape: tuple, dtype) -> np.ndarray:
            new = np.zeros((cap, *shape), dtype=dtype)
            if old is not None:
                new[: old.shape[0]] = old
            return new

        first = self._cap == 0
        g = (lambda name: None) if first else (lambda name: getattr(self, name))
        self.obs = [grow(None if first else self.obs[i], (h, *s), np.float32) for i, s in enumerate(shapes)]
        self.cont = grow(g("cont"), (h, a.continuous_size), np.float32)
        self.disc = grow(g("disc"), (h, a.discrete_size), np.int32)
        self.logp = grow(g("logp"), (h, a.continuous_size + a.discrete_size), np.float32)
        self.mask = grow(g("mask"), (h, n_mask), bool)
        self.rewards = grow(g("rewards"), (h,), np.float32)
        self.length = grow(g("length"), (), np.int64)
        # a decision awaits its reward: its observation and action sit in row ``length`` already
        self.pending = grow(g("pending"), (), bool)
        self.ep_reward = grow(g("ep_reward"), (), np.float64)
        self.ep_group_reward = grow(g("ep_group_reward"), (), np.float64)
        self.ep_length = grow(g("ep_length"), (), np.int64)
        m = self.memory_size
        self.memory = grow(g("memory"), (m,), np.float32)  # the next decision's input memory
        self.mem_in = grow(g("mem_in"), (h, m), np.float32)  # per experience: its input memory
        self._free.extend(range(cap - 1, self._cap - 1, -1))
        self._cap = cap

    def _slots(self, agent_ids: np.ndarray) -> np.ndarray:
        """int64 [n]: the slot of each episode id (unique ids); a new id gets a free slot.

        Looked up in a sorted copy of the id -> slot map, so agents that are already known cost
        no Python per agent; only new episodes go through the dict."""
        ids = np.asarray(agent_ids, dtype=np.int64)
        found, known = self._lookup(ids)
        if known.all():
            return found
        slot_of = self._slot_of
        missing = list(dict.fromkeys(ids[~known].tolist()))  # the index is in step with slot_of
        if len(missing) > len(self._free):
            self._alloc(max(self._cap * 2, self._cap + len(missing)))
        for agent in missing:
            s = self._free.pop()
            slot_of[agent] = s
            self.pending[s] = False
            self.length[s] = 0
            self.ep_reward[s] = 0.0
            self.ep_group_reward[s] = 0.0
            self.ep_length[s] = 0
            self.memory[s] = 0.0
        self._index = None
        return self._lookup(ids)[0]

    def memories_for(self, agent_ids: np.ndarray) -> np.ndarray:
        """float32 [n, memory_size]: the memory each agent's next action starts from (zero for an
        agent not seen yet, i.e. a new episode)."""
        found, known = self._lookup(np.asarray(agent_ids, dtype=np.int64))
        return np.where(known[:, None], self.memory[found], np.float32(0.0)).astype(np.float32)

    def _lookup(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(slot int64 [n], known bool [n]) of episode ids; a slot is meaningless where unknown."""
        keys, slots = self._sorted_index()
        if len(keys) == 0:
            return np.zeros(len(ids), dtype=np.int64), np.zeros(len(ids), dtype=bool)
        pos = np.minimum(np.searchsorted(keys, ids), len(keys) - 1)  # (np.clip's wrapper costs more)
        return slots[pos], keys[pos] == ids

    def _sorted_index(self) -> tuple[np.ndarray, np.ndarray]:
        """(episode ids ascending, their slots), rebuilt after the map changed."""
        if self._index is None:
            count = len(self._slot_of)
            keys = np.fromiter(self._slot_of.keys(), dtype=np.int64, count=count)
            order = np.argsort(keys)
            self._index = keys[order], np.fromiter(self._slot_of.values(), dtype=np.int64, count=count)[order]
        return self._index

    @property
    def num_agents(self) -> int:
        return len(self._slot_of)

    # ------------------------------------------------------------- experience
    def _record(self, slots: np.ndarray | int, reward: np.ndarray) -> None:
        """Close the pending decision of ``slots`` (int [n], or one slot with a scalar reward;
        already in row ``length``) with the reward that just arrived."""
        t = self.length[slots]
        self.rewards[slots, t] = reward
        self.length[slots] = t + 1
        self.pending[slots] = False

    def _emit(self, slot: int, agent_id: int, next_obs: list[np.ndarray], done: bool,
              interrupted: bool) -> Trajectory:
        n = int(self.length[slot])
        has_mask = self.mask.shape[-1] > 0
        traj = Trajectory(
            obs=[buf[slot, :n].copy() for buf in self.obs],
            next_obs=[o.copy() for o in next_obs],
            rewards=self.rewards[slot, :n].copy(),
            continuous_actions=self.cont[slot, :n].copy(),
            discrete_actions=self.disc[slot, :n].copy(),
            log_probs=self.logp[slot, :n].copy(),
            action_masks=self.mask[slot, :n].copy() if has_mask else None,
            memories=self.mem_in[slot, :n].copy() if self.memory_size else None,
            done=done,
            interrupted=interrupted,
            episode=(id(self), agent_id),  # Unity gives every episode a new id
        )
        self.length[slot] = 0
        return traj

    def on_step(self, ts: TerminalSteps, ds: DecisionSteps, emit: Callable[[Trajectory], None]) -> np.ndarray:
        """One message's terminal then decision steps of this behavior (``on_terminal``, then
        ``on_decision``, whose slots it returns)."""
        self.on_terminal(ts, emit)
        return self.on_decision(ds, emit)

    def on_terminal(self, ts: TerminalSteps, emit: Callable[[Trajectory], None]) -> None:
        """Agents whose episode ended: final reward, trajectory with done, episode stats."""
        if len(ts) == 0:
            return
        found, known = self._lookup(np.asarray(ts.agent_id, dtype=np.int64))
        if not known.any():
            return  # ended before ever deciding: nothing was experienced
        idx = np.nonzero(known)[0]
        slots = found[idx]
        has = self.pending[slots]
        if has.any():
            s = slots[has]
            self._record(s, ts.reward[idx][has] + ts.group_reward[idx][has])
            self.ep_reward[s] += ts.reward[idx][has]
            self.ep_group_reward[s] += ts.group_reward[idx][has]
            self.ep_length[s] += 1
        for k, slot in zip(idx, slots):
            slot = int(slot)
            if self.length[slot] > 0:
                emit(self._emit(slot, int(ts.agent_id[k]), [o[k] for o in ts.obs], True, bool(ts.interrupted[k])))
            self.episodes.rewards.append(float(self.ep_reward[slot]))
            self.episodes.lengths.append(int(self.ep_length[slot]))
            self.episodes.group_rewards.append(float(self.ep_group_reward[slot]))
            del self._slot_of[int(ts.agent_id[k])]
            self._free.append(slot)
        self._index = None

    def on_lost_terminal(self, agent_ids: np.ndarray, emit: Callable[[Trajectory], None]) -> int:
        """Agents whose episode ended with a step the codec dropped for NaN/Inf
        (trainer/protocol/codec.py): the decision that awaited that step's reward is discarded,
        the experiences before it go out as a trajectory that ends interrupted (done, bootstrapped
        from the value of that decision's observation, the last finite one), and the episode is
        closed without entering the episode statistics (its return is unknown). Returns the
        number of episodes closed. (With no experience left to emit, a trainer's per-episode
        entries for curiosity/memory sums stay until the run ends: one small entry per case.)"""
        found, known = self._lookup(np.asarray(agent_ids, dtype=np.int64))
        closed = 0
        for agent, slot in zip(np.asarray(agent_ids)[known].tolist(), found[known].tolist()):
            n = int(self.length[slot])
            if n > 0:
                emit(self._emit(slot, int(agent), [buf[slot, n] for buf in self.obs], True, True))
            del self._slot_of[int(agent)]
            self._free.append(slot)
            closed += 1
        self._index = None
        return closed

    def on_decision(self, ds: DecisionSteps, emit: Callable[[Trajectory], None]) -> np.ndarray:
        """Agents asking for a decision: pair their reward with the previous action, cut at
        time_horizon, remember the new observation. Returns their slots (for ``on_actions``)."""
        if len(ds) == 1:
            return self._on_one_decision(ds, emit)
        slots = self._slots(ds.agent_id)
        if len(slots) == 0:
            return slots
        has = self.pending[slots]
        pending = np.count_nonzero(has)
        if pending:
            if pending == len(slots):  # the usual step: every agent continues, nothing to select
                s, reward, group_reward = slots, ds.reward, ds.group_reward
            else:
                s, reward, group_reward = slots[has], ds.reward[has], ds.group_reward[has]
            self._record(s, reward + group_reward)
            self.ep_reward[s] += reward
            self.ep_group_reward[s] += group_reward
            self.ep_length[s] += 1
            full = np.nonzero(has & (self.length[slots] >= self.time_horizon))[0]
            for k in full:
                emit(self._emit(int(slots[k]), int(ds.agent_id[k]), [o[k] for o in ds.obs], False, False))
        t = self.length[slots]  # below time_horizon: full trajectories were just cut
        for buf, o in zip(self.obs, ds.obs):
            buf[slots, t] = o
        return slots

    def _on_one_decision(self, ds: DecisionSteps, emit: Callable[[Trajectory], None]) -> np.ndarray:
        """``on_decision`` for a single agent, the usual message of a one-agent behavior: the
        same writes on scalars instead of a dozen numpy calls on one-element arrays."""
        agent = int(ds.agent_id[0])
        slot = self._slot_of.get(agent)
        if slot is None:  # a new episode: its slot starts without a pending decision
            slot = int(self._slots(ds.agent_id)[0])
        elif self.pending[slot]:
            reward, group_reward = ds.reward[0], ds.group_reward[0]
            self._record(slot, reward + group_reward)  # scalar indices work there too
            self.ep_reward[slot] += reward
            self.ep_group_reward[slot] += group_reward
            self.ep_length[slot] += 1
            if self.length[slot] >= self.time_horizon:
                emit(self._emit(slot, agent, [o[0] for o in ds.obs], False, False))
        t = self.length[slot]
        for buf, o in zip(self.obs, ds.obs):
            buf[slot, t] = o[0]
        return np.array([slot])

    def on_actions(
        self,
        slots: np.ndarray,
        continuous_raw: np.ndarray,
        discrete: np.ndarray,
        log_probs: np.ndarray,
        action_mask: np.ndarray | None,
        memories_in: np.ndarray | None = None,
        memories_out: np.ndarray | None = None,
    ) -> None:
        """Store the policy's answer for the agents of the last ``on_decision`` call (and, for a
        recurrent policy, the memories it read and the ones it returned)."""
        if len(slots) == 1:  # one agent: scalar indices (numpy drops the rows' leading axis)
            slots = int(slots[0])
        t = self.length[slots]
        if self.memory_size:
            self.mem_in[slots, t] = memories_in
            self.memory[slots] = memories_out
        self.cont[slots, t] = continuous_raw
        self.disc[slots, t] = discrete
        self.logp[slots, t] = log_probs
        if action_mask is not None and self.mask.shape[-1] > 0:
            self.mask[slots, t] = action_mask
        else:
            self.mask[slots, t] = False
        self.pending[slots] = True

    def drop_all(self) -> None:
        """After a RESET or an env restart: in-progress trajectories are thrown away."""
        self._free.extend(self._slot_of.values())
        self._slot_of.clear()
        self._index = None

    def drain_episodes(self) -> EpisodeStats:
        out, self.episodes = self.episodes, EpisodeStats()
        return out


class GroupTracker(AgentTracker):
    """AgentTracker that also records, for each experience, what the agent's teammates (same
    ``group_id`` > 0 in the same simulator) did at that step, as ML-Agents' AgentProcessor
    assembles group trajectories for MA-POCA (docs/poca.md):

    - a teammate's status at a step is the observation it acted on, the action it took and the
      individual reward that came for it, from every agent of the group whose pending decision
      this message closes (its terminal or its next decision); an agent that left the group is no
      longer a teammate from the next message;
    - a trajectory's ``group.next_obs`` are the teammates' observations in the message that ends
      it, and ``group.all_done`` says whether every teammate's episode ended in it too: only then
      is the group's episode over and the value not bootstrapped;
    - ``EpisodeStats.group_returns``: the group rewards of an agent whose group finished with it.
    """

    def __init__(self, spec: BehaviorSpec, time_horizon: int, capacity: int = 16, memory_size: int = 0):
        super().__init__(spec, time_horizon, capacity, memory_size)
        self._mates: dict[int, list[list[tuple]]] = {}  # slot -> per experience, the teammates' statuses
        self._ends: dict[int, tuple[list[list[np.ndarray]], bool]] = {}  # agent -> (next obs of mates, all done)

    def on_step(self, ts: TerminalSteps, ds: DecisionSteps, emit: Callable[[Trajectory], None]) -> np.ndarray:
        statuses: dict[int, dict[int, tuple]] = {}  # group -> agent -> (obs, cont, disc, done, reward)
        current: dict[int, dict[int, list[np.ndarray]]] = {}  # group -> agent -> observations now
        closing: list[tuple[int, int, int]] = []  # (agent, group, slot) of every pending decision closed now
        for steps, done in ((ts, True), (ds, False)):
            if len(steps) == 0:
                continue
            found, known = self._lookup(np.asarray(steps.agent_id, dtype=np.int64))
            for k in np.nonzero(known)[0]:
                slot = int(found[k])
                if not self.pending[slot]:
                    continue
                agent, group, t = int(steps.agent_id[k]), int(steps.group_id[k]), int(self.length[slot])
                closing.append((agent, group, slot))
                if group > 0:
                    statuses.setdefault(group, {})[agent] = (
                        [buf[slot, t] for buf in self.obs], self.cont[slot, t], self.disc[slot, t], done,
                        float(steps.reward[k]))
                    current.setdefault(group, {})[agent] = [o[k] for o in steps.obs]
        self._ends = {}
        for agent, group, slot in closing:
            mates = [status for other, status in statuses.get(group, {}).items() if other != agent] if group > 0 else []
            self._mates.setdefault(slot, []).append(mates)
            mates_now = [obs for other, obs in current.get(group, {}).items() if other != agent] if group > 0 else []
            self._ends[agent] = (mates_now, all(status[3] for status in mates))
        ids = np.asarray(ts.agent_id, dtype=np.int64)
        known = self._lookup(ids)[1] if len(ts) else np.zeros(0, dtype=bool)
        before = len(self.episodes.group_rewards)
        self.on_terminal(ts, emit)  # appends one group reward sum per known terminal agent, in order
        for agent, group_reward in zip(ids[known].tolist(), self.episodes.group_rewards[before:]):
            if self._ends.get(agent, ([], True))[1]:
                self.episodes.group_returns.append(group_reward)
        return self.on_decision(ds, emit)

    def _emit(self, slot: int, agent_id: int, next_obs: list[np.ndarray], done: bool,
              interrupted: bool) -> Trajectory:
        n = int(self.length[slot])
        rows = self._mates.pop(slot, [])[:n]
        traj = super()._emit(slot, agent_id, next_obs, done, interrupted)
        mates_now, all_done = self._ends.get(agent_id, ([], True))
        width = max([len(r) for r in rows] + [len(mates_now), 0])
        a = self.spec.action_spec
        shapes = [tuple(o.shape) for o in self.spec.observation_specs]
        obs = [np.zeros((n, width, *shape), np.float32) for shape in shapes]
        cont = np.zeros((n, width, a.continuous_size), np.float32)
        disc = np.zeros((n, width, a.discrete_size), np.int32)
        present = np.zeros((n, width), bool)
        rewards = np.zeros((n, width), np.float32)
        for t, mates in enumerate(rows):
            for m, (mate_obs, mate_cont, mate_disc, _, mate_reward) in enumerate(mates):
                for i, o in enumerate(mate_obs):
                    obs[i][t, m] = o
                cont[t, m], disc[t, m], present[t, m], rewards[t, m] = mate_cont, mate_disc, True, mate_reward
        next_obs_mates = [np.zeros((width, *shape), np.float32) for shape in shapes]
        next_present = np.zeros(width, bool)
        for m, mate in enumerate(mates_now):
            for i, o in enumerate(mate):
                next_obs_mates[i][m] = o
            next_present[m] = True
        traj.group = GroupColumns(obs, cont, disc, present, rewards, next_obs_mates, next_present, bool(all_done))
        return traj

    def drop_all(self) -> None:
        super().drop_all()
        self._mates.clear()
        self._ends = {}


def concat_masks(ds: DecisionSteps, branches: tuple[int, ...]) -> np.ndarray | None:
    """Per-branch masks (True = forbidden) → one bool [n, sum(branches)] array, or None."""
    if not branches:
        return None
    if ds.action_mask is None:
        return np.zeros((len(ds), int(sum(branches))), dtype=bool)
    return np.concatenate(ds.action_mask, axis=1)
