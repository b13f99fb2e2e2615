"""``mimic``: a physically simulated ragdoll keeps its balance and imitates reference motions (the
task; ``motions.py`` makes and loads the reference clips, ``expert.py`` is a scripted balance
expert, ``evaluation.py`` the scripted evaluation; the seed project it follows is cited in
docs/stub-tasks.md).

The character (``mimic.xml`` beside this file; z up, y forward, x the character's right) is a
70 kg ragdoll of 16 capsule/box segments with a free root (the pelvis). Masses follow the human
fractions (head+neck 6.81 %, trunk 43.02 % split into pelvis 14.2 and torso 28.82, upper arm 2.63,
forearm 1.5, hand 0.585, thigh 14.47, shank 4.57, foot 1.33 %); the soles have friction 2 (the other
geoms 1). Joints, 26 unlocked hinge axes (degrees; positive = flexion, abduction, lateral rotation,
bending right):
  waist x -30..80, y -35..35, z -45..45     neck x -60..50, y -45..45, z -80..80
  shoulder x -60..170, y -30..160, z -90..90   elbow 0..150 (the wrists are locked: the hand is
  welded to the forearm)
  hip x -30..120, y -30..45, z -45..45      knee 0..150      ankle x -50..40, y -25..25
Every axis is driven by a PD controller, a MuJoCo position actuator (torque = kp (target - q) -
kv q', limited; kv is integrated implicitly): waist, hips and knees kp 1500 N m/rad, kv 150 N m s/rad,
|torque| <= 400 N m; ankles 1500/150/250; shoulders 150/15/100; elbows 80/8/60; neck 100/10/60.
Why so stiff at the ankles: standing is an inverted pendulum needing m g h ~ 70 * 9.81 * 1 ~ 700
N m/rad from the two ankles together; softer ankles sag and fall. How well these gains track the
reference on their own is the row "reference PD" of ``unity-stub-env --task mimic --evaluate zero``
(bench/RESULTS.md).
Ragdolls never touch each other (collision bits: ragdoll geoms only meet the floor) and have no
self-collision, so one MjModel holds all ``num_areas * 8`` of them.

Control: MuJoCo steps of 0.004 s (250 Hz, the seed's physics and PD rate); the environment
parameter ``decision_hz`` (read when every agent resets together, i.e. at a RESET; 250 Hz must be
a multiple of it and every clip a whole number of decisions long: 50 or 250) sets how many of them
one decision spans: 250 = the seed's rate, one action per MuJoCo step; 50 (default) = one action
every 5. Why 50 by default: the PD loop runs at 250 Hz inside MuJoCo either way; an untrained
policy's noise topples the ragdoll no later at 50 than at 250 decisions/s (bench/RESULTS.md,
"mimic: decision rate"), and at 250 a 10 s episode is 2,500 agent steps instead of 500, so the same
agent-step budget buys a fifth of the simulated time; DeepMimic itself decides at 30 Hz over a
1.2 kHz simulation. Episodes are interrupted after 10 s (``max_step`` = 10 s x decision_hz). The
reference clips (50 Hz) are resampled to the decision rate (``resample``). The trainer's horizon
and discount are per decision: configs/mimic.yaml says how to restate them for a rate.

Actions, 26 continuous in [-1, 1], one per axis in mimic.xml's actuator order (``JOINTS`` of
``motions``). Environment parameter ``residual`` (read at episode start):
  0 (default, the seed's absolute targets): target = a high for a >= 0, -a low for a < 0: the
    action mapped piecewise linearly onto the axis' limits with a = 0 at the anatomical neutral
    (0 rad, mimic.xml's standing pose; every range contains it). Why not the linear map
    low + (a + 1) / 2 (high - low): its a = 0 is the middle of each range (hips 45 deg, knees 75
    deg flexed: a deep crouch), so an untrained policy folds and falls at once and PPO learned
    nothing (bench/RESULTS.md); with the neutral at a = 0 the untrained policy stands in the PD's
    rest pose and the whole range stays reachable. Exploration is the hard part of this mode:
    PPO's Gaussian starts at std 1/3 in action units (std 1, sent as clamp(a, -3, 3) / 3), and
    white noise that small around the standing pose topples the ragdoll within seconds
    (bench/RESULTS.md), mostly through the knees; the seed's drive (kp 400, kv 40, torque caps
    20-140 N m) and its map (a = 0 at the middle of each range) do not prevent it: with them even
    zero actions fall within a second (bench/RESULTS.md, "mimic: does the seed's actuation keep an
    untrained ragdoll up?"). The bench
    recipes start from cloned demonstrations instead
    (bench/mimic/*_bc*.yaml, docs/stub-tasks.md);
  r > 0 (DeepMimic-like, our option): target = reference angle + a r (high - low) / 2, clipped to
    the limits: zero actions track the reference and the policy learns corrections.

Observations, float32 [170] per agent: for each of 13 body parts (pelvis, torso, head, upper arms,
forearms, thighs, shanks, feet: ``OBSERVED``; the hands are welded, so their state is the forearms')
13 values: the local rotation (quaternion w, x, y, z relative to the parent part, w >= 0; the
pelvis' is its world orientation), the linear velocity and the angular velocity, and the position
relative to the pelvis (for the pelvis: 0, 0, its height above the floor), all three vectors in the
pelvis frame; then the phase of the reference in [0, 1) (frame / frames; 0 for ``stand``). The
reference pose itself is not observed. Observations and rewards read MuJoCo's kinematics after the
decision's last ``mj_step``, i.e. of the state one 0.004 s step earlier (what ``mj_step`` leaves).

Reference motions (``motions``: stand, arms, squat, walk, CSV files at 50 Hz made by
``python -m unity_stub_env.tasks.mimic.motions``), chosen per episode by the environment parameter
``motion`` = 0 stand, 1 arms, 2 squat, 3 walk (a curriculum can move between them). The reference
is kinematic: only its numbers are used. For the walk the reference's forward position follows the
ragdoll's pelvis (as the seed does), for the other motions it stays at the agent's base.

Reward (DeepMimic-style, each decision, against the reference frame reached by that decision):
  R = w_r r_r + w_v r_v + w_m r_m + w_e r_e + w_t r_t with
  r_r = exp(-k_r sum_j angle(q_j, q^_j)^2)  the 13 parts' local rotations (the pelvis' world one)
  r_v = exp(-k_v sum_j (v_j - v^_j)^2)      the 26 joint velocities and the root angular velocity
  r_m = exp(-k_m |m - m^|^2)                 centre of mass (world)
  r_e = exp(-k_e sum_e |p_e - p^_e|^2)       hands and feet (world; geom centres)
  r_t = exp(-k_t (v_y - v^_y)^2)             forward pelvis velocity against the clip's mean speed
Effort (environment parameter ``effort_weight`` w_f in [0, 1], default 0 = off): R is multiplied by
1 - w_f f, f = the mean over the 26 actuators and the decision's MuJoCo steps of |torque| / its
force limit, so the less relative force the ragdoll spends the closer the factor is to 1 (the seed's
effort multiplier, whose coefficient it does not give).
Weights (environment parameter ``reward_weights``): 0 = the seed's (per motion, as its tables give
them: stand and arms w_r 0.7, w_v 0.15, w_m 0.15; squat 0.65, 0.1, 0.1, w_e 0.15; walk 0.56,
0.07, 0.07, 0.1, w_t 0.2), 1 = DeepMimic's (pose 0.65, velocity 0.1, end effectors 0.15, CoM 0.1).
Scales: DeepMimic's k_r 2, k_v 0.1, k_e 40, k_m 10 (the seed does not give its own), k_t 2 (our
choice: 0.5 m/s off costs 40 %). Any single value can be overridden by the environment parameters
``w_r w_v w_m w_e w_t k_r k_v k_m k_e k_t`` (negative = keep the preset).

Episodes: reference state initialisation (``rsi`` 1, default: a random frame of the clip, its pose
and velocities copied into the ragdoll; 0: frame 0). Early termination: a geom other than a foot
touches the floor, or the centre of mass is more than ``max_drift`` (default 0.5 m) from the
reference's. Optional pushes: every ``push_interval`` s (default 2) of an episode, when
``push_impulse`` (N s, default 0 = none) is positive, the torso gets that horizontal impulse in a
random direction, as a constant force over one decision (1 / decision_hz s).
Stats: Mimic/r_r, r_v, r_m, r_e (episode means) and Mimic/Fell, at each episode's end.
"""
from __future__ import annotations

