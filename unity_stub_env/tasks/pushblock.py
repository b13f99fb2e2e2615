"""``pushblock``: two agents must push a block together into a goal zone (a cooperative group task).

Each area (``pushblock.xml`` beside this file) holds two agents and a block on a 5 x 5 m floor; the
two agents of an area form one agent group (group id = area index + 1, sent on the wire). The block
reaches the goal in time only when both push: its joints' dry friction (9 N) leaves one agent's
force (10 N) little to move it with (0.09 m/s), two agents pushing together move it at 0.69 m/s
(the XML says how). Everything slides in the plane.

Actions, one discrete branch of 5: 0 = no force, 1 = +y (towards the goal), 2 = -y, 3 = +x, 4 = -x.
A decision every control step of 0.1 s (5 MuJoCo steps of 0.02 s).

Observations, float32 [11] per agent, in the area's frame (m, m/s):
  0..1 own position, 2..3 own velocity, 4..5 block position minus own position,
  6..7 block velocity, 8 GOAL_Y minus the block's y, 9..10 the teammate's position minus own.

Start: the block at (U(-0.3, 0.3), 0); agent 0 at (block x - U(0.15, 0.45), -0.6), agent 1 at
(block x + U(0.15, 0.45), -0.6): both just behind the block.

Rewards are group rewards (every agent of the area receives them), except for leaving the floor:
  every step  -0.5 / max_step (hurry)  +  (block y after - block y before) / GOAL_Y (progress)
  success     +1 when the block's centre reaches y >= GOAL_Y; the group's episode ends (done).
  timeout     after max_step = 80 steps (8 s) the group's episode is interrupted (all agents).
An agent that leaves the floor (|x| or |y| > 2.5 m) gets an individual reward of -1 and ends its
own episode early (done, the group goes on); it starts a new one at its start spot in the same
group and does not see the group's later rewards in the episode that ended (the trainer's POCA
critic credits them, docs/poca.md). When both agents of an area have left in the same step, the
area starts over (block included).

Environment parameters (read at each area's group episode start, Unity's EnvironmentParameters):
  block_friction   (default 9) the block joints' dry friction in N. At >= 10 one agent's 10 N cannot
                   move the block at all and only both pushing together earn progress (at 10: 0.625 m/s).
  progress_reward  (default 1) the scale of the progress term; 0 leaves only the sparse success
                   reward and the time penalty.

Measured (tests/stub/test_stub_pushblock.py): both pushing +y all the way reach the goal in 22
steps, group return ~1.2 / 1.2 + 1 - 22 * 0.5 / 80 = 1.86 (1.875 with the last step's overshoot);
a still policy returns -0.5 (the whole timeout); one agent pushing alone for the whole timeout
moves the block 0.79 m, short of the goal.
"""
from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from protos.types import ActionSpec, DimensionProperty, ObservationSpec, ObservationType, StatsAggregationMethod
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep, tiled_areas

XML_PATH = Path(__file__).with_name("pushblock.xml")
AGENTS = 2
AREA_SPACING = 10.0  # m between area centres along y
SUBSTEPS = 5  # MuJoCo steps per control step (0.1 s)
GOAL_Y = 1.2  # the block's centre at y >= GOAL_Y is in the goal zone
FLOOR_HALF = 2.5  # an agent beyond |x| or |y| > FLOOR_HALF has left the floor
START_Y = -0.6
MAX_STEP = 80
TIME_PENALTY = -0.5 / MAX_STEP
SUCCESS_REWARD = 1.0
BLOCK_FRICTION = 9.0  # N, the block joints' dry friction (pushblock.xml); environment parameter block_friction
PROGRESS_REWARD = 1.0  # scale of the progress term; environment parameter progress_reward
LEAVE_REWARD = -1.0  # individual: without it, leaving early dodged the time penalty (measured: episodes
# shrank to 12 steps within 40k steps of POCA training and no block reached the goal)
_FORCE_OF_ACTION = np.array([[0, 0], [0, 1], [0, -1], [1, 0], [-1, 0]], dtype=np.float64)


def build_model(num_areas: int) -> mujoco.MjModel:
    """One MjModel with ``num_areas`` copies of pushblock.xml (names prefixed ``area<k>/``)."""
    return tiled_areas(XML_PATH, num_areas, AREA_SPACING)


