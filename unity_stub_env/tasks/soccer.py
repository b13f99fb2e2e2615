"""``soccer`` (1 v 1) and ``soccer_twos`` (2 v 2): a symmetric ball game in MuJoCo, one behavior per
team (for self-play).

Each area is a small walled pitch (x in +-PITCH_HALF_LENGTH, y in +-PITCH_HALF_WIDTH) with a goal
in each end wall (|y| < GOAL_HALF_WIDTH, a box behind it) and a ball. P players per team (P = 1 for
``soccer``, 2 for ``soccer_twos``; the number of bodies is fixed when the model is built, so it is
the task, not an environment parameter), round pucks on two slide joints each, push the ball:
team 0 (behavior ``Soccer?team=0`` / ``SoccerTwos?team=0``) attacks +x, team 1 attacks -x. Agents
are ordered area by area, team 0's players then team 1's; the academy sends each team as its own
behavior (``Task.behaviors``), both stepped in one ``mj_step``.

Everything a player sees and does is in its team's frame (x towards the goal it attacks, y to
its left; team 1's frame is the world turned by 180 degrees), so both teams have identical specs
and one policy can play either side.

Observation, float32 [8 + 4 P]: own position (x / L, y / W), own velocity / PLAYER_SPEED (2), ball
position relative to the player / L (2), ball velocity / PLAYER_SPEED (2), each teammate's position
relative to the player / L (2 each, P - 1 of them), each opponent's position relative to the
player / L (2 each, in player order), ball position (x / L, y / W). ``soccer``: 12, ``soccer_twos``: 16.
Actions: two discrete branches of 3, [stay, forward, back] and [stay, left, right]: a force of
PLAYER_FORCE along each chosen axis (joint damping makes PLAYER_SPEED the top speed).

Rewards, ``soccer``: individual, -TIME_PENALTY every control step; at a goal +1 for the scorer, -1
for the other player. ``soccer_twos`` (as Unity's SoccerTwos): each team's two players form one agent
group (group id 2 * area + team + 1 on the wire) and the goal is a group reward: +1 - (k - 1) /
max_step for the scoring team (k the control step of the episode in which the ball crossed the
line, so a goal always pays > 0), -1 for the other; no individual reward. Both tasks: a goal ends
the episode of every player of the pitch (the group episode); after ``max_step`` control steps it
is interrupted (a draw, which ML-Agents' self-play does not rate). One control step is 0.04 s (2
MuJoCo steps of 0.02 s), a decision every 5 (0.2 s).

Start of an episode: each team on its own half, its player k at x = -START_X in the team's frame,
y = ``lanes[k]`` + uniform in +-``lane_spread`` (1 v 1: y uniform in +-0.5; 2 v 2: y = +0.55 and
-0.55, each +-0.15), the ball at rest near the centre (uniform in +-0.3 x +-0.5). Deterministic for
a seed and actions.
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

TEAMS = 2
AREA_SPACING = 10.0
PITCH_HALF_LENGTH = 1.6  # L
PITCH_HALF_WIDTH = 1.2  # W
GOAL_HALF_WIDTH = 0.7
GOAL_DEPTH = 0.5
WALL_HALF_THICKNESS = 0.05
WALL_HALF_HEIGHT = 0.25
PLAYER_RADIUS = 0.2
PLAYER_MASS = 1.0
BALL_RADIUS = 0.12
BALL_MASS = 0.2
PLAYER_FORCE = 12.0  # N
PLAYER_DAMPING = 6.0  # N s / m: top speed PLAYER_FORCE / PLAYER_DAMPING
PLAYER_SPEED = PLAYER_FORCE / PLAYER_DAMPING
TIMESTEP = 0.02
SUBSTEPS = 2
START_X = 1.0
GOAL_REWARD = 1.0
MAX_STEP = 250
TIME_PENALTY = 0.5 / MAX_STEP  # soccer: a whole episode without a goal costs 0.5

_DIRECTION = np.array([0.0, 1.0, -1.0])  # per action: stay, forward/left, back/right


def _box(x: float, y: float, hx: float, hy: float) -> str:
    return (f'<geom type="box" pos="{x:.4f} {y:.4f} {WALL_HALF_HEIGHT}" '
            f'size="{hx:.4f} {hy:.4f} {WALL_HALF_HEIGHT}" contype="3" conaffinity="3" rgba=".6 .6 .6 1"/>')


def build_mjcf(num_areas: int, players_per_team: int = 1) -> str:
    """The MJCF text of ``num_areas`` pitches on a square grid (walls, goals, 2 P players, a ball).
    Player ``i`` of area ``a`` (team i // P) is body ``player{a}_{i}`` with joints ``px{a}_{i}``,
    ``py{a}_{i}``."""
    L, W, G, D, T = PITCH_HALF_LENGTH, PITCH_HALF_WIDTH, GOAL_HALF_WIDTH, GOAL_DEPTH, WALL_HALF_THICKNESS
    columns = int(np.ceil(np.sqrt(num_areas)))
    players = TEAMS * players_per_team
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
        for i in range(players):
            bodies.append(
                f'<body name="player{a}_{i}" pos="{ox} {oy} {PLAYER_RADIUS / 2 + 0.01}">'
                f'<joint name="px{a}_{i}" type="slide" axis="1 0 0" damping="{PLAYER_DAMPING}"/>'
                f'<joint name="py{a}_{i}" type="slide" axis="0 1 0" damping="{PLAYER_DAMPING}"/>'
                f'<geom type="cylinder" size="{PLAYER_RADIUS} {PLAYER_RADIUS / 2}" mass="{PLAYER_MASS}" '
                f'contype="2" conaffinity="2" rgba="{"0 0 1 1" if i < players_per_team else "1 0 0 1"}"/></body>')
        bodies.append(
            f'<body name="ball{a}" pos="{ox} {oy} {BALL_RADIUS}"><freejoint name="ball{a}"/>'
            f'<geom type="sphere" size="{BALL_RADIUS}" mass="{BALL_MASS}" contype="3" conaffinity="3"/></body>')
    motors = "".join(f'<motor joint="p{axis}{a}_{i}" gear="{PLAYER_FORCE}" ctrlrange="-1 1" ctrllimited="true"/>'
                     for a in range(num_areas) for i in range(players) for axis in ("x", "y"))
    return (
        f'<mujoco model="soccer{players_per_team}v{players_per_team}">'
        f'<option timestep="{TIMESTEP}" integrator="Euler" gravity="0 0 -9.81"/>'
        '<default><geom friction="0.6 0.005 0.005"/><joint armature="0"/></default>'
        '<worldbody><geom type="plane" size="0 0 1" contype="1" conaffinity="1"/>'
        f'{"".join(bodies)}</worldbody><actuator>{motors}</actuator></mujoco>'
    )


def _vector_spec(size: int) -> tuple[ObservationSpec, ...]:
    return (ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, f"VectorSensor_size{size}"),)


class SoccerTask(Task):
    """1 v 1, individual rewards (the module docstring); ``SoccerTwosTask`` is the 2 v 2."""

    name = "soccer"
    behavior_name = "Soccer"
    players_per_team = 1
    lanes: tuple[float, ...] = (0.0,)  # each player's start y in its team's frame, +- lane_spread
    lane_spread = 0.5
    team_groups = False  # True: each team of an area is one agent group and goals are group rewards
    observation_specs = _vector_spec(12)
    action_spec = ActionSpec(continuous_size=0, discrete_branches=(3, 3))
    agents_per_area = TEAMS * players_per_team
    agents_interact = True
    max_step = MAX_STEP
    decision_period = 5
    sets_reward = False
    description = ("MuJoCo 1 v 1 ball game, behaviors Soccer?team=0 and Soccer?team=1 (self-play); "
                   "+1 / -1 at a goal, interrupted (a draw) at max_step.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        P, a = self.players_per_team, self.num_areas
        m = self.agents_per_area
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(a, P))
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        columns = int(np.ceil(np.sqrt(a)))
        self.origin = np.column_stack([(np.arange(a) % columns) * AREA_SPACING,
                                       (np.arange(a) // columns) * AREA_SPACING])  # [areas, 2]
        # bodies in order: the players (team 0's, then team 1's), the ball:
        # per area qpos [2 per player, ball 7], qvel [2 per player, ball 6]
        assert self.model.nq == (2 * m + 7) * a and self.model.nv == (2 * m + 6) * a
        self.qpos_rows = self.data.qpos.reshape(a, 2 * m + 7)
        self.qvel_rows = self.data.qvel.reshape(a, 2 * m + 6)
        self.ctrl_rows = self.data.ctrl.reshape(a, m, 2)  # [area, player, axis]
        team = np.arange(m) // P  # [m] each player's team
        self.sign = np.tile(np.where(team == 0, 1.0, -1.0), a)  # [n]: each agent's frame (team 1 turned)
        # per player of an area: its teammates' and its opponents' indices, in player order
        self._mates = np.array([[j for j in range(m) if team[j] == team[i] and j != i] for i in range(m)],
                               dtype=np.int64).reshape(m, P - 1)
        self._opponents = np.array([[j for j in range(m) if team[j] != team[i]] for i in range(m)], dtype=np.int64)
        self._groups = (2 * np.repeat(np.arange(a), m) + np.tile(team, a) + 1).astype(np.int64)
        self.episode_step = np.zeros(a, dtype=np.int64)
        self.reset()

    def behaviors(self) -> list[tuple[str, np.ndarray]]:
        rows = np.arange(self.num_agents).reshape(self.num_areas, TEAMS, self.players_per_team)
        return [(f"{self.behavior_name}?team={t}", rows[:, t].reshape(-1)) for t in range(TEAMS)]

    def group_ids(self) -> np.ndarray | None:
        """int64 [n]: 2 * area + team + 1 with team groups (``soccer_twos``), else None (no groups)."""
        return self._groups if self.team_groups else None

    # ----------------------------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        """New episodes for the areas of the agents in ``mask`` (every player of an area together)."""
        m, P = self.agents_per_area, self.players_per_team
        areas = np.flatnonzero(self.all_agents(mask).reshape(self.num_areas, m).any(axis=1))
        if len(areas) == 0:
            return
        k = len(areas)
        draws = self.rng.uniform(-1.0, 1.0, size=(k, m + 2))  # one per player's y, two for the ball
        origin = self.origin[areas]
        qpos, qvel = self.qpos_rows, self.qvel_rows
        # player joints are offsets from the body's position (the area's centre); team 1 mirrored
        for i in range(m):
            sign = 1.0 if i < P else -1.0
            qpos[areas, 2 * i] = -sign * START_X
            qpos[areas, 2 * i + 1] = sign * (self.lanes[i % P] + self.lane_spread * draws[:, i])
        b = 2 * m
        qpos[areas, b] = origin[:, 0] + 0.3 * draws[:, m]
        qpos[areas, b + 1] = origin[:, 1] + 0.5 * draws[:, m + 1]
        qpos[areas, b + 2] = BALL_RADIUS
        qpos[areas, b + 3:b + 7] = (1.0, 0.0, 0.0, 0.0)
        qvel[areas] = 0.0
        self.ctrl_rows[areas] = 0.0
        self.episode_step[areas] = 0
        mujoco.mj_forward(self.model, self.data)

    def _positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World-centred (relative to each area) players [areas, 2 P, 2] and their velocities, ball
        [areas, 2] and its velocity."""
        q, v, b = self.qpos_rows, self.qvel_rows, 2 * self.agents_per_area
        players = q[:, :b].reshape(self.num_areas, -1, 2)
        player_vel = v[:, :b].reshape(self.num_areas, -1, 2)
        ball = q[:, b:b + 2] - self.origin
        return players, player_vel, ball, v[:, b:b + 2]

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 8 + 4 P]]: see the module docstring; each agent in its team's frame."""
        players, player_vel, ball, ball_vel = self._positions()
        m, n = self.agents_per_area, self.num_agents
        s = self.sign[:, None]
        own = players.reshape(-1, 2) * s  # [n, 2]
        mates = players[:, self._mates].reshape(n, self.players_per_team - 1, 2) * s[:, None]  # [n, P - 1, 2]
        opponents = players[:, self._opponents].reshape(n, -1, 2) * s[:, None]  # [n, P, 2]
        ball_n = np.repeat(ball, m, axis=0) * s
        scale = np.array([PITCH_HALF_LENGTH, PITCH_HALF_WIDTH])
        others = np.concatenate([mates, opponents], axis=1) - own[:, None]  # [n, 2 P - 1, 2]
        obs = np.empty((n, self.observation_specs[0].shape[0]), dtype=np.float32)
        obs[:, 0:2] = own / scale
        obs[:, 2:4] = player_vel.reshape(-1, 2) * s / PLAYER_SPEED
        obs[:, 4:6] = (ball_n - own) / PITCH_HALF_LENGTH
        obs[:, 6:8] = np.repeat(ball_vel, m, axis=0) * s / PLAYER_SPEED
        obs[:, 8:-2] = others.reshape(n, -1) / PITCH_HALF_LENGTH
        obs[:, -2:] = ball_n / scale
        return [obs]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """discrete int [n, 2] -> one 0.04 s control step of every pitch."""
        m, P = self.agents_per_area, self.players_per_team
        choice = np.clip(np.asarray(discrete, dtype=np.int64).reshape(self.num_agents, 2), 0, 2)
        force = _DIRECTION[choice] * self.sign[:, None]  # [n, 2] in the world frame
        self.ctrl_rows[:] = force.reshape(self.num_areas, m, 2)
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self.episode_step += 1
        b = 2 * m
        ball = self.qpos_rows[:, b:b + 2] - self.origin
        in_mouth = np.abs(ball[:, 1]) < GOAL_HALF_WIDTH
        scored0 = in_mouth & (ball[:, 0] > PITCH_HALF_LENGTH + BALL_RADIUS)  # team 0 scored
        scored1 = in_mouth & (ball[:, 0] < -PITCH_HALF_LENGTH - BALL_RADIUS)
        goal = scored0 | scored1
        interrupted_area = ~goal & (self.episode_step >= self.max_step)
        done_area = goal | interrupted_area
        won = np.column_stack([scored0, scored1]).astype(np.float32)  # [areas, team]
        lost = won[:, ::-1]
        group_rewards = None
        if self.team_groups:  # SoccerTwos: the goal is the groups' reward, less the time used for the scorer
            time_used = ((self.episode_step - 1) / self.max_step).astype(np.float32)[:, None]
            per_team = GOAL_REWARD * (won * (1.0 - time_used) - lost)
            group_rewards = np.repeat(per_team, P, axis=1).reshape(-1).astype(np.float32)
            rewards = np.zeros(self.num_agents, dtype=np.float32)
        else:
            per_team = GOAL_REWARD * (won - lost) - TIME_PENALTY
            rewards = np.repeat(per_team, P, axis=1).reshape(-1).astype(np.float32)
        done = np.repeat(done_area, m)
        interrupted = np.repeat(interrupted_area, m)
        stats = []
        if done_area.any():
            stats = [(f"{self.behavior_name}/Goal Scored", float(g), StatsAggregationMethod.AVERAGE)
                     for g in goal[done_area].tolist()]
        return TaskStep(rewards, done, interrupted, stats, group_rewards)


