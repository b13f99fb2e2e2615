"""``dodge``: a kinematic humanoid learns to dodge thrown spheres with little effort (the task;
its scripted evaluation is ``evaluation.py`` beside this module, the seed project it follows is
cited in docs/stub-tasks.md).

The character (``dodge.xml`` beside this file; z up, y = forward, x = the character's right) stands
with fixed feet and static arms; the start pose has every joint angle at zero. Its joint positions
are written from the actions (no dynamics for the body: every character body has gravcomp=1 and its
contacts are MuJoCo's inactive ones, so nothing but the task moves it). Each episode one sphere is
thrown at it, a MuJoCo free body under gravity. One MjModel holds all ``num_areas * 14`` characters
and spheres, so one ``mj_step`` advances every agent.

Layout: in an area the 14 characters stand in a row 3 m apart (x), areas are rows 25 m apart (y),
everyone faces +y. Agent k of an area only collides with its own sphere (collision bit k + 1 on its
geoms' conaffinity and on its sphere's contype; bit 0 is the floor), so a sphere never touches
another agent; across areas, no sphere gets farther than 12 m from its own character (the episode
ends there at the latest; normally 0.8 m past it, see the pass) and rows are 25 m apart.

Actions, 9 continuous in [-1, 1] (|a| <= 0.05 counts as 0 for the crouch and the two angles, so a
policy can hold still, see the effort terms), in this order:
  0     crouch: the hip angle changes by a * 3 deg (150 deg/s); hips +alpha, knees -2 alpha, ankles
        +alpha, so the feet stay flat and, thigh and shank being equally long, the pelvis slides
        straight down by 0.86 (1 - cos alpha) m. alpha in [0, 45 deg] (45 deg is the ankle's
        weight-bearing dorsiflexion, the first human limit the coupling reaches).
  1..3  torso rotation axis in the pelvis frame (normalised; no rotation when its norm < 1e-6)
  4     torso rotation angle a * 4 deg (200 deg/s) about that axis, relative to the waist
  5..7  neck rotation axis in the torso frame
  8     neck rotation angle a * 6 deg (300 deg/s)
  The rotated orientation is decomposed into the x-y-z joint angles of the waist (or neck) and each
  is clamped to its human range (dodge.xml: waist flexion 80, extension 30, bending 35, rotation
  45 deg; neck flexion 50, extension 60, bending 45, rotation 80 deg).

Observations, float32 [17] per agent, in this order:
  0       crouch amount: the hip (upper-leg x) angle alpha, rad
  1..4    torso orientation relative to the pelvis, quaternion (w, x, y, z), w >= 0
  5..8    neck (head) orientation relative to the torso, quaternion (w, x, y, z), w >= 0
  9..10   CoM projection minus the support polygon's centroid, x and y (the horizontal plane), m
  11..13  sphere position minus pelvis position, m
  14..16  sphere velocity, m/s
  (The pelvis never rotates and every agent faces +y, so world axes are the character's axes.)

Rewards. Each control step (0.02 s, 4 MuJoCo steps of 0.005 s; a decision every step) adds the
effort terms -e^(a/100)/100 with a in degrees or centimetres:
  crouch  a = 3 * alpha, only while crouched (alpha > 0)
  torso   a = the torso-pelvis rotation angle, only on steps where the torso moved
  neck    a = half the neck-torso rotation angle, only on steps where the neck moved
  balance a = distance of the CoM projection from the support polygon's centroid in CENTIMETRES,
          every step (in metres, e^(a/100) would be flat: 1.0000..1.0015 over the whole polygon)
At the episode's end: +5 when the sphere passes without contact (its position is more than 0.8 m
past the character's vertical axis along its horizontal direction of travel, or 12 m away);
-5 when the CoM projection leaves the support polygon (the convex hull of the two feet's soles);
on a hit (any MuJoCo contact between the sphere and a character geom, checked after every MuJoCo
step) the penalty of the region first touched (the deepest contact of the first MuJoCo step with
one; the capsules overlap, so a sphere can touch two at once): head and neck -5, torso (abdomen, chest,
shoulders) -4, pelvis -3, arms -2, legs (thighs, shanks, feet) -2 (Zordan et al.'s ordering:
head > torso > pelvis > limbs). A hit and a balance loss in the same step both count; the pass
needs neither. Episodes are interrupted after max_step = 300 control steps (6 s; a throw lasts
0.4-1.4 s). The pose is back at zero for the next episode.

Throws (training): start at a horizontal distance of 4-6 m from the character's axis, from an
azimuth within +-120 deg of straight ahead (front and both sides, as the seed's test throws), at
a height of 0.5-2 m; aimed at a random point of the character in its start pose (a geom chosen with
probability proportional to its surface area, then a uniform point inside it); horizontal speed
5-9 m/s. The launch velocity puts the sphere exactly on the target under MuJoCo's semi-implicit
Euler (``launch``), so an unmoving character is hit unless the floor deflects the sphere first.

Masses: every geom has the density of water; MuJoCo integrates body masses from the geom volumes
once at compile time (79.0 kg in all; head 6.7 %, torso and pelvis 51.4 %, arms 9.6 %, thighs
18.8 %, shanks 8.9 %, feet 4.6 %, close to Winter's tables); the CoM is MuJoCo's ``subtree_com``
of the pelvis. Support polygon: the convex hull of the soles' corners, x in [-0.15, 0.15] m,
y in [-0.07, 0.19] m (centroid (0, 0.06)); the standing CoM is at y = 0.003 m.

Consequences worth knowing (measured on this model):
  * Within the human limits above the CoM projection never leaves the support polygon (over 4,200
    random poses it reached y = 0.172 m at most, the toes are at 0.19 m: only the upper body moves
    and the pelvis never shifts), so the -5 balance rule is a guard that the limits already
    satisfy; the tests exercise it on a shrunken polygon. The balance effort term still pays for
    leaning.
  * Area-weighted targets put 61 % of the random throws at or below the pelvis (targets under
    1.11 m: legs 39 % of the surface, pelvis 10 %, the lower arms), where fixed feet cannot get out
    of the way; the evaluation therefore also reports the hit rate of the throws aimed higher.
  * A limit stops a rotation: pushing further into it leaves the pose unchanged, which is not a
    move and costs nothing (the seed charges the torso and neck only on steps they moved).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from protos.types import (
    ActionSpec,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    StatsAggregationMethod,
)
from unity_stub_env.geometry import (
    axis_angle_matrix,
    convex_hull,
    euler_to_matrix,
    euler_to_quat,
    matrix_to_euler,
    polygon_centroid,
)
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep

XML_PATH = Path(__file__).with_name("dodge.xml")
AGENTS_PER_AREA = 14
AGENT_SPACING = 3.0  # m between the characters of an area (x)
AREA_SPACING = 25.0  # m between areas (y)
SUBSTEPS = 4  # MuJoCo steps (0.005 s, dodge.xml) per control step
HIP_HEIGHT = 0.94
LEG_LENGTH = 0.86  # thigh + shank
DEAD_ZONE = 0.05
CROUCH_RATE = math.radians(3.0)  # per control step at |a| = 1
TORSO_RATE = math.radians(4.0)
NECK_RATE = math.radians(6.0)
PASS_DISTANCE = 0.8
FAR_DISTANCE = 12.0
PASS_REWARD = 5.0
BALANCE_REWARD = -5.0
# hit penalty per region, most vital first
REGIONS = ("head", "torso", "pelvis", "arms", "legs")
HIT_PENALTY = np.array([-5.0, -4.0, -3.0, -2.0, -2.0])
_REGION_OF_GEOM = {
    "head": "head", "neck": "head",
    "abdomen": "torso", "chest": "torso", "shoulders": "torso",
    "pelvis": "pelvis",
    "upper_arm_r": "arms", "upper_arm_l": "arms", "forearm_r": "arms", "forearm_l": "arms",
    "hand_r": "arms", "hand_l": "arms",
    "thigh_r": "legs", "thigh_l": "legs", "shank_r": "legs", "shank_l": "legs",
    "foot_r": "legs", "foot_l": "legs",
}
# the joints the task writes, in this order: one row of ``pose`` per agent
POSE_JOINTS = ("root_z", "hip_r", "knee_r", "ankle_r", "hip_l", "knee_l", "ankle_l",
               "waist_x", "waist_y", "waist_z", "neck_x", "neck_y", "neck_z")
# random throws
THROW_DISTANCE = (4.0, 6.0)
THROW_AZIMUTH = math.radians(120.0)
THROW_HEIGHT = (0.5, 2.0)
THROW_SPEED = (5.0, 9.0)  # horizontal, m/s


@dataclass
class Throws:
    """Throws for ``count`` agents, relative to each character's base (the floor under its pelvis):
    start and target float [count, 3] (m), horizontal speed float [count] (m/s)."""

    start: np.ndarray
    target: np.ndarray
    speed: np.ndarray

    def __len__(self) -> int:
        return len(self.speed)


def build_model(num_agents: int) -> tuple[mujoco.MjModel, np.ndarray]:
    """The MjModel of ``num_agents`` characters with their spheres (names prefixed ``a<i>/``),
    and their base positions float [n, 3]."""
    spec = mujoco.MjSpec.from_file(str(XML_PATH))
    spec.delete(spec.body("pelvis"))
    spec.delete(spec.body("ball"))
    index = np.arange(num_agents)
    base = np.column_stack([(index % AGENTS_PER_AREA) * AGENT_SPACING,
                            (index // AGENTS_PER_AREA) * AREA_SPACING, np.zeros(num_agents)])
    text = XML_PATH.read_text()
    for i in range(num_agents):
        agent = mujoco.MjSpec.from_string(text)
        frame = spec.worldbody.add_frame(pos=base[i])
        frame.attach_body(agent.body("pelvis"), f"a{i}/", "")
        frame.attach_body(agent.body("ball"), f"a{i}/", "")
    return spec.compile(), base


def _geom_table(model: mujoco.MjModel, num_agents: int):
    """Per geom: owning agent (-1: none), region index (-1: not a character geom); ball geom ids."""
    agent = np.full(model.ngeom, -1)
    region = np.full(model.ngeom, -1)
    ball = np.zeros(num_agents, dtype=np.int64)
    for g in range(model.ngeom):
        name = model.geom(g).name
        if "/" not in name:
            continue
        prefix, local = name.split("/", 1)
        i = int(prefix[1:])
        if local == "ball":
            ball[i] = g
        else:
            agent[g], region[g] = i, REGIONS.index(_REGION_OF_GEOM[local])
    return agent, region, ball


def effort(alpha_degrees: np.ndarray) -> np.ndarray:
    """The magnitude of one effort term: e^(a/100)/100 (the reward is its negative)."""
    return np.exp(np.asarray(alpha_degrees, dtype=np.float64) / 100.0) / 100.0


def _dead_zone(a: np.ndarray) -> np.ndarray:
    return np.where(np.abs(a) <= DEAD_ZONE, 0.0, a)


class DodgeTask(Task):
    name = "dodge"
    behavior_name = "Dodge"
    observation_specs = (
        ObservationSpec((17,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor_size17"),
    )
    action_spec = ActionSpec(continuous_size=9, discrete_branches=())
    agents_per_area = AGENTS_PER_AREA
    max_step = 300
    decision_period = 1
    sets_reward = False
    description = ("Kinematic humanoid dodging thrown spheres (docs/stub-tasks.md). Observations: crouch (1), "
                   "torso quaternion (4), neck quaternion (4), CoM - support centroid x,y (2), "
                   "sphere - pelvis (3), sphere velocity (3). Actions: crouch (1), torso axis (3) + "
                   "angle (1), neck axis (3) + angle (1). +5 pass, -5 balance lost, hit -5 head .. -2 legs.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        n = self.num_agents
        self.model, self.base = build_model(n)
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        model = self.model
        joint = lambda i, name: model.joint(f"a{i}/{name}")  # noqa: E731
        self.pose_qpos = np.array([[joint(i, j).qposadr[0] for j in POSE_JOINTS] for i in range(n)])
        self.pose_dof = np.array([[joint(i, j).dofadr[0] for j in POSE_JOINTS] for i in range(n)])
        ball_qpos = np.array([joint(i, "ball").qposadr[0] for i in range(n)])
        ball_dof = np.array([joint(i, "ball").dofadr[0] for i in range(n)])
        self.ball_pos_qpos = ball_qpos[:, None] + np.arange(3)
        self.ball_quat_qpos = ball_qpos[:, None] + 3 + np.arange(4)
        self.ball_dof = ball_dof[:, None] + np.arange(6)
        self.ball_lin_dof = self.ball_dof[:, :3]
        self.pelvis_body = np.array([model.body(f"a{i}/pelvis").id for i in range(n)])
        self.geom_agent, self.geom_region, self.ball_geom = _geom_table(model, n)
        self.is_character_geom = self.geom_agent >= 0
        # collision bits: floor bit 0; agent k of an area bit k + 1 on its geoms and its sphere
        bits = 1 << (1 + np.arange(n) % AGENTS_PER_AREA)
        character = self.is_character_geom
        model.geom_contype[character] = 0
        model.geom_conaffinity[character] = bits[self.geom_agent[character]]
        model.geom_contype[self.ball_geom] = 1 | bits
        model.geom_conaffinity[self.ball_geom] = 0
        self.timestep = float(model.opt.timestep)
        self.gravity = float(-model.opt.gravity[2])
        self.joint_low = model.jnt_range[[model.joint(f"a0/{j}").id for j in POSE_JOINTS], 0]
        self.joint_high = model.jnt_range[[model.joint(f"a0/{j}").id for j in POSE_JOINTS], 1]
        # the two 3-DoF joints' limits as [2, 3] (torso, neck)
        self.rot_low = self.joint_low[7:].reshape(2, 3)
        self.rot_high = self.joint_high[7:].reshape(2, 3)
        # the crouch stops where the first coupled joint meets its limit (hip a, knee -2a, ankle a):
        # with dodge.xml's ranges the ankle, at 45 degrees
        self.crouch_max = float(min(self.joint_high[1], -self.joint_low[2] / 2, self.joint_high[3]))
        self._start_pose_geometry()
        # per-agent state
        self.crouch = np.zeros(n)
        self.aim = np.zeros((n, 3))  # the world point each sphere was thrown at (drawn by unity_stub_env.render)
        self.euler = np.zeros((n, 2, 3))  # torso, neck joint angles
        self.com = np.zeros((n, 2))  # CoM projection relative to the base
        self.episode_step = np.zeros(n, dtype=np.int64)
        self.episode_effort = np.zeros(n)
        # the last step's pieces (read by tests and the evaluation)
        self.last_effort = np.zeros(n)  # sum of the four effort magnitudes
        self.last_hit_region = np.full(n, -1)  # index into REGIONS, -1 = no hit
        self.last_balance_lost = np.zeros(n, dtype=bool)
        self.last_passed = np.zeros(n, dtype=bool)
        self.reset()

    def _start_pose_geometry(self) -> None:
        """From agent 0 in the start pose: the CoM, the support polygon (hull of the soles) and its
        centroid, and the target geoms (centre, half axis, radius, box half-extents, area weight),
        all relative to the agent's base."""
        model, data = self.model, self.data
        mujoco.mj_forward(model, data)
        base = self.base[0]
        self.start_com = data.subtree_com[self.pelvis_body[0], :2] - base[:2]
        corners = []
        for side in ("r", "l"):
            g = model.geom(f"a0/foot_{side}").id
            size, centre, rot = model.geom_size[g], data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
            for sx in (-1, 1):
                for sy in (-1, 1):
                    corners.append((centre + rot @ (size * np.array([sx, sy, -1])))[:2] - base[:2])
        self.support = convex_hull(np.array(corners))
        self.support_centroid = polygon_centroid(self.support)
        edges = np.roll(self.support, -1, axis=0) - self.support
        self.support_normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward for CCW
        self.support_offsets = (self.support_normals * self.support).sum(axis=1)
        geoms = np.flatnonzero(self.geom_agent == 0)
        kinds, sizes = model.geom_type[geoms], model.geom_size[geoms]
        rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
        capsule, sphere, box = (kinds == mujoco.mjtGeom.mjGEOM_CAPSULE), (kinds == mujoco.mjtGeom.mjGEOM_SPHERE), \
            (kinds == mujoco.mjtGeom.mjGEOM_BOX)
        assert (capsule | sphere | box).all()
        r = np.where(box, 0.0, sizes[:, 0])
        half = np.where(capsule, sizes[:, 1], 0.0)
        area = np.where(box, 8 * (sizes[:, 0] * sizes[:, 1] + sizes[:, 1] * sizes[:, 2] + sizes[:, 2] * sizes[:, 0]),
                        4 * np.pi * r**2 + 4 * np.pi * r * half)
        self.target_centre = data.geom_xpos[geoms] - base
        self.target_half_axis = rot[:, :, 2] * half[:, None]
        self.target_radius = r
        self.target_box = np.where(box[:, None, None], rot * sizes[:, None, :], 0.0)  # columns = half extents
        self.target_weight = area / area.sum()
        self.target_region = self.geom_region[geoms]

    # --- throws ---------------------------------------------------------------------------------
    def draw_throws(self, count: int, rng: np.random.Generator | None = None) -> Throws:
        """``count`` random throws (the training distribution, see the module docstring)."""
        rng = self.rng if rng is None else rng
        distance = rng.uniform(*THROW_DISTANCE, count)
        azimuth = rng.uniform(-THROW_AZIMUTH, THROW_AZIMUTH, count)
        start = np.column_stack([distance * np.sin(azimuth), distance * np.cos(azimuth),
                                 rng.uniform(*THROW_HEIGHT, count)])
        geom = rng.choice(len(self.target_weight), size=count, p=self.target_weight)
        direction = rng.normal(size=(count, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        target = (self.target_centre[geom] + self.target_half_axis[geom] * rng.uniform(-1, 1, (count, 1))
                  + np.einsum("kij,kj->ki", self.target_box[geom], rng.uniform(-1, 1, (count, 3)))
                  + direction * (self.target_radius[geom] * rng.uniform(0, 1, count) ** (1 / 3))[:, None])
        return Throws(start, target, rng.uniform(*THROW_SPEED, count))

    def launch(self, agents: np.ndarray, throws: Throws) -> None:
        """Put each agent's sphere at its throw's start with the velocity that brings it exactly to
        the target under semi-implicit Euler: x(t) = x0 + v0 t - g t (t + dt) / 2, at
        t = horizontal distance / horizontal speed."""
        delta = throws.target - throws.start
        flight = np.linalg.norm(delta[:, :2], axis=1) / throws.speed
        if not (flight > 0).all():
            raise ValueError("every throw needs a horizontal distance to its target and a positive speed")
        velocity = delta / flight[:, None]
        velocity[:, 2] += 0.5 * self.gravity * (flight + self.timestep)
        qpos, qvel = self.data.qpos, self.data.qvel
        qpos[self.ball_pos_qpos[agents]] = self.base[agents] + throws.start
        self.aim[agents] = self.base[agents] + throws.target
        qpos[self.ball_quat_qpos[agents]] = (1.0, 0.0, 0.0, 0.0)
        qvel[self.ball_dof[agents]] = 0.0
        qvel[self.ball_lin_dof[agents]] = velocity

    # --- the task interface -----------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        """Start pose and a new random throw for the agents in mask."""
        agents = np.flatnonzero(self.all_agents(mask))
        if len(agents) == 0:
            return
        self.crouch[agents] = 0.0
        self.euler[agents] = 0.0
        self.com[agents] = self.start_com
        self.episode_step[agents] = 0
        self.episode_effort[agents] = 0.0
        self.data.qpos[self.pose_qpos[agents]] = 0.0
        self.data.qvel[self.pose_dof[agents]] = 0.0
        self.launch(agents, self.draw_throws(len(agents)))

    def _pose_rows(self) -> np.ndarray:
        """float [n, 13]: the POSE_JOINTS positions of every agent."""
        a = self.crouch
        drop = -LEG_LENGTH * (1.0 - np.cos(a))
        legs = np.column_stack([drop, a, -2 * a, a, a, -2 * a, a])
        return np.concatenate([legs, self.euler.reshape(-1, 6)], axis=1)

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 17]]: see the module docstring for the order."""
        n = self.num_agents
        obs = np.empty((n, 17), dtype=np.float32)
        obs[:, 0] = self.crouch
        obs[:, 1:9] = euler_to_quat(self.euler).reshape(n, 8)
        obs[:, 9:11] = self.com - self.support_centroid
        pelvis = self.base.copy()
        pelvis[:, 2] = HIP_HEIGHT - LEG_LENGTH * (1.0 - np.cos(self.crouch))
        obs[:, 11:14] = self.data.qpos[self.ball_pos_qpos] - pelvis
        obs[:, 14:17] = self.data.qvel[self.ball_lin_dof]
        return [obs]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """continuous float [n, 9] in [-1, 1] -> one 0.02 s control step of every agent."""
        n = self.num_agents
        action = _dead_zone(np.asarray(continuous, dtype=np.float64).reshape(n, 9).clip(-1.0, 1.0))
        self.crouch = np.clip(self.crouch + action[:, 0] * CROUCH_RATE, 0.0, self.crouch_max)
        axes = action[:, [[1, 2, 3], [5, 6, 7]]]  # [n, 2, 3]: torso, neck
        norm = np.linalg.norm(axes, axis=2)
        angle = np.where(norm > 1e-6, action[:, [4, 8]] * (TORSO_RATE, NECK_RATE), 0.0)
        unit = axes / np.maximum(norm, 1e-6)[..., None]
        rotated = axis_angle_matrix(unit, angle) @ euler_to_matrix(self.euler)
        euler = np.clip(matrix_to_euler(rotated), self.rot_low, self.rot_high)
        moved = (np.abs(euler - self.euler) > 1e-9).any(axis=2)  # [n, 2]
        self.euler = euler
        data = self.data
        data.qpos[self.pose_qpos] = self._pose_rows()
        data.qvel[self.pose_dof] = 0.0
        hit_penalty = np.zeros(n)
        hit_region = np.full(n, len(REGIONS))  # not hit
        for _ in range(SUBSTEPS):
            mujoco.mj_step(self.model, data)
            if data.ncon:
                self._record_hits(hit_region)
        hit = hit_region < len(REGIONS)
        hit_penalty[hit] = HIT_PENALTY[hit_region[hit]]
        self.com = data.subtree_com[self.pelvis_body, :2] - self.base[:, :2]
        balance_lost = (self.com @ self.support_normals.T > self.support_offsets + 1e-12).any(axis=1)
        # effort terms (magnitudes), angles in degrees, the CoM distance in centimetres
        angles = np.degrees(2.0 * np.arccos(np.clip(euler_to_quat(euler)[..., 0], -1.0, 1.0)))  # [n, 2]
        com_cm = 100.0 * np.linalg.norm(self.com - self.support_centroid, axis=1)
        spent = (np.where(self.crouch > 0, effort(3.0 * np.degrees(self.crouch)), 0.0)
                 + np.where(moved[:, 0], effort(angles[:, 0]), 0.0)
                 + np.where(moved[:, 1], effort(0.5 * angles[:, 1]), 0.0)
                 + effort(com_cm))
        # did the sphere pass?
        relative = data.qpos[self.ball_pos_qpos[:, :2]] - self.base[:, :2]
        velocity = data.qvel[self.ball_lin_dof[:, :2]]
        speed = np.linalg.norm(velocity, axis=1)
        along = (relative * velocity).sum(axis=1) / np.maximum(speed, 1e-9)
        far = np.linalg.norm(relative, axis=1) > FAR_DISTANCE
        passed = ~hit & ~balance_lost & (((speed > 1e-9) & (along > PASS_DISTANCE)) | far)
        rewards = (-spent + hit_penalty + np.where(balance_lost, BALANCE_REWARD, 0.0)
                   + np.where(passed, PASS_REWARD, 0.0)).astype(np.float32)
        self.episode_step += 1
        self.episode_effort += spent
        ended = hit | balance_lost | passed
        interrupted = ~ended & (self.episode_step >= self.max_step)
        done = ended | interrupted
        self.last_effort, self.last_balance_lost, self.last_passed = spent, balance_lost, passed
        self.last_hit_region = np.where(hit, hit_region, -1)
        stats = []
        if done.any():
            for name, values in (("Dodge/Hit", hit), ("Dodge/Balance Lost", balance_lost),
                                 ("Dodge/Passed", passed), ("Dodge/Episode Effort", self.episode_effort)):
                stats += [(name, float(v), StatsAggregationMethod.AVERAGE) for v in values[done].tolist()]
        return TaskStep(rewards, done, interrupted, stats)

    def _record_hits(self, hit_region: np.ndarray) -> None:
        """Set ``hit_region`` [n] (an index into REGIONS; len(REGIONS) = not hit yet) of every agent
        not hit yet whose sphere touches one of its geoms now: the region of the deepest contact."""
        contacts = self.data.contact
        pairs, depth = contacts.geom[: self.data.ncon], contacts.dist[: self.data.ncon]
        part = np.where(self.is_character_geom[pairs[:, 0]], pairs[:, 0], pairs[:, 1])
        touching = np.flatnonzero(self.is_character_geom[part])
        if len(touching) == 0:
            return
        touching = touching[np.argsort(depth[touching], kind="stable")]  # deepest first
        agents, first = np.unique(self.geom_agent[part[touching]], return_index=True)
        new = hit_region[agents] == len(REGIONS)
        hit_region[agents[new]] = self.geom_region[part[touching[first[new]]]]