class PushBlockTask(Task):
    name = "pushblock"
    behavior_name = "PushBlock"
    observation_specs = (
        ObservationSpec((11,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor_size11"),
    )
    action_spec = ActionSpec(continuous_size=0, discrete_branches=(5,))
    agents_per_area = AGENTS
    agents_interact = True
    max_step = MAX_STEP
    decision_period = 1
    sets_reward = False
    description = ("2 agents per area (one group) push a block into a goal zone, in time only together; "
                   "group rewards; both pushing: group return 1.875, standing still -0.50.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        self.rng = np.random.default_rng(seed)
        self.model = build_model(self.num_areas)
        self.data = mujoco.MjData(self.model)
        # per area, qpos/qvel columns: block x, y, agent0 x, y, agent1 x, y (the XML's joint order)
        self.qpos = self.data.qpos.reshape(self.num_areas, 6)
        self.friction = self.model.dof_frictionloss.reshape(self.num_areas, 6)  # a view: writes reach MuJoCo
        self.progress_scale = np.full(self.num_areas, PROGRESS_REWARD)
        self.qvel = self.data.qvel.reshape(self.num_areas, 6)
        self.ctrl = self.data.ctrl.reshape(self.num_areas, 4)
        self.episode_step = np.zeros(self.num_areas, dtype=np.int64)
        self.start = np.zeros((self.num_areas, AGENTS, 2))  # each agent's start spot
        self._area_of = np.repeat(np.arange(self.num_areas), AGENTS)
        self._groups = (self._area_of + 1).astype(np.int64)
        self.reset()

    # ------------------------------------------------------------------------------ episodes
    def reset(self, mask: np.ndarray | None = None) -> None:
        """Agents of ``mask`` start over: a whole area's pair starts a new group episode (the block
        too); a single agent (it left the floor) goes back to its start spot."""
        agents = self.all_agents(mask).reshape(self.num_areas, AGENTS)
        whole = agents.all(axis=1)
        for area in np.nonzero(whole)[0]:
            block_x = self.rng.uniform(-0.3, 0.3)
            offset = self.rng.uniform(0.15, 0.45, size=2)
            self.start[area] = [[block_x - offset[0], START_Y], [block_x + offset[1], START_Y]]
            self.qpos[area, 0:2] = (block_x, 0.0)
            self.friction[area, 0:2] = max(0.0, self.env_params.get("block_friction", BLOCK_FRICTION))
            self.progress_scale[area] = self.env_params.get("progress_reward", PROGRESS_REWARD)
            self.qvel[area, 0:2] = 0.0
            self.episode_step[area] = 0
        for area, agent in zip(*np.nonzero(agents)):
            self.qpos[area, 2 + 2 * agent:4 + 2 * agent] = self.start[area, agent]
            self.qvel[area, 2 + 2 * agent:4 + 2 * agent] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def group_ids(self) -> np.ndarray:
        return self._groups

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 11]] (see the module docstring)."""
        pos = self.qpos[:, 2:6].reshape(self.num_areas, AGENTS, 2)
        vel = self.qvel[:, 2:6].reshape(self.num_areas, AGENTS, 2)
        block = self.qpos[:, None, 0:2]
        block_vel = np.broadcast_to(self.qvel[:, None, 0:2], pos.shape)
        goal = np.broadcast_to((GOAL_Y - self.qpos[:, 1])[:, None, None], (self.num_areas, AGENTS, 1))
        mate = pos[:, ::-1] - pos
        obs = np.concatenate([pos, vel, block - pos, block_vel, goal, mate], axis=2)
        return [obs.reshape(self.num_agents, 11).astype(np.float32)]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """discrete int [n, 1] in 0..4 (others clamp) -> one 0.1 s control step of every area."""
        choice = np.clip(np.asarray(discrete).reshape(self.num_agents, -1)[:, 0], 0, 4)
        self.ctrl[:] = _FORCE_OF_ACTION[choice].reshape(self.num_areas, 4)
        before = self.qpos[:, 1].copy()
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self.episode_step += 1
        block_y = self.qpos[:, 1]
        success = block_y >= GOAL_Y
        timeout = ~success & (self.episode_step >= self.max_step)
        area_reward = TIME_PENALTY + self.progress_scale * (block_y - before) / GOAL_Y + np.where(success, SUCCESS_REWARD, 0.0)
        pos = self.qpos[:, 2:6].reshape(self.num_agents, 2)
        off_floor = (np.abs(pos) > FLOOR_HALF).any(axis=1)
        group_end = np.repeat(success | timeout, AGENTS)
        done = group_end | off_floor
        interrupted = np.repeat(timeout, AGENTS) & ~off_floor
        stats = []
        if (success | timeout).any():
            stats = [("PushBlock/Success", float(s), StatsAggregationMethod.AVERAGE)
                     for s in success[success | timeout].tolist()]
        return TaskStep(np.where(off_floor, LEAVE_REWARD, 0.0).astype(np.float32), done, interrupted, stats,
                        group_rewards=np.repeat(area_reward, AGENTS).astype(np.float32))
