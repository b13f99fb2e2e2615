"""``ball3d``: ML-Agents' 3DBall in MuJoCo. Each agent tilts a plate to keep a ball on it.

One MjModel holds all ``num_areas * 12`` plates (12 agents per area, like the 3DBall scene),
so a single ``mj_step`` advances every agent. MuJoCo is z-up: the plate tilts about the world
x and y axes (two hinges driven by position actuators), the ball has a free joint.

Observation, float32 [8] per agent: plate tilt about x and about y (rad), ball position
relative to the plate centre (x, y, z), ball linear velocity (x, y, z).
Actions: 2 continuous in [-1, 1]; action a changes the target tilt by a * 2 degrees per
control step (Unity's 3DBall rotates by 2 * a degrees per FixedUpdate); targets are clipped
to +-0.25 rad. One control step = 0.02 s (2 MuJoCo steps of 0.01 s); a decision every 5.
Reward (Unity's SetReward each step): +0.1 while the ball is on the plate; -1 and the
episode ends when the ball falls (relative z < -2, |relative x| > 3 or |relative y| > 3).
Episodes are interrupted after max_step = 5000 control steps (max return 1000 * 0.1 = 100).
Episode start: random tilt in +-10 degrees per axis, ball 4 m above the plate centre with a
random offset in +-1.5 m; environment parameters ``mass`` (ball mass, default 1),
``scale`` (ball diameter, default 1) and ``gravity`` (default 9.81) are read at episode start.
Deterministic for a given seed and action sequence.
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

AGENTS_PER_AREA = 12
AREA_SPACING = 12.0  # metres between plate centres on the grid
PLATE_HEIGHT = 2.0
PLATE_HALF_SIZE = 2.5
BALL_RADIUS = 0.5  # scale 1 = a unit-diameter sphere, as in Unity
TIMESTEP = 0.01
SUBSTEPS = 2  # MuJoCo steps per control step (0.02 s, Unity's fixed timestep)
MAX_TILT = 0.25  # rad
TILT_RATE = np.deg2rad(2.0)  # rad of target change per control step at |action| = 1
# PD plate servo: position actuator stiffness, joint damping (Euler integrates joint damping
# implicitly, so this is stable at 0.01 s); about 0.9 of critical damping for the plate inertia.
PLATE_STIFFNESS = 2000.0
PLATE_DAMPING = 250.0
FALL_DEPTH = -2.0
FALL_DISTANCE = 3.0
ON_PLATE_REWARD = 0.1
FALL_REWARD = -1.0
_PHYSICS_PARAMETERS = ("mass", "scale", "gravity")  # the environment parameters reset() reads


def build_mjcf(num_plates: int) -> str:
    """The MJCF text of ``num_plates`` plate+ball pairs laid out on a square grid."""
    columns = int(np.ceil(np.sqrt(num_plates)))
    bodies, actuators = [], []
    for i in range(num_plates):
        x, y = (i % columns) * AREA_SPACING, (i // columns) * AREA_SPACING
        bodies.append(
            f'<body name="plate{i}" pos="{x} {y} {PLATE_HEIGHT}">'
            f'<joint name="tilt_x{i}" type="hinge" axis="1 0 0" damping="{PLATE_DAMPING}"/>'
            f'<joint name="tilt_y{i}" type="hinge" axis="0 1 0" damping="{PLATE_DAMPING}"/>'
            f'<geom type="box" size="{PLATE_HALF_SIZE} {PLATE_HALF_SIZE} 0.2" mass="5"/></body>'
            f'<body name="ball{i}" pos="{x} {y} {PLATE_HEIGHT + 4}"><freejoint name="ball{i}"/>'
            f'<geom name="ball{i}" type="sphere" size="{BALL_RADIUS}" mass="1"/></body>'
        )
        for axis in ("x", "y"):
            actuators.append(f'<position joint="tilt_{axis}{i}" kp="{PLATE_STIFFNESS}"/>')
    return (
        '<mujoco model="ball3d">'
        # island="disable": every plate+ball pair is its own constraint island, and finding them
        # each step cost more than solving the 12 small systems together (Newton converges in one
        # iteration either way): mj_step x2 63 -> 50 us for one area, measured with MuJoCo 4.0
        f'<option timestep="{TIMESTEP}" integrator="Euler" gravity="0 0 -9.81"><flag island="disable"/></option>'
        '<default><geom friction="1 0.005 0.0001"/></default>'
        f'<worldbody>{"".join(bodies)}</worldbody>'
        f'<actuator>{"".join(actuators)}</actuator></mujoco>'
    )


class Ball3DTask(Task):
    name = "ball3d"
    behavior_name = "3DBall"
    observation_specs = (
        ObservationSpec((8,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "VectorSensor_size8"),
    )
    action_spec = ActionSpec(continuous_size=2, discrete_branches=())
    agents_per_area = AGENTS_PER_AREA
    max_step = 5000
    decision_period = 5
    sets_reward = True
    description = "MuJoCo plate-and-ball balancing; max return 100 per episode."

    def __init__(self, num_areas: int, seed: int, env_params: EnvironmentParameters | None = None):
        super().__init__(num_areas, seed, env_params)
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.num_agents))
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(self.seed)
        self._index_arrays()
        self.target_tilt = np.zeros((self.num_agents, 2))
        self.episode_step = np.zeros(self.num_agents, dtype=np.int64)
        # every ball has the default mass and size and gravity is the default (written by our own
        # formulas, so writing them again would change nothing): episode starts can skip that
        self._default_physics = False
        self.reset()

    def _index_arrays(self) -> None:
        """Precomputed qpos/qvel/ctrl/body/geom indices, each int [n] or [n, k]."""
        model, n = self.model, self.num_agents
        joint = lambda name: model.joint(name)  # noqa: E731
        self.tilt_qpos = np.array([[joint(f"tilt_x{i}").qposadr[0], joint(f"tilt_y{i}").qposadr[0]]
                                   for i in range(n)])
        self.tilt_qvel = np.array([[joint(f"tilt_x{i}").dofadr[0], joint(f"tilt_y{i}").dofadr[0]]
                                   for i in range(n)])
        ball_qpos = np.array([joint(f"ball{i}").qposadr[0] for i in range(n)])
        ball_qvel = np.array([joint(f"ball{i}").dofadr[0] for i in range(n)])
        self.ball_pos_qpos = ball_qpos[:, None] + np.arange(3)  # [n, 3]
        self.ball_quat_qpos = ball_qpos[:, None] + 3 + np.arange(4)  # [n, 4]
        self.ball_qvel = ball_qvel[:, None] + np.arange(6)  # [n, 6]: linear then angular
        self.ctrl = np.arange(2 * n).reshape(n, 2)  # actuators were declared x, y per plate
        self.ball_body = np.array([model.body(f"ball{i}").id for i in range(n)])
        self.ball_geom = np.array([model.geom(f"ball{i}").id for i in range(n)])
        self.plate_centre = np.array([model.body(f"plate{i}").pos for i in range(n)])  # [n, 3]
        # build_mjcf lays every agent out contiguously: qpos [tilt x, tilt y, ball pos 3, quat 4]
        # and qvel [tilt x, tilt y, ball lin 3, ang 3], so per-agent rows are plain reshaped views.
        assert np.array_equal(self.tilt_qpos, 9 * np.arange(n)[:, None] + np.arange(2))
        assert np.array_equal(self.ball_qvel, 8 * np.arange(n)[:, None] + 2 + np.arange(6))
        self.qpos_rows = self.data.qpos.reshape(n, 9)  # views into MjData: no copies per step
        self.qvel_rows = self.data.qvel.reshape(n, 8)
        self.ctrl_rows = self.data.ctrl.reshape(n, 2)

    # ----------------------------------------------------------------------------------------
    def reset(self, mask: np.ndarray | None = None) -> None:
        """New episodes for the agents in mask: random tilt and ball drop, env params applied."""
        agents = np.flatnonzero(self.all_agents(mask))
        if len(agents) == 0:
            return
        # a parameter the trainer sent stays set (samplers are never removed): from then on every
        # episode start reads them; until then the defaults are written once, by the
        # constructor's reset of every agent
        custom = any(key in self.env_params.samplers for key in _PHYSICS_PARAMETERS)
        if custom or not self._default_physics:
            self._apply_environment_parameters(agents)
            self._default_physics = not custom and len(agents) == self.num_agents
        draws = self.rng.uniform(-1.0, 1.0, size=(len(agents), 4))
        tilt = draws[:, :2] * np.deg2rad(10.0)
        qpos, qvel = self.data.qpos, self.data.qvel
        self.target_tilt[agents] = tilt
        qpos[self.tilt_qpos[agents]] = tilt
        qvel[self.tilt_qvel[agents]] = 0.0
        self.data.ctrl[self.ctrl[agents]] = tilt
        offset = np.column_stack([draws[:, 2:] * 1.5, np.full(len(agents), 4.0)])
        qpos[self.ball_pos_qpos[agents]] = self.plate_centre[agents] + offset
        qpos[self.ball_quat_qpos[agents]] = (1.0, 0.0, 0.0, 0.0)
        qvel[self.ball_qvel[agents]] = 0.0
        self.episode_step[agents] = 0

    def _apply_environment_parameters(self, agents: np.ndarray) -> None:
        params = self.env_params
        mass = params.get_many("mass", 1.0, len(agents))
        radius = BALL_RADIUS * params.get_many("scale", 1.0, len(agents))
        inertia = 0.4 * mass * radius**2  # solid sphere
        model, bodies, dofs = self.model, self.ball_body[agents], self.ball_qvel[agents]
        model.body_mass[bodies] = mass
        model.body_inertia[bodies] = inertia[:, None]
        # MuJoCo caches these for "simple" bodies (constant mass matrix) and for contact softness
        model.dof_M0[dofs] = np.column_stack([np.repeat(mass[:, None], 3, 1), np.repeat(inertia[:, None], 3, 1)])
        model.body_invweight0[bodies] = np.column_stack([1.0 / mass, 1.0 / inertia])
        model.dof_invweight0[dofs] = 1.0 / model.dof_M0[dofs]
        model.geom_size[self.ball_geom[agents], 0] = radius
        model.geom_rbound[self.ball_geom[agents]] = radius  # broadphase bounds follow the size
        model.geom_aabb[self.ball_geom[agents], 3:] = radius[:, None]
        model.opt.gravity[2] = -params.get("gravity", 9.81)

    def observe(self) -> list[np.ndarray]:
        """[float32 [n, 8]]: tilt x, tilt y, ball position - plate centre (3), ball velocity (3)."""
        obs = np.empty((self.num_agents, 8), dtype=np.float32)
        obs[:, 0:2] = self.qpos_rows[:, 0:2]
        obs[:, 2:5] = self.qpos_rows[:, 2:5] - self.plate_centre
        obs[:, 5:8] = self.qvel_rows[:, 2:5]
        return [obs]

    def step(self, continuous: np.ndarray, discrete: np.ndarray) -> TaskStep:
        """continuous float [n, 2] in [-1, 1] -> one 0.02 s control step of every plate."""
        action = np.asarray(continuous, dtype=np.float64).reshape(self.num_agents, 2).clip(-1.0, 1.0)
        self.target_tilt = (self.target_tilt + action * TILT_RATE).clip(-MAX_TILT, MAX_TILT)
        self.ctrl_rows[:] = self.target_tilt
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self.episode_step += 1
        relative = self.qpos_rows[:, 2:5] - self.plate_centre
        fell = ((relative[:, 2] < FALL_DEPTH) | (np.abs(relative[:, 0]) > FALL_DISTANCE)
                | (np.abs(relative[:, 1]) > FALL_DISTANCE))
        rewards = np.where(fell, FALL_REWARD, ON_PLATE_REWARD).astype(np.float32)
        interrupted = ~fell & (self.max_step > 0) & (self.episode_step >= self.max_step)
        done = fell | interrupted
        stats = []
        if done.any():
            stats = [("3DBall/Ball Fell", float(f), StatsAggregationMethod.AVERAGE)
                     for f in fell[done].tolist()]
            stats.append(("3DBall/Last Episode Length", float(self.episode_step[done][-1]),
                          StatsAggregationMethod.MOST_RECENT))
        return TaskStep(rewards, done, interrupted, stats)
