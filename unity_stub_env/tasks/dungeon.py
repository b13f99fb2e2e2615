"""``dungeon``: three agents escape a room; one must be eaten by the dragon so that another can take
the key it drops to the door (a cooperative group task whose reward comes after the helper is gone).

Each area (``dungeon.xml`` beside this file) is a 2 x 2 m room with three agents, a dragon, a key and
a door; the three agents of an area form one agent group (group id = area index + 1, sent on the
wire). Agents slide in the plane and bump into each other (MuJoCo contacts); the room's walls are
their joints' limits. Dragon, key and door are placed by the task; touches are centre distances.

Actions, one discrete branch of 5: 0 = no force, 1 = +y, 2 = -y, 3 = +x, 4 = -x (10 N; 2 m/s at full
speed). A decision every control step of 0.1 s (5 MuJoCo steps of 0.02 s).

Observations, float32 [18] per agent, in the area's frame (m, m/s; absent things are zeros):
  0..1 own position, 2..3 own velocity,
  4..5 dragon minus own position, 6 dragon there (1/0),
  7..8 key minus own position, 9 key on the floor (1/0),
  10..11 door minus own position,
  12 I carry the key (1/0), 13 a teammate carries the key (1/0),
  14..15, 16..17 the two teammates' positions minus own (agent i sees i+1 then i+2, modulo 3).

Group episode start: the agents at y = -0.7, x = -0.6, 0, +0.6 (each + U(-0.1, 0.1)); the dragon
at (U(-0.6, 0.6), U(-0.1, 0.2)), between them and the door; the door's centre at (U(-0.6, 0.6), 1.0)
on the far wall. The room is small enough for random actions to escape now and then (below), so
that a sparse +1 is learnable in tens of thousands of steps.

Events, checked after every control step (centre distances):
  dragon   an agent within TOUCH_DRAGON (0.4 m) of the dragon is eaten: its own episode ends (done,
           not interrupted, no reward of its own) while the group goes on; the dragon is gone and
           the key lies where it was. (Two agents touching it in one step: the lower index is eaten.)
           The eaten agent starts a new episode at its start spot in the same group, as an agent of
           ``pushblock`` that left the floor; it does not see the rewards of the episode it left.
           (A Unity scene may instead deactivate it until the group's episode ends; the stub's
           agents all request a decision every step, so it comes back, with no dragon to meet.)
  key      an agent within TOUCH_KEY (0.3 m) of the key on the floor carries it from then on.
  door     the carrier within TOUCH_DOOR (0.5 m) of the door's centre: group reward +1 and the
           group's episode ends (done, all three agents).
  timeout  after max_step = 100 steps (10 s) the group's episode is interrupted (all agents).

Rewards are group rewards only (``SimpleMultiAgentGroup.AddGroupReward``): +1 at the door, and
``time_penalty`` every step (environment parameter, default 0: the only reward is the escape).
Nothing pays the sacrifice itself: only a trainer that credits an agent with its group's rewards
after it left (MA-POCA, docs/poca.md) sees why touching the dragon is worth it.

Independent PPO sees as much as it can already: like the reference's PPO (whose extrinsic reward
adds each step's group reward to the agent's own) our rollout gives every agent ``reward +
group_reward`` while it is in its episode (trainer/rollout.py), so no extra environment parameter is
needed to show PPO the group reward. What PPO cannot see is the +1 earned after the eaten agent's
episode ended. Why the default time penalty is 0: a per-step group penalty pays an independent
learner for being eaten (its penalty stream stops), a reason to touch the dragon that has nothing to
do with the key; ``time_penalty`` (e.g. -0.005) adds it back for comparison.

Environment parameters (read at each area's group episode start, Unity's EnvironmentParameters):
  time_penalty  (default 0) group reward every step.

Measured (tests/stub/test_stub_dungeon.py): the scripted sacrifice (while the dragon is there the
agent nearest to it walks into it, then the agent nearest to the key fetches it and carries it to
the door, the others stand still) escapes in each of 20 seeded episodes, in 12 to 18 steps (group
return 1 + steps * time_penalty); a still group is interrupted at 100 steps with return
100 * time_penalty (0 by default); uniformly random actions escape in 21 % of the episodes (the
dragon eats somebody in almost every one).
What MA-POCA and independent PPO learn on it: docs/poca.md and bench/RESULTS.md.
"""
from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from protos.types import ActionSpec, DimensionProperty, ObservationSpec, ObservationType, StatsAggregationMethod
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep, tiled_areas