import math
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
from unity_stub_env.geometry import cross, quat_angle, quat_conj, quat_mul
from unity_stub_env.tasks.base import EnvironmentParameters, Task, TaskStep
from unity_stub_env.tasks.mimic.motions import JOINTS, MOTIONS, RATE, load_motion

XML_PATH = Path(__file__).with_name("mimic.xml")
AGENTS_PER_AREA = 8
AGENT_SPACING = 2.0  # m between the ragdolls of an area (x); areas 4 m apart (y). They never collide.
AREA_SPACING = 4.0
PHYSICS_HZ = 250  # mimic.xml's timestep, 0.004 s
DECISION_HZ = 50  # the default of the environment parameter decision_hz (see the module docstring)
SUBSTEPS = PHYSICS_HZ // DECISION_HZ  # MuJoCo steps per decision at the default rate
CONTROL_DT = 1.0 / DECISION_HZ  # s per decision at the default rate
EPISODE_SECONDS = 10.0  # episodes are interrupted after this much simulated time
OBSERVED = ("pelvis", "torso", "head", "upper_arm_r", "forearm_r", "upper_arm_l", "forearm_l",
            "thigh_r", "shank_r", "foot_r", "thigh_l", "shank_l", "foot_l")
END_EFFECTORS = ("hand_r", "hand_l", "foot_r", "foot_l")  # geoms
FEET = ("foot_r", "foot_l")
OBSERVATION_SIZE = 13 * len(OBSERVED) + 1
TERMS = ("r_r", "r_v", "r_m", "r_e", "r_t")
SEED_WEIGHTS = {"stand": (0.7, 0.15, 0.15, 0.0, 0.0), "arms": (0.7, 0.15, 0.15, 0.0, 0.0),
                  "squat": (0.65, 0.1, 0.1, 0.15, 0.0), "walk": (0.56, 0.07, 0.07, 0.1, 0.2)}
