"""``creature``: a generated creature learns to walk to targets over generated terrain (the task;
``terrain.py`` draws the heightfields, ``evaluation.py`` measures a policy; the creature report it
follows: docs/stub-tasks.md, "Seed projects").

One agent per area. Each area is an arena: a 20 m x 20 m heightfield (flat, or Perlin noise whose
height is set by the roughness), four walls 1 m high, optional box obstacles, and a target; the
agent is one generated creature (``unity_stub_env.creatures``). Areas sit in a row 24 m apart (x)
in one MjModel, so one ``mj_step`` advances every arena; creatures never touch one another.

Environment parameters (Unity's EnvironmentParameters; read where said):
  creature_kind       0 quadruped (default), 1 biped, 2 L-system      at construction
  creature_seed       the generator's seed (default 0)                  at construction
  terrain_roughness   0 (flat, default) .. 1: noise height 0 .. 0.6 m  at each episode start
  obstacles           number of boxes in the arena, 0 (default) .. 6    at each episode start
  target_speed        the speed to match, m/s (default 1.0)             at each episode start
  fall_penalty        the reward of a step that ends in a fall is        at each episode start
                      -fall_penalty when > 0 (default 0: no penalty)
  gait_clock_hz       > 0: two clock observations at this frequency     at construction
                      (default 0: none; our addition, not Walker's)
All arenas of a run share one creature morphology: the agents of one behavior must share one
observation and action spec, and the spec depends on the bone and hinge counts. The morphology is
fixed when the task is built (the trainer's first message carries the side channel before the
stub builds its tasks); terrain, obstacles and target speed change at every episode start, so a
curriculum can raise the roughness without a rebuild. The heightfield of an arena is drawn anew
(``perlin``, seeded from the task's generator) whenever its agent's episode starts, by rewriting
``model.hfield_data`` (MuJoCo's collision reads it every step; nothing is uploaded headless).

Episode start: the creature in its rest pose, every hinge at 0, at the arena centre, turned by a
uniform random yaw, lifted so its lowest point is 5 cm above the highest terrain within 1.5 m of
the centre; a new target uniform in the arena's inner 16 m x 16 m, at least 4 m from the centre.

Orientation reference (Walker's orientation cube): a frame at the creature's centre of mass (CoM),
z up, its forward axis the horizontal direction from the CoM to the target. "cube frame" below.

Actions, float [-1, 1], one per hinge of the creature (``skeleton.LIMITS``, in bone order, axes
lateral, ventral, proximal): the target angle of the hinge's position servo, a * max for a >= 0
and a * |min| for a < 0 (a = 0 holds the rest pose).

Observations, float32 [14 + 10 B + J] per agent (B bones, J hinges), in this order:
  0..2    the average velocity of the bones (the mean over bones of each bone CoM's displacement in
          the control step / 0.05 s), cube frame
  3..5    the goal velocity, cube frame: (target_speed, 0, 0)
  6..9    the root bone's orientation in the cube frame, quaternion (w, x, y, z), w >= 0
  10..12  the target minus the creature's CoM, cube frame
  13      the CoM's height above the terrain below it
  per bone: ground contact in the control step (0/1), its CoM's velocity (3, cube frame), its
          angular velocity (3, cube frame), its CoM minus the creature's CoM (3, cube frame)
  per hinge: its angle mapped linearly from [min, max] to [-1, 1]
  with gait_clock_hz = f > 0 only, two more: sin(2 pi f t), cos(2 pi f t), t = the episode's time
          (control steps x 0.05 s; 0 at the episode start). A policy that sees only the state has
          no time input, so its mean action is a function of the pose alone; the clock lets the
          mean action be a rhythm (docs/stub-tasks.md, "creature: a recipe that walks with its
          mean actions", says why a run may want it). Neither Walker nor the creature report has it.

Reward per control step (Walker's product of two terms, both in [0, 1]):
  match_speed = (1 - (min(|v_goal - v_avg|, s) / s)^2)^2, s = target_speed, v_goal = s * cube forward,
                v_avg the average bone velocity above (world frame)
  look        = (cube_forward . root_forward + 1) / 2, root_forward = the root bone's +x axis (the
                creature's facing in its rest pose; generated creatures have no separate face frame)
  reward      = match_speed * look
Reaching the target (the CoM within 1 m of it horizontally) moves the target (no reward of its own,
as in Walker). The episode ends when a torso, hip, shoulder, neck or head bone touches the ground,
walls or an obstacle (Walker ends on its body parts' ground contact): without penalty by default,
as Walker; with fall_penalty > 0 that step's reward is -fall_penalty instead (Walker's
ground-contact component has this as its option "penalize ground contact", which sets the step's
reward to a penalty such as -1; docs/stub-tasks.md, "creature: a recipe that walks with its mean
actions", says why a run may want it). The episode is
interrupted after max_step = 1000 control steps (50 s). A non-finite state (never seen) ends the
episode too. Stats at an episode's end: Creature/Targets Reached, Creature/Distance (the CoM's
horizontal path length, m).

Physics: MuJoCo timestep 0.005 s, 10 steps per control step (0.05 s), one decision per control
step (20 decisions/s; Walker decides every 5 steps of 1/75 s, 15/s).
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
from unity_stub_env.creatures import generate, mjcf
from unity_stub_env.creatures.skeleton import Skeleton
from unity_stub_env.geometry import matrix_quat
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep
from unity_stub_env.tasks.creature.terrain import NOISE_CELL, perlin

KINDS = ("quadruped", "biped", "lsystem")
ARENA_HALF = 10.0  # m, half the side of the arena (the heightfield's half extent)
AREA_SPACING = 24.0
WALL_HEIGHT = 1.0
WALL_THICKNESS = 0.2
HFIELD_SIZE = 81  # rows = columns of the heightfield grid (0.25 m cells)
MAX_TERRAIN_HEIGHT = 0.6  # m at roughness 1
HFIELD_BASE = 0.5
MAX_OBSTACLES = 6
TARGET_RANGE = 8.0
TARGET_MIN_DISTANCE = 4.0
REACH_DISTANCE = 1.0
SPAWN_RADIUS = 1.5
SPAWN_CLEARANCE = 0.05
SUBSTEPS = 10
MAX_STEP = 1000
VITAL = ("torso", "hip", "shoulder", "neck", "head")
DEFAULTS = {"creature_kind": 0.0, "creature_seed": 0.0, "terrain_roughness": 0.0, "obstacles": 0.0,
            "target_speed": 1.0, "fall_penalty": 0.0, "gait_clock_hz": 0.0}
PARK = np.array([0.0, 0.0, -10.0])  # where unused obstacles wait (below every heightfield)


def match_speed_reward(goal_velocity: np.ndarray, velocity: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Walker's speed term: (1 - (min(|goal - v|, s) / s)^2)^2 per agent."""
    delta = np.minimum(np.linalg.norm(goal_velocity - velocity, axis=-1), speed)
    return (1.0 - (delta / speed) ** 2) ** 2