XML_PATH = Path(__file__).with_name("dungeon.xml")
AGENTS = 3
AREA_SPACING = 10.0  # m between area centres along y
SUBSTEPS = 5  # MuJoCo steps per control step (0.1 s)
START_Y = -0.7
START_X = (-0.6, 0.0, 0.6)
DOOR_Y = 1.0
TOUCH_DRAGON = 0.4  # agent radius 0.15 + dragon radius 0.25
TOUCH_KEY = 0.3
TOUCH_DOOR = 0.5
MAX_STEP = 100
ESCAPE_REWARD = 1.0
TIME_PENALTY = 0.0  # group reward every step; environment parameter time_penalty
OBS_SIZE = 18
_FORCE_OF_ACTION = np.array([[0, 0], [0, 1], [0, -1], [1, 0], [-1, 0]], dtype=np.float64)
_DRAGON, _KEY, _DOOR = 0, 1, 2  # mocap bodies of an area, in the XML's order
_HIDDEN_Z = -1.0  # a mocap body that is not in play is drawn under the floor


def build_model(num_areas: int) -> mujoco.MjModel:
    """One MjModel with ``num_areas`` copies of dungeon.xml (names prefixed ``area<k>/``)."""
    return tiled_areas(XML_PATH, num_areas, AREA_SPACING)