DEEPMIMIC_WEIGHTS = (0.65, 0.1, 0.1, 0.15, 0.0)  # in TERMS order: pose, velocity, CoM, end effectors
SCALES = (2.0, 0.1, 10.0, 40.0, 2.0)  # k_r, k_v, k_m, k_e, k_t
MAX_DRIFT = 0.5
PUSH_INTERVAL = 2.0


def check_decision_hz(hz: float) -> int:
    """``hz`` as an int if MuJoCo's 250 Hz divides into it and every clip lasts a whole number of
    decisions at it (50 and 250 do; so do 10 and 25 for some clips, not all), else ValueError."""
    rate = int(round(hz))
    durations = [load_motion(name).frames / RATE for name in MOTIONS]
    if (rate <= 0 or abs(hz - rate) > 1e-9 or PHYSICS_HZ % rate
            or any(abs(d * rate - round(d * rate)) > 1e-9 for d in durations)):
        raise ValueError(f"environment parameter decision_hz must divide {PHYSICS_HZ} and fit every clip "
                         f"(e.g. 50 or 250), got {hz:g}")
    return rate


def reward_terms(rot_sq: np.ndarray, vel_sq: np.ndarray, com_sq: np.ndarray, end_sq: np.ndarray,
                 speed_sq: np.ndarray, scales) -> np.ndarray:
    """[n, 5]: the five terms exp(-k x) from the summed squared errors (each float [n])."""
    errors = np.stack([rot_sq, vel_sq, com_sq, end_sq, speed_sq], axis=-1)
    return np.exp(-np.asarray(scales, dtype=np.float64) * errors)


