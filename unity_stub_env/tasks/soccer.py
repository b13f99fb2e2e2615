"""``soccer``: a symmetric 1 v 1 ball game in MuJoCo, one behavior per team (for self-play).

Each area is a small walled pitch (x in +-PITCH_HALF_LENGTH, y in +-PITCH_HALF_WIDTH) with a goal
in each end wall (|y| < GOAL_HALF_WIDTH, a box behind it) and a ball. Two players, round pucks
on two slide joints each, push the ball: team 0 (behavior ``Soccer?team=0``) attacks +x, team 1
(``Soccer?team=1``) attacks -x. Agents are ordered area by area, team 0 then team 1; the academy
sends each team as its own behavior (``Task.behaviors``), both stepped in one ``mj_step``.

Everything a player sees and does is in its team's frame (x towards the goal it attacks, y to
its left; team 1's frame is the world turned by 180 degrees), so both teams have identical specs
and one policy can play either side.

Observation, float32 [12]: own position (x / L, y / W), own velocity / PLAYER_SPEED (2), ball
position relative to the player / L (2), ball velocity / PLAYER_SPEED (2), opponent position
relative to the player / L (2), ball position (x / L, y / W).
Actions: two discrete branches of 3, [stay, forward, back] and [stay, left, right]: a force of
PLAYER_FORCE along each chosen axis (joint damping makes PLAYER_SPEED the top speed).
Rewards: -TIME_PENALTY every control step; at a goal +1 for the scorer, -1 for the other player,
and the episode ends for both. After ``max_step`` control steps the episode is interrupted (a
draw, which ML-Agents' self-play does not rate). One control step is 0.04 s (2 MuJoCo steps of
0.02 s), a decision every 5 (0.2 s).

Start of an episode: each player on its own half (x = -START_X in its frame, y uniform in +-0.5),
the ball at rest near the centre (uniform in +-0.3 x +-0.5). Deterministic for a seed and actions.
"""
from __future__ import annotations

import mujoco
import numpy as np

from protos.types import (
    ActionSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    StatsAggregationMethod,
)
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep

AGENTS_PER_AREA = 2  # team 0 then team 1
AREA_SPACING = 10.0
PITCH_HALF_LENGTH = 1.6  # L
PITCH_HALF_WIDTH = 1.2  # W
GOAL_HALF_WIDTH = 0.7
GOAL_DEPTH = 0.5
WALL_HALF_THICKNESS = 0.05
WALL_HALF_HEIGHT = 0.25
PLAYER_RADIUS = 0.2
BALL_RADIUS = 0.12
PLAYER_FORCE = 12.0  # N
PLAYER_DAMPING = 6.0  # N s / m: top speed PLAYER_FORCE / PLAYER_DAMPING
PLAYER_SPEED = PLAYER_FORCE / PLAYER_DAMPING
TIMESTEP = 0.02
SUBSTEPS = 2
START_X = 1.0
GOAL_REWARD = 1.0
MAX_STEP = 250
TIME_PENALTY = 0.5 / MAX_STEP  # a whole episode without a goal costs 0.5

_DIRECTION = np.array([0.0, 1.0, -1.0])  # per action: stay, forward/left, back/right


def _box(x: float, y: float, hx: float, hy: float) -> str:
    return (f'<geom type="box" pos="{x:.4f} {y:.4f} {WALL_HALF_HEIGHT}" '
            f'size="{hx:.4f} {hy:.4f} {WALL_HALF_HEIGHT}" contype="3" conaffinity="3" rgba=".6 .6 .6 1"/>')