def look_reward(cube_forward: np.ndarray, facing: np.ndarray) -> np.ndarray:
    """Walker's look-at-target term: (cube_forward . facing + 1) / 2 per agent."""
    return ((cube_forward * facing).sum(axis=-1) + 1.0) / 2.0


def creature_of(env_params: EnvironmentParameters) -> Skeleton:
    kind = int(round(env_params.get("creature_kind", DEFAULTS["creature_kind"])))
    if not 0 <= kind < len(KINDS):
        raise ValueError(f"environment parameter creature_kind must be 0 (quadruped), 1 (biped) or "
                         f"2 (lsystem), got {kind}")
    return generate(KINDS[kind], int(round(env_params.get("creature_seed", DEFAULTS["creature_seed"]))))


def arena_xml(skeleton: Skeleton, num_areas: int) -> str:
    """The MJCF of ``num_areas`` arenas, each with its heightfield ``hf<i>``, walls, obstacles
    ``a<i>/obstacle<k>``, target ``a<i>/target`` and creature (names prefixed ``a<i>/``)."""
    f = mjcf.fmt
    assets = "".join(f'    <hfield name="hf{i}" nrow="{HFIELD_SIZE}" ncol="{HFIELD_SIZE}" '
                     f'size="{f(ARENA_HALF, ARENA_HALF, MAX_TERRAIN_HEIGHT, HFIELD_BASE)}"/>\n'
                     for i in range(num_areas))
    world = []
    ground = mjcf.GROUND_CONTACT
    for i in range(num_areas):
        cx = i * AREA_SPACING
        world.append(f'    <geom name="a{i}/terrain" type="hfield" hfield="hf{i}" pos="{f(cx, 0, 0)}" {ground}/>')
        h, t = ARENA_HALF + WALL_THICKNESS, WALL_THICKNESS
        for name, pos, size in (("n", (cx, h, 0), (h + t, t, WALL_HEIGHT)), ("s", (cx, -h, 0), (h + t, t, WALL_HEIGHT)),
                                ("e", (cx + h, 0, 0), (t, h + t, WALL_HEIGHT)), ("w", (cx - h, 0, 0), (t, h + t, WALL_HEIGHT))):
            world.append(f'    <geom name="a{i}/wall_{name}" type="box" pos="{f(pos)}" size="{f(size)}" {ground}/>')
        for k in range(MAX_OBSTACLES):
            world.append(f'    <geom name="a{i}/obstacle{k}" type="box" pos="{f(PARK)}" size="0.5 0.5 0.3" {ground}/>')
        world.append(f'    <geom name="a{i}/target" type="sphere" pos="{f(cx, 5, 0.5)}" size="0.3" '
                     'contype="0" conaffinity="0" rgba="1 0.5 0 1"/>')
        world.append(mjcf.body(skeleton, prefix=f"a{i}/", offset=(cx, 0.0, 0.0), indent=2).rstrip("\n"))
    return (mjcf.header(f"creature-arenas-{skeleton.kind}-{skeleton.seed}") + mjcf.defaults(skeleton)
            + "  <asset>\n" + assets + "  </asset>\n  <worldbody>\n" + "\n".join(world) + "\n  </worldbody>\n"
            + "  <actuator>\n" + "".join(mjcf.actuators(skeleton, prefix=f"a{i}/") for i in range(num_areas))
            + "  </actuator>\n</mujoco>\n")