def build_model(num_agents: int) -> tuple[mujoco.MjModel, np.ndarray]:
    """The MjModel of ``num_agents`` ragdolls (names prefixed ``a<i>/``) and their bases [n, 3]."""
    spec = mujoco.MjSpec.from_file(str(XML_PATH))
    spec.delete(spec.body("pelvis"))
    index = np.arange(num_agents)
    base = np.column_stack([(index % AGENTS_PER_AREA) * AGENT_SPACING,
                            (index // AGENTS_PER_AREA) * AREA_SPACING, np.zeros(num_agents)])
    text = XML_PATH.read_text()
    for i in range(num_agents):
        agent = mujoco.MjSpec.from_string(text)
        spec.worldbody.add_frame(pos=base[i]).attach_body(agent.body("pelvis"), f"a{i}/", "")
    return spec.compile(), base


def resample(q: np.ndarray, stride: float, factor: int) -> np.ndarray:
    """A looping clip's qpos [F, 33] at ``factor`` times its rate [F * factor, 33]: positions and
    joint angles interpolated linearly between neighbouring frames, the root quaternion normalised
    after the same interpolation; the frame after the last is the first, advanced by ``stride``."""
    if factor == 1:
        return q
    following = np.roll(q, -1, axis=0)
    following[-1, 1] += stride
    t = (np.arange(factor) / factor)[None, :, None]
    out = ((1.0 - t) * q[:, None, :] + t * following[:, None, :]).reshape(-1, q.shape[1])
    out[:, 3:7] /= np.linalg.norm(out[:, 3:7], axis=1, keepdims=True)
    return out


class Reference:
    """Every motion's frames at one decision rate and what the reward and RSI need of them,
    concatenated over MOTIONS (``offset[m]``, ``frames[m]``): qpos [F, 33], qvel [F, 32], local part
    rotations [F, 13, 4], CoM [F, 3] and end effectors [F, 4, 3] relative to the reference root's
    horizontal position, joint-velocity vector [F, 29] (26 joints + root angular), the walk's stride
    and mean speed. The clips (50 Hz) are resampled to ``decision_hz`` (``resample``)."""

    _cache: dict[int, "Reference"] = {}

    @classmethod
    def at(cls, decision_hz: int) -> "Reference":
        """The tables at ``decision_hz``, built once per process and rate."""
        if decision_hz not in cls._cache:
            cls._cache[decision_hz] = cls(decision_hz)
        return cls._cache[decision_hz]

    def __init__(self, decision_hz: int = DECISION_HZ) -> None:
        factor = check_decision_hz(decision_hz) // RATE if decision_hz >= RATE else 0
        if factor == 0 or decision_hz % RATE:
            raise ValueError(f"decision_hz {decision_hz}: the reference clips ({RATE} Hz) are only resampled "
                             f"to multiples of {RATE} Hz")
        dt = 1.0 / decision_hz
        model = mujoco.MjModel.from_xml_path(str(XML_PATH))
        data = mujoco.MjData(model)
        parts = [model.body(name).id for name in OBSERVED]
        parents = model.body_parentid[parts]
        ends = [model.geom(name).id for name in END_EFFECTORS]
        joint_dof = [model.joint(j).dofadr[0] for j in JOINTS]
        qpos, qvel, rot, com, end, speed, frames, offset, stride = [], [], [], [], [], [], [], [], []
        for name in MOTIONS:
            q = load_motion(name).qpos
            # the walk advances by one stride per loop: its last advance plus one more frame's
            stride.append(2 * q[-1, 1] - q[-2, 1] if name == "walk" else 0.0)
            q = resample(q, stride[-1], factor)
            count = len(q)
            after = q[np.arange(1, count + 1) % count].copy()
            before = q[np.arange(-1, count - 1) % count].copy()
            after[-1, 1] += stride[-1]
            before[0, 1] -= stride[-1]
            v = np.zeros((count, model.nv))
            for k in range(count):
                mujoco.mj_differentiatePos(model, v[k], 2 * dt, before[k], after[k])
            for k in range(count):
                data.qpos[:] = q[k]
                data.qvel[:] = v[k]
                mujoco.mj_kinematics(model, data)
                mujoco.mj_comPos(model, data)
                xquat = data.xquat.copy()
                local = quat_mul(quat_conj(xquat[parents]), xquat[parts])
                local[0] = xquat[parts[0]]
                rot.append(local)
                root = np.array([q[k, 0], q[k, 1], 0.0])
                com.append(data.subtree_com[parts[0]] - root)
                end.append(data.geom_xpos[ends] - root)
            qpos.append(q)
            qvel.append(v)
            offset.append(sum(frames))
            frames.append(count)
            speed.append(stride[-1] / (count * dt))
        self.qpos, self.qvel = np.concatenate(qpos), np.concatenate(qvel)
        self.rot, self.com, self.end = np.array(rot), np.array(com), np.array(end)
        self.joint_vel = np.concatenate([self.qvel[:, joint_dof], self.qvel[:, 3:6]], axis=1)
        self.frames, self.offset = np.array(frames), np.array(offset)
        self.stride, self.speed = np.array(stride), np.array(speed)
        self.joints = self.qpos[:, 7:]
        self.decision_hz = decision_hz


class MimicTask(Task):
    name = "mimic"
    behavior_name = "Mimic"
    observation_specs = (
        ObservationSpec((OBSERVATION_SIZE,), (DimensionProperty.NONE,), ObservationType.DEFAULT,
                        f"VectorSensor_size{OBSERVATION_SIZE}"),
    )
    action_spec = ActionSpec(continuous_size=len(JOINTS), discrete_branches=())
    agents_per_area = AGENTS_PER_AREA
    max_step = round(EPISODE_SECONDS * DECISION_HZ)  # instances: EPISODE_SECONDS at their decision_hz
    decision_period = 1
    sets_reward = False
    description = ("PD-controlled ragdoll imitating a reference motion (docs/stub-tasks.md). Observations: 13 parts x "
                   "(local rotation 4, linear velocity 3, angular velocity 3, position from the pelvis 3) + "
                   "phase (1). Actions: 26 PD targets. DeepMimic-style reward; env params motion (0 stand, "
                   "1 arms, 2 squat, 3 walk), decision_hz, effort_weight, residual, push_impulse, push_interval, "
                   "reward_weights, rsi.")

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        n = self.num_agents
        self.model, self.base = build_model(n)
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        self.set_decision_hz(DECISION_HZ)
        model = self.model
        self.timestep = float(model.opt.timestep)
        joint = lambda i, name: model.joint(f"a{i}/{name}")  # noqa: E731
        self.root_qpos = np.array([joint(i, "root").qposadr[0] for i in range(n)])
        self.root_dof = np.array([joint(i, "root").dofadr[0] for i in range(n)])
        self.joint_qpos = np.array([[joint(i, j).qposadr[0] for j in JOINTS] for i in range(n)])
        self.joint_dof = np.array([[joint(i, j).dofadr[0] for j in JOINTS] for i in range(n)])
        self.actuator = np.array([[model.actuator(f"a{i}/{j}").id for j in JOINTS] for i in range(n)])
        self.agent_qpos = self.root_qpos[:, None] + np.arange(7 + len(JOINTS))  # joints follow the root
        self.agent_dof = self.root_dof[:, None] + np.arange(6 + len(JOINTS))
        assert (self.agent_qpos[:, 7:] == self.joint_qpos).all() and (self.agent_dof[:, 6:] == self.joint_dof).all()
        self.parts = np.array([[model.body(f"a{i}/{b}").id for b in OBSERVED] for i in range(n)])
        self.parents = model.body_parentid[self.parts]
        self.pelvis = self.parts[:, 0]
        self.torso = self.parts[:, 1]
        self.ends = np.array([[model.geom(f"a{i}/{g}").id for g in END_EFFECTORS] for i in range(n)])
        self.low = model.jnt_range[[[joint(i, j).id for j in JOINTS] for i in range(n)], 0]
        self.high = model.jnt_range[[[joint(i, j).id for j in JOINTS] for i in range(n)], 1]
        self.floor = model.geom("floor").id
        self.force_limit = model.actuator_forcerange[self.actuator, 1]  # [n, 26] N m
        # per geom: owning agent (-1 = floor); feet may touch the floor
        self.geom_agent = np.full(model.ngeom, -1)
        self.geom_is_foot = np.zeros(model.ngeom, dtype=bool)
        for g in range(model.ngeom):
            name = model.geom(g).name
            if "/" in name:
                prefix, local = name.split("/", 1)
                self.geom_agent[g] = int(prefix[1:])
                self.geom_is_foot[g] = local in FEET
        # per-agent episode state
        self.motion = np.zeros(n, dtype=np.int64)
        self.frame = np.zeros(n, dtype=np.int64)  # index within the motion's clip
        self.episode_step = np.zeros(n, dtype=np.int64)
        self.weights = np.zeros((n, 5))
        self.scales = np.tile(SCALES, (n, 1))
        self.residual = np.zeros(n)
        self.push_impulse = np.zeros(n)
        self.push_interval = np.full(n, PUSH_INTERVAL)
        self.max_drift = np.full(n, MAX_DRIFT)
        self.effort_weight = np.zeros(n)
        self.last_effort = np.zeros(n)  # the mean relative actuator force of the last decision (0 if no effort_weight)
        self.term_sum = np.zeros((n, 5))
        self.last_terms = np.zeros((n, 5))
        self.last_fell = np.zeros(n, dtype=bool)
        self.last_push = np.zeros((n, 3))  # the impulse (N s) applied in the last decision
        self.reset()

    def set_decision_hz(self, hz: float) -> None:
        """Decide ``hz`` times per simulated second: the MuJoCo steps per decision, max_step (10 s)
        and the reference tables follow."""
        rate = check_decision_hz(hz)
        self.decision_hz, self.substeps, self.control_dt = rate, PHYSICS_HZ // rate, 1.0 / rate
        self.max_step = round(EPISODE_SECONDS * rate)
        self.ref = Reference.at(rate)

    # --- reference lookups -------------------------------------------------------------------
    def ref_rows(self, frame: np.ndarray | None = None) -> np.ndarray:
        """Row of every agent's current reference frame in the Reference tables."""
        return self.ref.offset[self.motion] + (self.frame if frame is None else frame)

    def anchor(self) -> np.ndarray:
        """[n, 3]: where the reference root stands on the floor (its horizontal position)."""
        rows = self.ref_rows()
        anchor = self.base + np.column_stack([self.ref.qpos[rows, 0], self.ref.qpos[rows, 1], np.zeros(len(rows))])
        walking = self.ref.stride[self.motion] > 0
        anchor[walking, 1] = self.data.xpos[self.pelvis[walking], 1]  # the walk's reference follows
        return anchor

    # --- the task interface --------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        """Read the environment parameters and put the agents in mask at their reference (RSI)."""
        agents = np.flatnonzero(self.all_agents(mask))
        if len(agents) == 0:
            return
        count, get = len(agents), self.env_params.get_many
        hz = self.env_params.get("decision_hz", DECISION_HZ)
        if mask is None:  # every agent restarts together: the rate may change (one MuJoCo step for all)
            self.set_decision_hz(hz)
        elif round(hz) != self.decision_hz:
            raise ValueError(f"environment parameter decision_hz changed from {self.decision_hz} to {hz:g} "
                             "between episodes; it is read when every agent resets together (a RESET)")
        motion = np.rint(get("motion", 0, count)).astype(np.int64)
        if ((motion < 0) | (motion >= len(MOTIONS))).any():
            raise ValueError(f"environment parameter motion must be 0..{len(MOTIONS) - 1} "
                             f"({', '.join(MOTIONS)}), got {sorted(set(motion.tolist()))}")
        self.motion[agents] = motion
        frames = self.ref.frames[motion]
        rsi = get("rsi", 1, count) > 0.5
        self.frame[agents] = np.where(rsi, (self.rng.random(count) * frames).astype(np.int64), 0)
        self.episode_step[agents] = 0
        self.term_sum[agents] = 0.0
        preset = np.rint(get("reward_weights", 0, count))
        seed_weights = np.array([SEED_WEIGHTS[name] for name in MOTIONS])[motion]
        weights = np.where(preset[:, None] == 1, np.array(DEEPMIMIC_WEIGHTS), seed_weights)
        scales = np.tile(SCALES, (count, 1))
        for j, term in enumerate(("r", "v", "m", "e", "t")):
            w, k = get(f"w_{term}", -1, count), get(f"k_{term}", -1, count)
            weights[:, j] = np.where(w >= 0, w, weights[:, j])
            scales[:, j] = np.where(k >= 0, k, scales[:, j])
        self.weights[agents], self.scales[agents] = weights, scales
        self.residual[agents] = np.maximum(get("residual", 0, count), 0.0)
        self.push_impulse[agents] = np.maximum(get("push_impulse", 0, count), 0.0)
        self.push_interval[agents] = np.maximum(get("push_interval", PUSH_INTERVAL, count), self.control_dt)
        self.effort_weight[agents] = np.clip(get("effort_weight", 0.0, count), 0.0, 1.0)
        self.max_drift[agents] = get("max_drift", MAX_DRIFT, count)
        rows = self.ref.offset[motion] + self.frame[agents]
        qpos = self.ref.qpos[rows].copy()
        qpos[:, :3] += self.base[agents]
        walking = self.ref.stride[motion] > 0
        qpos[walking, 1] = self.base[agents[walking], 1]
        self.data.qpos[self.agent_qpos[agents]] = qpos
        self.data.qvel[self.agent_dof[agents]] = self.ref.qvel[rows]
        self.data.ctrl[self.actuator[agents]] = self.ref.joints[rows]
        self.data.xfrc_applied[self.torso[agents]] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def targets(self, action: np.ndarray) -> np.ndarray:
        """[n, 26] PD targets (rad) from actions [n, 26] in [-1, 1] (see ``residual``), aimed at the
        reference frame the decision leads to."""
        span = self.high - self.low
        absolute = np.where(action >= 0.0, action * self.high, -action * self.low)
        following = self.ref.joints[self.ref_rows((self.frame + 1) % self.ref.frames[self.motion])]
        residual = np.clip(following + action * self.residual[:, None] * 0.5 * span, self.low, self.high)
        return np.where(self.residual[:, None] > 0, residual, absolute)

    def absolute_actions(self, targets: np.ndarray) -> np.ndarray:
        """The inverse of the default (absolute) map of ``targets``: actions [n, 26] in [-1, 1] whose PD
        targets are ``targets`` [n, 26] (rad, within the limits): q / high for q >= 0, -q / low below."""
        q = np.clip(targets, self.low, self.high)
        up = np.divide(q, self.high, out=np.zeros_like(q), where=self.high > 0)
        down = np.divide(-q, self.low, out=np.zeros_like(q), where=self.low < 0)
        return np.where(q >= 0.0, up, down)

    def reference_actions(self) -> np.ndarray:
        """[n, 26]: the actions that put every PD target on the reference frame the next decision leads
        to (what ``targets`` aims at): the absolute map's inverse, or 0 in ``residual`` mode. The
        scripted expert of ``--record-demo`` (unity_stub_env/record_demo.py)."""
        following = self.ref.joints[self.ref_rows((self.frame + 1) % self.ref.frames[self.motion])]
        return np.where(self.residual[:, None] > 0, 0.0, self.absolute_actions(following))

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 170]]: see the module docstring for the order."""
        data, n = self.data, self.num_agents
        xquat = data.xquat[self.parts]  # [n, 13, 4]
        local = quat_mul(quat_conj(data.xquat[self.parents]), xquat)
        local[:, 0] = xquat[:, 0]
        local = np.where(local[..., :1] < 0, -local, local)
        rot = data.xmat[self.pelvis].reshape(n, 3, 3)  # pelvis frame -> world
        pelvis_pos = data.xpos[self.pelvis]
        angular = data.cvel[self.parts, :3]
        offset = data.xpos[self.parts] - data.subtree_com[self.pelvis][:, None, :]
        linear = data.cvel[self.parts, 3:] + cross(angular, offset)  # cvel is about the root subtree CoM
        relative = data.xpos[self.parts] - pelvis_pos[:, None, :]
        to_local = lambda v: np.einsum("nji,nkj->nki", rot, v)  # noqa: E731  R^T v for every part
        position = to_local(relative)
        position[:, 0] = [0.0, 0.0, 0.0]
        position[:, 0, 2] = pelvis_pos[:, 2] - self.base[:, 2]
        obs = np.concatenate([local, to_local(linear), to_local(angular), position], axis=2).reshape(n, -1)
        phase = np.where(self.motion == 0, 0.0, self.frame / self.ref.frames[self.motion])
        return [np.concatenate([obs, phase[:, None]], axis=1).astype(np.float32)]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """continuous float [n, 26] in [-1, 1] -> one decision (250 / decision_hz MuJoCo steps) of every agent."""
        n, data = self.num_agents, self.data
        action = np.asarray(continuous, dtype=np.float64).reshape(n, len(JOINTS)).clip(-1.0, 1.0)
        data.ctrl[self.actuator] = self.targets(action)
        # pushes: at every multiple of push_interval seconds into the episode
        dt = self.control_dt
        elapsed = (self.episode_step + 1) * dt
        due = (self.push_impulse > 0) & (np.floor(elapsed / self.push_interval + 1e-9)
                                         > np.floor((elapsed - dt) / self.push_interval + 1e-9))
        self.last_push[:] = 0.0
        if due.any():
            azimuth = self.rng.uniform(0.0, 2 * math.pi, int(due.sum()))
            impulse = self.push_impulse[due, None] * np.column_stack([np.cos(azimuth), np.sin(azimuth),
                                                                      np.zeros(len(azimuth))])
            self.last_push[due] = impulse
            data.xfrc_applied[self.torso[due], :3] = impulse / dt
        measure = bool(self.effort_weight.any())  # the effort costs a gather per MuJoCo step: only when used
        force = np.zeros(n)
        for _ in range(self.substeps):
            mujoco.mj_step(self.model, data)
            if measure:
                force += (np.abs(data.actuator_force[self.actuator]) / self.force_limit).mean(axis=1)
        self.last_effort = force / self.substeps
        if due.any():
            data.xfrc_applied[self.torso[due], :3] = 0.0
        # advance the reference
        frames = self.ref.frames[self.motion]
        self.frame += 1
        self.frame[self.frame >= frames] = 0
        rows = self.ref_rows()
        terms, drift = self.compare(rows)
        rewards = (self.weights * terms).sum(axis=1) * (1.0 - self.effort_weight * self.last_effort)
        fell = self._fallen() | (drift > self.max_drift)
        self.episode_step += 1
        self.term_sum += terms
        self.last_terms, self.last_fell = terms, fell
        interrupted = ~fell & (self.episode_step >= self.max_step)
        done = fell | interrupted
        stats = []
        if done.any():
            means = self.term_sum[done] / self.episode_step[done, None]
            for j, term in enumerate(TERMS[:4]):
                stats += [(f"Mimic/{term}", float(v), StatsAggregationMethod.AVERAGE) for v in means[:, j].tolist()]
            stats += [("Mimic/Fell", float(v), StatsAggregationMethod.AVERAGE) for v in fell[done].tolist()]
        return TaskStep(rewards.astype(np.float32), done, interrupted, stats)

    def compare(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reward terms [n, 5] against the reference rows, and the CoM distance [n] (m)."""
        data, ref, n = self.data, self.ref, self.num_agents
        local = quat_mul(quat_conj(data.xquat[self.parents]), data.xquat[self.parts])
        local[:, 0] = data.xquat[self.pelvis]
        rot_sq = (quat_angle(local, ref.rot[rows]) ** 2).sum(axis=1)
        velocity = np.concatenate([data.qvel[self.joint_dof], data.qvel[self.root_dof[:, None] + np.arange(3, 6)]], axis=1)
        vel_sq = ((velocity - ref.joint_vel[rows]) ** 2).sum(axis=1)
        anchor = self.anchor()
        com_error = data.subtree_com[self.pelvis] - (anchor + ref.com[rows])
        com_sq = (com_error**2).sum(axis=1)
        end_sq = ((data.geom_xpos[self.ends] - (anchor[:, None, :] + ref.end[rows])) ** 2).sum(axis=(1, 2))
        pelvis_speed = data.cvel[self.pelvis, 4] + cross(data.cvel[self.pelvis, :3], data.xpos[self.pelvis]
                                                            - data.subtree_com[self.pelvis])[:, 1]
        speed_sq = (pelvis_speed - ref.speed[self.motion]) ** 2
        return reward_terms(rot_sq, vel_sq, com_sq, end_sq, speed_sq, self.scales), np.sqrt(com_sq)

    def _fallen(self) -> np.ndarray:
        """bool [n]: a geom other than a foot touches the floor."""
        fallen = np.zeros(self.num_agents, dtype=bool)
        ncon = self.data.ncon
        if ncon:
            pairs = self.data.contact.geom[:ncon]
            other = np.where(pairs[:, 0] == self.floor, pairs[:, 1], pairs[:, 0])
            floor = (pairs == self.floor).any(axis=1)
            bad = floor & ~self.geom_is_foot[other] & (self.geom_agent[other] >= 0)
            fallen[self.geom_agent[other[bad]]] = True
        return fallen
