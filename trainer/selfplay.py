"""Self-play (``self_play:`` under a behavior): which team learns, what the other teams play, ELO.

The contract, as ML-Agents' ghost trainer has it (docs/selfplay.md):

* Teams come from the behavior name on the wire, ``Name?team=N``. One team learns at a time, for
  the whole run (``TeamController``): the first team seen starts; every ``team_change`` trainer
  steps the next team in line takes over and the simulators are reset.
* The learning team acts with the trainer's policy and its trajectories train it. Every other
  team acts with a frozen snapshot and its trajectories are only counted (``ghost_step``).
* A snapshot of the trainer's policy is kept every ``save_steps`` trainer steps, the last
  ``window`` of them in a ring. Every ``swap_steps`` ghost steps (and at a team change) each other
  team draws its opponent again: the latest policy with probability
  ``play_against_latest_model_ratio``, otherwise a snapshot from the window, uniformly.
* ELO: a learning-team trajectory that ends its episode (not interrupted by max_step; in an agent
  group, with every teammate's episode over too) is one game;
  the sign of its last reward says win (1), draw (0.5) or loss (0). The learning policy's rating
  moves by ``result - expected`` (expected = 1 / (1 + 10^((opponent - own) / 400)), no K factor, as
  the reference) and the opponent snapshot's rating by the opposite amount. Against the latest
  policy both are the same rating, so the game changes nothing.

The layer needs from a trainer only ``trainer.policy`` (``act`` and its ``actor`` module, whose
``state_dict`` are the weights a snapshot holds) and ``trainer.step``; it works the same for every
trainer type. Checkpoints keep its state (``state_dict``), so --resume continues the window, the
ratings and the schedule.
"""
from __future__ import annotations

import json
import logging
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import torch

logger = logging.getLogger("mlagents_like")

ELO_STAT = "Self-play/ELO"


def game_result(final_reward: float) -> float:
    """1.0 win, 0.5 draw, 0.0 loss from the sign of an episode's last reward."""
    if final_reward > 0:
        return 1.0
    if final_reward < 0:
        return 0.0
    return 0.5


def elo_change(rating: float, opponent_rating: float, result: float) -> float:
    """What one game adds to ``rating`` (and takes from the opponent's): result - expected score."""
    r1 = 10.0 ** (rating / 400.0)
    r2 = 10.0 ** (opponent_rating / 400.0)
    return result - r1 / (r1 + r2)


class TeamController:
    """One per run: the learning team, shared by every self-play behavior (an asymmetric game has
    one behavior per team, e.g. Striker?team=0 and Goalie?team=1, and one team learns at a time)."""

    def __init__(self) -> None:
        self.learning_team: int | None = None
        self.queue: deque[int] = deque()
        self.members: dict[int, "SelfPlay"] = {}  # team id -> the self-play layer that acts for it

    def subscribe(self, team: int, member: "SelfPlay") -> None:
        if team in self.members:
            return
        self.members[team] = member
        if self.learning_team is None:
            self.learning_team = team
        elif team != self.learning_team and team not in self.queue:
            self.queue.append(team)

    def change_team(self) -> None:
        """The learning team goes to the back of the line; the next one learns."""
        if not self.queue:
            return
        self.queue.append(self.learning_team)
        self.learning_team = self.queue.popleft()

    def rate_game(self, rating: float, result: float) -> float:
        """ELO change of the learning policy for one game; the opponents' ratings move opposite."""
        opponents = [m for team, m in self.members.items() if team != self.learning_team]
        opponent_rating = opponents[-1].opponent_elo if opponents else rating
        change = elo_change(rating, opponent_rating, result)
        for member in opponents:
            member.opponent_elo -= change
        return change

    def restore(self, learning_team: int, queue: list[int]) -> None:
        self.learning_team = learning_team
        self.queue = deque(queue)


def policy_weights(policy) -> dict[str, "torch.Tensor"]:
    """A copy of the acting network's parameters and normaliser buffers."""
    return {k: v.detach().clone() for k, v in policy.actor.state_dict().items()}