class SoccerTwosTask(SoccerTask):
    """2 v 2 as Unity's SoccerTwos: each team of a pitch one agent group, goals as group rewards."""

    name = "soccer_twos"
    behavior_name = "SoccerTwos"
    players_per_team = 2
    lanes = (0.55, -0.55)
    lane_spread = 0.15
    team_groups = True
    observation_specs = _vector_spec(16)
    agents_per_area = TEAMS * players_per_team
    description = ("MuJoCo 2 v 2 ball game, behaviors SoccerTwos?team=0 and SoccerTwos?team=1 (POCA + "
                   "self-play), each team of a pitch one agent group; group reward +1 - time used / -1 at a "
                   "goal, interrupted (a draw) at max_step.")


def play_match(task: SoccerTask, team0, team1, decisions: int) -> tuple[int, int, int]:
    """Play ``decisions`` decisions on every pitch of ``task``; ``team0`` / ``team1`` map the
    observations of that team's players (float32 [areas * P, obs], area by area) to actions
    (int [areas * P, 2]). Returns team 0's (wins, losses, draws): goals for, goals against,
    episodes interrupted."""
    wins = losses = draws = 0
    (_, rows0), (_, rows1) = task.behaviors()
    first = rows0[::task.players_per_team]  # team 0's first player on each pitch
    actions = np.zeros((task.num_agents, 2), dtype=np.int64)
    for _ in range(decisions):
        obs = task.observe()[0]
        actions[rows0] = team0(obs[rows0])
        actions[rows1] = team1(obs[rows1])
        for _ in range(task.decision_period):
            result = task.step(np.zeros((task.num_agents, 0), np.float32), actions)
            if result.done.any():
                total = result.rewards if result.group_rewards is None else result.rewards + result.group_rewards
                ended = result.done[first]
                reward, timeout = total[first][ended], result.interrupted[first][ended]
                wins += int((reward > 0).sum())
                losses += int(((reward < 0) & ~timeout).sum())
                draws += int(timeout.sum())
                task.reset(result.done)
    return wins, losses, draws