class DungeonTask(Task):
    name = "dungeon"
    behavior_name = "Dungeon"
    observation_specs = (
        ObservationSpec((OBS_SIZE,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor_size18"),
    )
    action_spec = ActionSpec(continuous_size=0, discrete_branches=(5,))
    agents_per_area = AGENTS
    agents_interact = True
    max_step = MAX_STEP
    decision_period = 1
    sets_reward = False
    description = ("3 agents per area (one group): one must be eaten by the dragon, another takes the key it "
                   "drops to the door; group reward +1 at the door only; still: 0.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        self.rng = np.random.default_rng(seed)
        self.model = build_model(self.num_areas)
        self.data = mujoco.MjData(self.model)
        # per area, qpos/qvel columns: agent0 x, y, agent1 x, y, agent2 x, y (the XML's joint order)
        self.qpos = self.data.qpos.reshape(self.num_areas, AGENTS, 2)
        self.qvel = self.data.qvel.reshape(self.num_areas, AGENTS, 2)
        self.ctrl = self.data.ctrl.reshape(self.num_areas, AGENTS * 2)
        self.mocap = self.data.mocap_pos.reshape(self.num_areas, 3, 3)  # (dragon, key, door) x (x, y, z)
        self.origin = np.zeros((self.num_areas, 2))
        self.origin[:, 1] = AREA_SPACING * np.arange(self.num_areas)
        self.dragon = np.zeros((self.num_areas, 2))  # positions in the area's frame
        self.key = np.zeros((self.num_areas, 2))
        self.door = np.zeros((self.num_areas, 2))
        self.dragon_there = np.zeros(self.num_areas, dtype=bool)
        self.key_on_floor = np.zeros(self.num_areas, dtype=bool)
        self.carrier = np.full(self.num_areas, -1, dtype=np.int64)  # agent index in its area, -1: nobody
        self.time_penalty = np.full(self.num_areas, TIME_PENALTY)
        self.episode_step = np.zeros(self.num_areas, dtype=np.int64)
        self.start = np.zeros((self.num_areas, AGENTS, 2))
        self._groups = (np.repeat(np.arange(self.num_areas), AGENTS) + 1).astype(np.int64)
        self._mates = np.array([[(i + 1) % AGENTS, (i + 2) % AGENTS] for i in range(AGENTS)])
        self.reset()

    # ------------------------------------------------------------------------------ episodes
    def reset(self, mask: np.ndarray | None = None) -> None:
        """Agents of ``mask`` start over: a whole area's three start a new group episode (dragon,
        key and door too); a single agent (it was eaten) goes back to its start spot."""
        agents = self.all_agents(mask).reshape(self.num_areas, AGENTS)
        for area in np.nonzero(agents.all(axis=1))[0]:
            self.start[area, :, 0] = np.array(START_X) + self.rng.uniform(-0.1, 0.1, size=AGENTS)
            self.start[area, :, 1] = START_Y
            self.dragon[area] = (self.rng.uniform(-0.6, 0.6), self.rng.uniform(-0.1, 0.2))
            self.door[area] = (self.rng.uniform(-0.6, 0.6), DOOR_Y)
            self.dragon_there[area] = True
            self.key_on_floor[area] = False
            self.carrier[area] = -1
            self.time_penalty[area] = self.env_params.get("time_penalty", TIME_PENALTY)
            self.episode_step[area] = 0
        for area, agent in zip(*np.nonzero(agents)):
            self.qpos[area, agent] = self.start[area, agent]
            self.qvel[area, agent] = 0.0
        self._place_props()
        mujoco.mj_forward(self.model, self.data)

    def _place_props(self) -> None:
        """Mocap bodies where the game state says (for viewers; the rules use the arrays)."""
        self.mocap[:, _DRAGON, :2] = self.origin + self.dragon
        self.mocap[:, _DRAGON, 2] = np.where(self.dragon_there, 0.25, _HIDDEN_Z)
        carried = self.carrier >= 0
        held = self.qpos[np.arange(self.num_areas), np.maximum(self.carrier, 0)]
        self.mocap[:, _KEY, :2] = self.origin + np.where(carried[:, None], held, self.key)
        self.mocap[:, _KEY, 2] = np.where(self.key_on_floor, 0.1, np.where(carried, 0.4, _HIDDEN_Z))
        self.mocap[:, _DOOR, :2] = self.origin + self.door

    def group_ids(self) -> np.ndarray:
        return self._groups

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 18]] (see the module docstring)."""
        n_areas = self.num_areas
        pos, vel = self.qpos, self.qvel
        dragon = np.where(self.dragon_there[:, None, None], self.dragon[:, None] - pos, 0.0)
        key = np.where(self.key_on_floor[:, None, None], self.key[:, None] - pos, 0.0)
        door = self.door[:, None] - pos
        mine = self.carrier[:, None] == np.arange(AGENTS)[None]
        theirs = (self.carrier[:, None] >= 0) & ~mine
        mates = (pos[:, self._mates] - pos[:, :, None]).reshape(n_areas, AGENTS, 4)
        def flag(b: np.ndarray) -> np.ndarray:  # bool [areas] or [areas, AGENTS] -> float [areas, AGENTS, 1]
            return np.broadcast_to(b.reshape(n_areas, -1, 1), (n_areas, AGENTS, 1)).astype(np.float64)

        obs = np.concatenate([pos, vel, dragon, flag(self.dragon_there), key, flag(self.key_on_floor), door,
                              flag(mine), flag(theirs), mates], axis=2)
        return [obs.reshape(self.num_agents, OBS_SIZE).astype(np.float32)]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """discrete int [n, 1] in 0..4 (others clamp) -> one 0.1 s control step of every area."""
        choice = np.clip(np.asarray(discrete).reshape(self.num_agents, -1)[:, 0], 0, 4)
        self.ctrl[:] = _FORCE_OF_ACTION[choice].reshape(self.num_areas, AGENTS * 2)
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self.episode_step += 1
        pos = self.qpos
        eaten = np.zeros((self.num_areas, AGENTS), dtype=bool)
        near_dragon = self.dragon_there[:, None] & (np.linalg.norm(pos - self.dragon[:, None], axis=2) < TOUCH_DRAGON)
        for area in np.nonzero(near_dragon.any(axis=1))[0]:
            eaten[area, np.argmax(near_dragon[area])] = True
            self.dragon_there[area] = False
            self.key_on_floor[area] = True
            self.key[area] = self.dragon[area]
        near_key = (self.key_on_floor[:, None] & ~eaten
                    & (np.linalg.norm(pos - self.key[:, None], axis=2) < TOUCH_KEY))
        for area in np.nonzero(near_key.any(axis=1))[0]:
            self.carrier[area] = np.argmax(near_key[area])
            self.key_on_floor[area] = False
        areas = np.arange(self.num_areas)
        carrier_pos = pos[areas, np.maximum(self.carrier, 0)]
        escaped = (self.carrier >= 0) & (np.linalg.norm(carrier_pos - self.door, axis=1) < TOUCH_DOOR)
        timeout = ~escaped & (self.episode_step >= self.max_step)
        group_end = escaped | timeout
        eaten = eaten.reshape(self.num_agents)
        done = np.repeat(group_end, AGENTS) | eaten
        interrupted = np.repeat(timeout, AGENTS) & ~eaten
        group_reward = self.time_penalty + np.where(escaped, ESCAPE_REWARD, 0.0)
        self._place_props()
        stats = [("Dungeon/Success", float(s), StatsAggregationMethod.AVERAGE) for s in escaped[group_end].tolist()]
        return TaskStep(np.zeros(self.num_agents, dtype=np.float32), done, interrupted, stats,
                        group_rewards=np.repeat(group_reward, AGENTS).astype(np.float32))