class SelfPlay:
    """The self-play layer of one behavior (brain); see the module docstring."""

    def __init__(self, settings, trainer, controller: TeamController, seed: int) -> None:
        self.settings = settings
        self.trainer = trainer
        self.controller = controller
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.window = max(1, int(settings.window))
        self.snapshots: list[dict[str, "torch.Tensor"]] = []
        self.snapshot_counter = 0
        # ratings of the window's snapshots, the last entry the learning policy's (index -1)
        self.elos: list[float] = [float(settings.initial_elo)] * (self.window + 1)
        # index into elos of what the other teams play (-1: the latest); until the first swap
        # they play the first snapshot, the policy the run starts with
        self.current_opponent = 0
        self.ghost_step = 0
        self.last_save = 0
        self.last_swap = 0
        self.last_team_change = 0
        self.learning_team: int | None = None  # as this layer last acted on it (the controller decides)
        self.teams: list[int] = []
        self._opponents: dict[int, Any] = {}  # team -> a policy holding the snapshot it plays
        self._opponent_weights: dict[str, "torch.Tensor"] | None = None

    # ------------------------------------------------------------------ who acts
    def add_team(self, team: int) -> None:
        if team in self.teams:
            return
        self.teams.append(team)
        self.controller.subscribe(team, self)
        if not self.snapshots:  # the first snapshot: the policy as it starts (or was restored)
            self._save_snapshot()
        if self.learning_team is None:
            self.learning_team = self.controller.learning_team
        if team != self.controller.learning_team:
            self._load_opponent(team)

    def is_learning(self, team: int) -> bool:
        return team == self.controller.learning_team

    def policy_for(self, team: int):
        """The policy that acts for ``team``: the trainer's for the learning team, else the team's
        snapshot (one policy object per team, its weights replaced at each swap)."""
        self.add_team(team)
        if self.is_learning(team):
            return self.trainer.policy
        return self._opponents[team]

    # ------------------------------------------------------------------ experience
    def count_ghost_steps(self, steps: int) -> None:
        """Experiences of a team that does not learn: not trained on, counted towards swap_steps."""
        self.ghost_step += int(steps)

    def rate_trajectory(self, final_reward: float, done: bool, interrupted: bool,
                        group_done: bool = True) -> float | None:
        """One game for an episode-ending learning-team trajectory; returns the new ELO, or None
        when the trajectory does not end a game (cut at time_horizon, or interrupted, or, in an agent
        group (POCA), some teammate's episode is still going: ``group_done`` False)."""
        if not done or interrupted or not group_done:
            return None
        change = self.controller.rate_game(self.current_elo, game_result(final_reward))
        self.elos[-1] += change
        return self.current_elo

    @property
    def current_elo(self) -> float:
        return self.elos[-1]

    @property
    def opponent_elo(self) -> float:
        return self.elos[self.current_opponent]

    @opponent_elo.setter
    def opponent_elo(self, value: float) -> None:
        self.elos[self.current_opponent] = value

    # ------------------------------------------------------------------ schedule
    def advance(self, step: int) -> bool:
        """After the trainer took its trajectories (and maybe updated) at trainer step ``step``:
        team change, snapshot, swap, in the reference's order. Returns True when the learning team
        changed (the run loop then resets the simulators)."""
        changed = False
        if step - self.last_team_change > self.settings.team_change:
            self.controller.change_team()
            self.last_team_change = step
            changed = True
        if step - self.last_save > self.settings.save_steps:
            self._save_snapshot()
            self.last_save = step
        next_team = self.controller.learning_team
        if self.learning_team != next_team or self.ghost_step - self.last_swap > self.settings.swap_steps:
            if self.learning_team != next_team:
                logger.info("%s: team %s learns now (step %d).", self.trainer.brain_name, next_team, step)
            self.learning_team = next_team
            self._swap()
            self.last_swap = self.ghost_step
        return changed

    def _save_snapshot(self) -> None:
        weights = policy_weights(self.trainer.policy)
        if self.snapshot_counter < len(self.snapshots):
            self.snapshots[self.snapshot_counter] = weights
        else:
            self.snapshots.append(weights)
        self.elos[self.snapshot_counter] = self.current_elo
        self.snapshot_counter = (self.snapshot_counter + 1) % self.window

    def _swap(self) -> None:
        """Every team that does not learn draws what it plays until the next swap."""
        for team in self.teams:
            if team == self.controller.learning_team:
                continue
            if self.rng.uniform() < 1.0 - self.settings.play_against_latest_model_ratio:
                self.current_opponent = int(self.rng.integers(len(self.snapshots)))
                weights = self.snapshots[self.current_opponent]
            else:
                self.current_opponent = -1
                weights = policy_weights(self.trainer.policy)
            self._opponent_weights = weights
            self._load_opponent(team)

    def _load_opponent(self, team: int) -> None:
        policy = self._opponents.get(team)
        if policy is None:
            src = self.trainer.policy
            policy = type(src)(src.behavior_spec, src.hyperparams, seed=self.seed + 1000 + team,
                               device=str(src.device))
            self._opponents[team] = policy
        weights = self._opponent_weights
        if weights is None:  # before the first swap: the snapshot the window starts with
            weights = self.snapshots[max(self.current_opponent, 0)]
        policy.actor.load_state_dict(weights)  # in place: the numpy actor's views see it

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        import torch  # the run loop imports this module before torch is loaded (trainer/run.py)

        return {
            "snapshots": list(self.snapshots),
            "opponent": dict(self._opponent_weights) if self._opponent_weights is not None else {},
            "elos": torch.tensor(self.elos, dtype=torch.float64),
            "counters": torch.tensor([self.snapshot_counter, self.current_opponent, self.ghost_step,
                                      self.last_save, self.last_swap, self.last_team_change], dtype=torch.int64),
            "teams": torch.tensor([self.controller.learning_team if self.controller.learning_team is not None
                                   else -1, *self.controller.queue], dtype=torch.int64),
            "rng": json.dumps(self.rng.bit_generator.state),
        }

    def start_from_elo(self, elo: float) -> None:
        """--resume of a checkpoint without the layer's state (ML-Agents keeps only the rating, in
        training_status.json): every rating starts from ``elo``; the window starts anew."""
        self.elos = [float(elo)] * (self.window + 1)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """--resume: the window, the ratings, the schedule and the learning team as saved."""
        elos = [float(x) for x in state["elos"].tolist()]
        if len(elos) != self.window + 1:  # window changed between runs: keep the newest ratings
            kept = elos[:-1][: self.window]
            elos = kept + [elos[0] if kept else self.settings.initial_elo] * (self.window - len(kept)) + [elos[-1]]
        self.snapshots = list(state["snapshots"])[: self.window]
        self.elos = elos
        counters = [int(x) for x in state["counters"].tolist()]
        (self.snapshot_counter, self.current_opponent, self.ghost_step, self.last_save, self.last_swap,
         self.last_team_change) = counters
        self.snapshot_counter %= self.window
        if self.current_opponent >= len(self.snapshots):
            self.current_opponent = -1
        self._opponent_weights = dict(state["opponent"]) or None
        teams = [int(x) for x in state["teams"].tolist()]
        if teams and teams[0] >= 0:
            self.controller.restore(teams[0], teams[1:])
            self.learning_team = teams[0]
        self.rng.bit_generator.state = json.loads(state["rng"])
        for team in self._opponents:
            self._load_opponent(team)