def build_mjcf(num_areas: int) -> str:
    """The MJCF text of ``num_areas`` pitches on a square grid (walls, goals, 2 players, a ball)."""
    L, W, G, D, T = PITCH_HALF_LENGTH, PITCH_HALF_WIDTH, GOAL_HALF_WIDTH, GOAL_DEPTH, WALL_HALF_THICKNESS
    columns = int(np.ceil(np.sqrt(num_areas)))
    bodies = []
    for a in range(num_areas):
        ox, oy = (a % columns) * AREA_SPACING, (a // columns) * AREA_SPACING
        side = (W - G) / 2
        walls = [
            _box(ox, oy + W + T, L + D + T, T), _box(ox, oy - W - T, L + D + T, T),  # side walls
        ]
        for s in (1, -1):
            walls += [
                _box(ox + s * (L + T), oy + G + side, T, side), _box(ox + s * (L + T), oy - G - side, T, side),
                _box(ox + s * (L + D + T), oy, T, G),  # back of the goal
                _box(ox + s * (L + D / 2), oy + G + T, D / 2, T), _box(ox + s * (L + D / 2), oy - G - T, D / 2, T),
            ]
        bodies.append(f'<body name="area{a}" pos="0 0 0">{"".join(walls)}</body>')
        for t in range(AGENTS_PER_AREA):
            bodies.append(
                f'<body name="player{a}_{t}" pos="{ox} {oy} {PLAYER_RADIUS / 2 + 0.01}">'
                f'<joint name="px{a}_{t}" type="slide" axis="1 0 0" damping="{PLAYER_DAMPING}"/>'
                f'<joint name="py{a}_{t}" type="slide" axis="0 1 0" damping="{PLAYER_DAMPING}"/>'
                f'<geom type="cylinder" size="{PLAYER_RADIUS} {PLAYER_RADIUS / 2}" mass="1" contype="2" '
                f'conaffinity="2" rgba="{"0 0 1 1" if t == 0 else "1 0 0 1"}"/></body>')
        bodies.append(
            f'<body name="ball{a}" pos="{ox} {oy} {BALL_RADIUS}"><freejoint name="ball{a}"/>'
            f'<geom type="sphere" size="{BALL_RADIUS}" mass="0.2" contype="3" conaffinity="3"/></body>')
    motors = "".join(f'<motor joint="p{axis}{a}_{t}" gear="{PLAYER_FORCE}" ctrlrange="-1 1" ctrllimited="true"/>'
                     for a in range(num_areas) for t in range(AGENTS_PER_AREA) for axis in ("x", "y"))
    return (
        '<mujoco model="soccer">'
        f'<option timestep="{TIMESTEP}" integrator="Euler" gravity="0 0 -9.81"/>'
        '<default><geom friction="0.6 0.005 0.005"/><joint armature="0"/></default>'
        '<worldbody><geom type="plane" size="0 0 1" contype="1" conaffinity="1"/>'
        f'{"".join(bodies)}</worldbody><actuator>{motors}</actuator></mujoco>'
    )


class SoccerTask(Task):
    name = "soccer"
    behavior_name = "Soccer"
    observation_specs = (
        ObservationSpec((12,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor_size12"),
    )
    action_spec = ActionSpec(continuous_size=0, discrete_branches=(3, 3))
    agents_per_area = AGENTS_PER_AREA
    max_step = MAX_STEP
    decision_period = 5
    sets_reward = False
    description = ("MuJoCo 1 v 1 ball game, behaviors Soccer?team=0 and Soccer?team=1 (self-play); "
                   "+1 / -1 at a goal, interrupted (a draw) at max_step.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.num_areas))
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        a = self.num_areas
        columns = int(np.ceil(np.sqrt(a)))
        self.origin = np.column_stack([(np.arange(a) % columns) * AREA_SPACING,
                                       (np.arange(a) // columns) * AREA_SPACING])  # [areas, 2]
        # bodies in order player 0, player 1, ball: per area qpos [p0 x y, p1 x y, ball 7], qvel [4 + 6]
        assert self.model.nq == 11 * a and self.model.nv == 10 * a
        self.qpos_rows = self.data.qpos.reshape(a, 11)
        self.qvel_rows = self.data.qvel.reshape(a, 10)
        self.ctrl_rows = self.data.ctrl.reshape(a, 2, 2)  # [area, team, axis]
        self.sign = np.tile([1.0, -1.0], a)  # [n]: each agent's frame (team 1 turned by 180 degrees)
        self.episode_step = np.zeros(a, dtype=np.int64)
        self.reset()

    def behaviors(self) -> list[tuple[str, np.ndarray]]:
        n = self.num_agents
        return [(f"{self.behavior_name}?team={t}", np.arange(t, n, AGENTS_PER_AREA)) for t in range(AGENTS_PER_AREA)]

    # ----------------------------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        """New episodes for the areas of the agents in ``mask`` (both players of an area together)."""
        areas = np.flatnonzero(self.all_agents(mask).reshape(self.num_areas, AGENTS_PER_AREA).any(axis=1))
        if len(areas) == 0:
            return
        k = len(areas)
        draws = self.rng.uniform(-1.0, 1.0, size=(k, 4))
        origin = self.origin[areas]
        qpos, qvel = self.qpos_rows, self.qvel_rows
        # player joints are offsets from the body's position (the area's centre)
        qpos[areas, 0], qpos[areas, 1] = -START_X, 0.5 * draws[:, 0]
        qpos[areas, 2], qpos[areas, 3] = START_X, -0.5 * draws[:, 1]
        qpos[areas, 4] = origin[:, 0] + 0.3 * draws[:, 2]
        qpos[areas, 5] = origin[:, 1] + 0.5 * draws[:, 3]
        qpos[areas, 6] = BALL_RADIUS
        qpos[areas, 7:11] = (1.0, 0.0, 0.0, 0.0)
        qvel[areas] = 0.0
        self.ctrl_rows[areas] = 0.0
        self.episode_step[areas] = 0
        mujoco.mj_forward(self.model, self.data)

    def _positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World-centred (relative to each area) players [areas, 2, 2] and their velocities, ball [areas, 2]
        and its velocity."""
        q, v = self.qpos_rows, self.qvel_rows
        players = q[:, 0:4].reshape(-1, 2, 2)
        player_vel = v[:, 0:4].reshape(-1, 2, 2)
        ball = q[:, 4:6] - self.origin
        return players, player_vel, ball, v[:, 4:6]

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 12]]: see the module docstring; each agent in its team's frame."""
        players, player_vel, ball, ball_vel = self._positions()
        s = self.sign[:, None]
        own = players.reshape(-1, 2) * s  # [n, 2]
        other = players[:, ::-1].reshape(-1, 2) * s
        ball_n = np.repeat(ball, AGENTS_PER_AREA, axis=0) * s
        scale = np.array([PITCH_HALF_LENGTH, PITCH_HALF_WIDTH])
        obs = np.empty((self.num_agents, 12), dtype=np.float32)
        obs[:, 0:2] = own / scale
        obs[:, 2:4] = player_vel.reshape(-1, 2) * s / PLAYER_SPEED
        obs[:, 4:6] = (ball_n - own) / PITCH_HALF_LENGTH
        obs[:, 6:8] = np.repeat(ball_vel, AGENTS_PER_AREA, axis=0) * s / PLAYER_SPEED
        obs[:, 8:10] = (other - own) / PITCH_HALF_LENGTH
        obs[:, 10:12] = ball_n / scale
        return [obs]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """discrete int [n, 2] -> one 0.04 s control step of every pitch."""
        choice = np.clip(np.asarray(discrete, dtype=np.int64).reshape(self.num_agents, 2), 0, 2)
        force = _DIRECTION[choice] * self.sign[:, None]  # [n, 2] in the world frame
        self.ctrl_rows[:] = force.reshape(self.num_areas, AGENTS_PER_AREA, 2)
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self.episode_step += 1
        ball = self.qpos_rows[:, 4:6] - self.origin
        in_mouth = np.abs(ball[:, 1]) < GOAL_HALF_WIDTH
        scored0 = in_mouth & (ball[:, 0] > PITCH_HALF_LENGTH + BALL_RADIUS)  # team 0 scored
        scored1 = in_mouth & (ball[:, 0] < -PITCH_HALF_LENGTH - BALL_RADIUS)
        goal = scored0 | scored1
        interrupted_area = ~goal & (self.episode_step >= self.max_step)
        done_area = goal | interrupted_area
        won = np.column_stack([scored0, scored1])  # [areas, team]
        lost = won[:, ::-1]
        rewards = (GOAL_REWARD * (won.astype(np.float32) - lost.astype(np.float32)) - TIME_PENALTY).reshape(-1)
        done = np.repeat(done_area, AGENTS_PER_AREA)
        interrupted = np.repeat(interrupted_area, AGENTS_PER_AREA)
        stats = []
        if done_area.any():
            stats = [("Soccer/Goal Scored", float(g), StatsAggregationMethod.AVERAGE)
                     for g in goal[done_area].tolist()]
        return TaskStep(rewards.astype(np.float32), done, interrupted, stats)


def play_match(task: SoccerTask, team0, team1, decisions: int) -> tuple[int, int, int]:
    """Play ``decisions`` decisions on every pitch of ``task``; ``team0`` / ``team1`` map the
    observations of that team's players (float32 [areas, 12]) to actions (int [areas, 2]).
    Returns team 0's (wins, losses, draws): goals for, goals against, episodes interrupted."""
    wins = losses = draws = 0
    actions = np.zeros((task.num_agents, 2), dtype=np.int64)
    for _ in range(decisions):
        obs = task.observe()[0]
        actions[0::2] = team0(obs[0::2])
        actions[1::2] = team1(obs[1::2])
        for _ in range(task.decision_period):
            result = task.step(np.zeros((task.num_agents, 0), np.float32), actions)
            if result.done.any():
                ended = result.done[0::2]
                reward, timeout = result.rewards[0::2][ended], result.interrupted[0::2][ended]
                wins += int((reward > 0).sum())
                losses += int(((reward < 0) & ~timeout).sum())
                draws += int(timeout.sum())
                task.reset(result.done)
    return wins, losses, draws