def observation_size(skeleton: Skeleton, clock: bool = False) -> int:
    """The observation's length for ``skeleton``: 14 + 10 per bone + 1 per hinge, + 2 with the gait
    clock (module docstring)."""
    return 14 + 10 * len(skeleton.bones) + skeleton.num_hinges() + (2 if clock else 0)


def gait_clock_of(env_params: EnvironmentParameters) -> float:
    """The environment parameter gait_clock_hz (0: no clock observations), checked."""
    hz = float(env_params.get("gait_clock_hz", DEFAULTS["gait_clock_hz"]))
    if not (np.isfinite(hz) and hz >= 0):
        raise ValueError(f"environment parameter gait_clock_hz must be >= 0 (0: no clock), got {hz:g}")
    return hz


def _specs(skeleton: Skeleton, clock: bool = False) -> tuple[tuple[ObservationSpec, ...], ActionSpec]:
    size = observation_size(skeleton, clock)
    return ((ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, f"VectorSensor_size{size}"),),
            ActionSpec(continuous_size=skeleton.num_hinges(), discrete_branches=()))


_DEFAULT_SPECS = _specs(generate(KINDS[0], 0))


class CreatureTask(Task):
    name = "creature"
    behavior_name = "Creature"
    observation_specs, action_spec = _DEFAULT_SPECS  # the default creature's; instances set their own
    agents_per_area = 1
    max_step = MAX_STEP
    decision_period = 1
    sets_reward = False
    description = ("Generated creature walking to targets over generated terrain (docs/stub-tasks.md). Shapes shown for "
                   "the default quadruped (creature_kind 0, creature_seed 0); they follow the creature. "
                   "Reward: Walker's match-speed x look-at-target. Env params: creature_kind, creature_seed, "
                   "terrain_roughness, obstacles, target_speed, fall_penalty, gait_clock_hz.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        n = self.num_agents
        self.skeleton = creature_of(self.env_params)
        self.gait_clock_hz = gait_clock_of(self.env_params)
        self.observation_specs, self.action_spec = _specs(self.skeleton, self.gait_clock_hz > 0)
        self.model = mujoco.MjModel.from_xml_string(arena_xml(self.skeleton, n))
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        model, bones = self.model, self.skeleton.bones
        self.centre = np.column_stack([np.arange(n) * AREA_SPACING, np.zeros(n), np.zeros(n)])
        self.body = np.array([[model.body(f"a{i}/{b.name}").id for b in bones] for i in range(n)])
        self.root = self.body[:, 0]
        root_joint = [model.joint(f"a{i}/root") for i in range(n)]
        self.root_qpos = np.array([j.qposadr[0] for j in root_joint])[:, None] + np.arange(7)
        self.root_dof = np.array([j.dofadr[0] for j in root_joint])[:, None] + np.arange(6)
        hinges = [f"{b.name}_{axis}" for b in bones[1:] for axis, _, _ in b.free_axes()]
        self.hinge_qpos = np.array([[model.joint(f"a{i}/{h}").qposadr[0] for h in hinges] for i in range(n)],
                                   dtype=np.int64).reshape(n, len(hinges))
        self.hinge_dof = np.array([[model.joint(f"a{i}/{h}").dofadr[0] for h in hinges] for i in range(n)],
                                  dtype=np.int64).reshape(n, len(hinges))
        self.actuator = np.array([[model.actuator(f"a{i}/{h}").id for h in hinges] for i in range(n)],
                                 dtype=np.int64).reshape(n, len(hinges))
        ranges = model.jnt_range[[model.joint(f"a0/{h}").id for h in hinges]].reshape(len(hinges), 2)
        self.hinge_low, self.hinge_high = ranges[:, 0], ranges[:, 1]
        # per geom: owning agent and bone (-1 for the world's geoms)
        self.geom_agent = np.full(model.ngeom, -1)
        self.geom_bone = np.full(model.ngeom, -1)
        for i in range(n):
            for k, b in enumerate(bones):
                g = model.geom(f"a{i}/{b.name}").id
                self.geom_agent[g], self.geom_bone[g] = i, k
        self.vital = np.array([b.category in VITAL for b in bones])
        self.target_geom = np.array([model.geom(f"a{i}/target").id for i in range(n)])
        self.obstacle_geom = np.array([[model.geom(f"a{i}/obstacle{k}").id for k in range(MAX_OBSTACLES)]
                                       for i in range(n)])
        self.hfield_adr = np.array([model.hfield_adr[model.hfield(f"hf{i}").id] for i in range(n)])
        self.rest_qpos = np.array(model.qpos0[self.root_qpos[0]])  # the root's rest position (area 0)
        self.rest_qpos[:3] -= self.centre[0]
        self.control_dt = SUBSTEPS * float(model.opt.timestep)
        self.grid = np.linspace(-ARENA_HALF, ARENA_HALF, HFIELD_SIZE)
        # per-agent state
        self.target = np.zeros((n, 3))
        self.target_speed = np.full(n, DEFAULTS["target_speed"])
        self.fall_penalty = np.full(n, DEFAULTS["fall_penalty"])
        self.roughness = np.zeros(n)
        self.episode_step = np.zeros(n, dtype=np.int64)
        self.targets_reached = np.zeros(n, dtype=np.int64)
        self.distance = np.zeros(n)
        self.contact = np.zeros((n, len(bones)), dtype=bool)
        self.velocity = np.zeros((n, len(bones), 3))
        self.last_reward_terms = (np.zeros(n), np.zeros(n))  # match_speed, look of the last step
        self.reset()

    # --- terrain, targets --------------------------------------------------------------------------
    def heights(self, agent: int) -> np.ndarray:
        """float [HFIELD_SIZE, HFIELD_SIZE] terrain heights (m) of an arena; row = y, column = x."""
        adr = self.hfield_adr[agent]
        data = self.model.hfield_data[adr: adr + HFIELD_SIZE * HFIELD_SIZE]
        return data.reshape(HFIELD_SIZE, HFIELD_SIZE) * MAX_TERRAIN_HEIGHT

    def terrain_height(self, agents: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """The terrain height at the grid point nearest to each world point ``xy`` [k, 2]."""
        local = xy - self.centre[agents, :2]
        col = np.clip(np.rint((local[:, 0] + ARENA_HALF) / (2 * ARENA_HALF) * (HFIELD_SIZE - 1)), 0, HFIELD_SIZE - 1)
        row = np.clip(np.rint((local[:, 1] + ARENA_HALF) / (2 * ARENA_HALF) * (HFIELD_SIZE - 1)), 0, HFIELD_SIZE - 1)
        index = self.hfield_adr[agents] + row.astype(np.int64) * HFIELD_SIZE + col.astype(np.int64)
        return self.model.hfield_data[index] * MAX_TERRAIN_HEIGHT

    def _new_terrain(self, agent: int, roughness: float, obstacles: int) -> None:
        adr = self.hfield_adr[agent]
        if roughness > 0:  # flat ground skips the noise (15 % of a random policy's step time)
            noise = perlin((HFIELD_SIZE, HFIELD_SIZE), NOISE_CELL * (HFIELD_SIZE - 1) / (2 * ARENA_HALF), self.rng)
            self.model.hfield_data[adr: adr + HFIELD_SIZE * HFIELD_SIZE] = (roughness * noise).ravel()
        else:
            self.model.hfield_data[adr: adr + HFIELD_SIZE * HFIELD_SIZE] = 0.0
        geoms = self.obstacle_geom[agent]
        self.model.geom_pos[geoms] = PARK
        for k in range(obstacles):
            while True:
                xy = self.rng.uniform(-TARGET_RANGE, TARGET_RANGE, 2)
                if np.linalg.norm(xy) > 2.5:
                    break
            half = np.array([*self.rng.uniform(0.3, 1.0, 2), self.rng.uniform(0.2, 0.4)])
            self.model.geom_size[geoms[k]] = half
            base = self.heights(agent)[int(round((xy[1] + ARENA_HALF) / (2 * ARENA_HALF) * (HFIELD_SIZE - 1))),
                                       int(round((xy[0] + ARENA_HALF) / (2 * ARENA_HALF) * (HFIELD_SIZE - 1)))]
            self.model.geom_pos[geoms[k]] = [self.centre[agent, 0] + xy[0], xy[1], base]

    def place_targets(self, agents: np.ndarray, away_from: np.ndarray) -> None:
        """A new target for each agent: uniform in the inner square, >= 4 m from ``away_from`` [k, 2]."""
        for i, origin in zip(agents, away_from):
            while True:
                xy = self.centre[i, :2] + self.rng.uniform(-TARGET_RANGE, TARGET_RANGE, 2)
                if np.linalg.norm(xy - origin) >= TARGET_MIN_DISTANCE:
                    break
            self.target[i, :2] = xy
        self.target[agents, 2] = self.terrain_height(agents, self.target[agents, :2]) + 0.5
        self.model.geom_pos[self.target_geom[agents]] = self.target[agents]

    # --- the task interface --------------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        agents = np.flatnonzero(self.all_agents(mask))
        if len(agents) == 0:
            return
        roughness = np.clip(self.env_params.get_many("terrain_roughness", DEFAULTS["terrain_roughness"], len(agents)), 0, 1)
        obstacles = np.clip(np.rint(self.env_params.get_many("obstacles", DEFAULTS["obstacles"], len(agents))),
                            0, MAX_OBSTACLES).astype(int)
        speed = self.env_params.get_many("target_speed", DEFAULTS["target_speed"], len(agents))
        if not (speed > 0).all():
            raise ValueError(f"environment parameter target_speed must be > 0, got {speed.min():g}")
        self.target_speed[agents] = speed
        penalty = self.env_params.get_many("fall_penalty", DEFAULTS["fall_penalty"], len(agents))
        if not (penalty >= 0).all():
            raise ValueError(f"environment parameter fall_penalty must be >= 0 (the penalty is subtracted), "
                             f"got {penalty.min():g}")
        self.fall_penalty[agents] = penalty
        self.roughness[agents] = roughness
        data = self.data
        for i, r, k in zip(agents, roughness, obstacles):
            self._new_terrain(i, float(r), int(k))
            h = self.heights(i)
            near = (self.grid[None, :] ** 2 + self.grid[:, None] ** 2) <= SPAWN_RADIUS**2
            yaw = self.rng.uniform(0.0, 2 * np.pi)
            qpos = self.rest_qpos.copy()
            qpos[:3] += self.centre[i] + [0.0, 0.0, h[near].max() + SPAWN_CLEARANCE]
            qpos[3:] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
            # the yaw turns the whole creature about its root bone's proximal point (the free joint)
            data.qpos[self.root_qpos[i]] = qpos
        data.qpos[self.hinge_qpos[agents]] = 0.0
        data.qvel[self.root_dof[agents]] = 0.0
        data.qvel[self.hinge_dof[agents]] = 0.0
        data.ctrl[self.actuator[agents]] = 0.0
        mujoco.mj_forward(self.model, data)
        com = data.subtree_com[self.root[agents]]
        self.place_targets(agents, com[:, :2])
        self.episode_step[agents] = 0
        self.targets_reached[agents] = 0
        self.distance[agents] = 0.0
        self.contact[agents] = False
        self.velocity[agents] = 0.0

    def cube_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The creature's CoM [n, 3], the cube's forward and left axes [n, 3] (horizontal, unit)."""
        com = self.data.subtree_com[self.root]
        direction = self.target[:, :2] - com[:, :2]
        yaw = np.arctan2(direction[:, 1], direction[:, 0])
        zero = np.zeros_like(yaw)
        forward = np.column_stack([np.cos(yaw), np.sin(yaw), zero])
        left = np.column_stack([-np.sin(yaw), np.cos(yaw), zero])
        return com, forward, left

    @staticmethod
    def _to_cube(v: np.ndarray, forward: np.ndarray, left: np.ndarray) -> np.ndarray:
        """World vectors [n, ..., 3] -> cube frame (forward, left, up)."""
        shape = (len(v),) + (1,) * (v.ndim - 2) + (3,)
        f, l_ = forward.reshape(shape), left.reshape(shape)
        return np.stack([(v * f).sum(-1), (v * l_).sum(-1), v[..., 2]], axis=-1)

    def observe(self) -> list[np.ndarray]:
        n, bones = self.num_agents, len(self.skeleton.bones)
        data = self.data
        com, forward, left = self.cube_frame()
        cube = lambda v: self._to_cube(v, forward, left)  # noqa: E731
        obs = np.empty((n, self.observation_specs[0].shape[0]), dtype=np.float32)
        obs[:, 0:3] = cube(self.velocity.mean(axis=1))
        obs[:, 3] = self.target_speed
        obs[:, 4:6] = 0.0
        rotation = np.stack([forward, left, np.tile([0.0, 0.0, 1.0], (n, 1))], axis=1)  # rows: cube axes
        root = data.xmat[self.root].reshape(n, 3, 3)
        obs[:, 6:10] = matrix_quat(rotation @ root)
        obs[:, 10:13] = cube(self.target - com)
        obs[:, 13] = com[:, 2] - self.terrain_height(np.arange(n), com[:, :2])
        per_bone = np.concatenate([self.contact[..., None].astype(np.float64), cube(self.velocity),
                                   cube(data.cvel[self.body, :3]), cube(data.xipos[self.body] - com[:, None, :])],
                                  axis=2)
        obs[:, 14:14 + 10 * bones] = per_bone.reshape(n, -1)
        angles = data.qpos[self.hinge_qpos]
        hinges_end = 14 + 10 * bones + len(self.hinge_low)
        obs[:, 14 + 10 * bones:hinges_end] = 2.0 * (angles - self.hinge_low) / (self.hinge_high - self.hinge_low) - 1.0
        if self.gait_clock_hz > 0:
            phase = 2.0 * np.pi * self.gait_clock_hz * self.episode_step * self.control_dt
            obs[:, hinges_end] = np.sin(phase)
            obs[:, hinges_end + 1] = np.cos(phase)
        return [obs]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        n = self.num_agents
        model, data = self.model, self.data
        action = np.asarray(continuous, dtype=np.float64).reshape(n, -1).clip(-1.0, 1.0)
        data.ctrl[self.actuator] = np.where(action >= 0, action * self.hinge_high, -action * self.hinge_low)
        before = data.xipos[self.body].copy()
        com_before = data.subtree_com[self.root, :2].copy()
        contact = np.zeros((n, len(self.skeleton.bones)), dtype=bool)
        for _ in range(SUBSTEPS):
            mujoco.mj_step(model, data)
            if data.ncon:
                geoms = data.contact.geom[: data.ncon].ravel()
                mine = geoms[self.geom_agent[geoms] >= 0]
                contact[self.geom_agent[mine], self.geom_bone[mine]] = True
        # mj_step leaves positions and velocities of the state it started from: recompute them
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        self.contact = contact
        self.velocity = (data.xipos[self.body] - before) / self.control_dt
        com, forward, _ = self.cube_frame()
        self.distance += np.linalg.norm(com[:, :2] - com_before, axis=1)
        average = self.velocity.mean(axis=1)
        facing = data.xmat[self.root].reshape(n, 3, 3)[:, :, 0]
        speed_term = match_speed_reward(forward * self.target_speed[:, None], average, self.target_speed)
        look_term = look_reward(forward, facing)
        self.last_reward_terms = (speed_term, look_term)
        rewards = (speed_term * look_term).astype(np.float32)
        reached = np.linalg.norm(self.target[:, :2] - com[:, :2], axis=1) < REACH_DISTANCE
        if reached.any():
            agents = np.flatnonzero(reached)
            self.targets_reached[agents] += 1
            self.place_targets(agents, com[agents, :2])
        broken = ~np.isfinite(data.qpos[self.root_qpos]).all(axis=1) | ~np.isfinite(self.velocity).all(axis=(1, 2))
        fallen = (contact & self.vital).any(axis=1) | broken
        penalized = fallen & (self.fall_penalty > 0)
        rewards[penalized] = -self.fall_penalty[penalized]
        self.episode_step += 1
        interrupted = ~fallen & (self.episode_step >= self.max_step)
        done = fallen | interrupted
        stats = []
        if done.any():
            for name, values in (("Creature/Targets Reached", self.targets_reached), ("Creature/Distance", self.distance)):
                stats += [(name, float(v), StatsAggregationMethod.AVERAGE) for v in values[done].tolist()]
        return TaskStep(rewards, done, interrupted, stats)
