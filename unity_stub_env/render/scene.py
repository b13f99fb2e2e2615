"""MuJoCo tasks drawn with MuJoCo's offscreen renderer: one ``Shot`` per task says where the camera
looks (the followed agent, or its area for the planar team games), how far away, whether it
follows, and which cues to add to the scene (``CUES``).

Colours are painted into the task's own ``model.geom_rgba`` (this model is the play's own copy;
colours play no part in the physics), the cues are extra geoms appended to the scene after
``update_scene``: they are drawn, never simulated."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import mujoco
import numpy as np

from unity_stub_env.render.gl import open_renderer

Vec = np.ndarray
BODY = (0.62, 0.68, 0.78, 1.0)
FLOOR = (0.42, 0.45, 0.40, 1.0)
SPHERE = (1.0, 0.35, 0.05, 1.0)  # dodge's thrown sphere (tests look for this colour)
AIM = (1.0, 0.1, 0.1, 0.45)
GHOST = (0.2, 0.75, 1.0, 0.35)
TARGET = (1.0, 0.8, 0.1, 0.45)
TEAM = ((0.2, 0.4, 1.0, 1.0), (1.0, 0.25, 0.2, 1.0))
MARK = (1.0, 1.0, 1.0, 0.5)


@dataclass(frozen=True)
class Shot:
    """body(task, k): the body id of agent k; focus(task, k): the point the camera looks at;
    distance (m), elevation and azimuth (deg, MuJoCo's free camera); follow: move the camera with
    the focus (else it stays where the first frame put it)."""

    body: Callable
    focus: Callable
    distance: float
    elevation: float = -15.0
    azimuth: float = 90.0
    follow: bool = True
    span: Callable | None = None  # span(task, k): the distance instead, when what to frame moves apart


def _dodge_chest(task, k):
    return task.base[k] + (0.0, 0.0, 1.1)


def _dodge_ball(task, k):
    return task.data.geom_xpos[task.ball_geom[k]]


def _dodge_focus(task, k):
    """Between the character and its sphere: both stay in the picture from the throw on."""
    return 0.5 * (_dodge_chest(task, k) + _dodge_ball(task, k))


def _dodge_span(task, k):
    return 3.0 + 1.3 * min(float(np.linalg.norm(_dodge_ball(task, k) - _dodge_chest(task, k))), 8.0)


def _body(name_of: Callable[[object, int], str]) -> Callable:
    return lambda task, k: task.model.body(name_of(task, k)).id


def _at_body(task, k):
    return task.data.xpos[SHOTS[task.name].body(task, k)].copy()


def _area_centre(spacing_origin: Callable[[object, int], Vec]) -> Callable:
    return lambda task, k: np.array([*spacing_origin(task, k // task.agents_per_area)[:2], 0.0])


SHOTS: dict[str, Shot] = {
    "ball3d": Shot(_body(lambda t, k: f"plate{k}"), _at_body, 11.0, -25.0),
    "dodge": Shot(lambda t, k: int(t.pelvis_body[k]), _dodge_focus, 6.0, -12.0, 35.0, span=_dodge_span),
    "mimic": Shot(lambda t, k: int(t.pelvis[k]), lambda t, k: t.data.xpos[t.pelvis[k]] * (1, 1, 0) + (0, 0, 0.9),
                  4.5, -12.0, 20.0),
    "creature": Shot(lambda t, k: int(t.root[k]), _at_body, 5.0, -22.0, 60.0),
    "pushblock": Shot(_body(lambda t, k: f"area{k // 2}/agent{k % 2}"),
                      _area_centre(lambda t, a: (0.0, 10.0 * a)), 7.5, -60.0, 90.0, follow=False),
    "dungeon": Shot(_body(lambda t, k: f"area{k // 3}/agent{k % 3}"),
                    _area_centre(lambda t, a: t.origin[a]), 3.6, -65.0, 90.0, follow=False),
    "soccer": Shot(_body(lambda t, k: f"player{k // t.agents_per_area}_{k % t.agents_per_area}"),
                   _area_centre(lambda t, a: t.origin[a]), 4.6, -65.0, 90.0, follow=False),
}
SHOTS["soccer_twos"] = SHOTS["soccer"]


# --- colours ------------------------------------------------------------------------------------
def _paint(task) -> None:
    """Readable colours: bodies light, floors dark, the things a viewer follows bright."""
    model, rgba = task.model, task.model.geom_rgba
    names = [model.geom(g).name for g in range(model.ngeom)]
    default = np.all(np.isclose(rgba, 0.5), axis=1)  # geoms the MJCF left MuJoCo's grey
    rgba[default] = BODY
    for g, name in enumerate(names):
        local = name.split("/")[-1]
        if local == "floor" and default[g]:
            rgba[g] = FLOOR
        if task.name == "dodge" and local == "ball":
            rgba[g] = SPHERE
        if task.name == "ball3d" and name.startswith("ball"):
            rgba[g] = SPHERE
    if task.name in ("soccer", "soccer_twos"):  # players by team; agents are ordered team 0 then team 1
        per_team = task.agents_per_area // 2
        for k in range(task.num_agents):
            body = SHOTS[task.name].body(task, k)
            rgba[model.body_geomadr[body]: model.body_geomadr[body] + model.body_geomnum[body]] = \
                TEAM[(k % task.agents_per_area) // per_team]


# --- cues: extra geoms in the scene ----------------------------------------------------------------
def add_geom(scene: mujoco.MjvScene, kind: int, size, pos, mat=None, rgba=MARK) -> None:
    if scene.ngeom >= scene.maxgeom:
        return
    mujoco.mjv_initGeom(scene.geoms[scene.ngeom], kind, np.asarray(size, np.float64), np.asarray(pos, np.float64),
                        np.eye(3).ravel() if mat is None else np.asarray(mat, np.float64).ravel(),
                        np.asarray(rgba, np.float32))
    scene.ngeom += 1


def _dodge_cues(task, k: int, scene, state) -> None:
    """The point the sphere was aimed at, a translucent red ball (drawn until the episode ends)."""
    add_geom(scene, mujoco.mjtGeom.mjGEOM_SPHERE, (0.15, 0, 0), task.aim[k], rgba=AIM)


def _mimic_cues(task, k: int, scene, state) -> None:
    """The reference pose as a translucent ghost: the agent's geoms placed by the reference's joint
    angles at the current frame, rooted where the task anchors the reference."""
    ghost = state.setdefault("ghost", mujoco.MjData(task.model))
    q = task.ref.qpos[task.ref_rows()[k]].copy()
    q[:2] = task.anchor()[k, :2]
    ghost.qpos[:] = task.data.qpos
    ghost.qpos[task.agent_qpos[k]] = q
    mujoco.mj_kinematics(task.model, ghost)
    model = task.model
    for g in np.flatnonzero(task.geom_agent == k):
        add_geom(scene, int(model.geom_type[g]), model.geom_size[g], ghost.geom_xpos[g], ghost.geom_xmat[g], GHOST)


def _creature_cues(task, k: int, scene, state) -> None:
    """The target with a translucent beacon above it, visible from anywhere in the arena."""
    target = task.target[k]
    add_geom(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, (0.12, 0.75, 0), target + (0, 0, 0.75), rgba=TARGET)


def _marker_cues(task, k: int, scene, state) -> None:
    """Several agents in view: a ring over the one ``--agent`` picks."""
    position = task.data.xpos[SHOTS[task.name].body(task, k)]
    add_geom(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, (0.2, 0.005, 0), position + (0, 0, 0.25), rgba=MARK)


CUES: dict[str, Callable] = {"dodge": _dodge_cues, "mimic": _mimic_cues, "creature": _creature_cues,
                             "pushblock": _marker_cues, "dungeon": _marker_cues, "soccer": _marker_cues,
                             "soccer_twos": _marker_cues}


class MujocoView:
    """Frames of ``task`` (a MuJoCo task) seen by a camera on agent ``agent``."""

    def __init__(self, task, agent: int, width: int, height: int, samples: int = 4) -> None:
        """samples: multisampling (antialiasing) of the offscreen buffer; 0 draws ~3x faster on a CPU
        (llvmpipe: 29 vs 75 ms a 640x480 dodge frame, bench/render.py)."""
        if task.name not in SHOTS:
            raise KeyError(task.name)
        self.task, self.agent, self.shot = task, agent, SHOTS[task.name]
        _paint(task)
        task.model.vis.headlight.ambient[:] = 0.45
        task.model.vis.headlight.diffuse[:] = 0.55
        task.model.vis.quality.offsamples = samples
        # MuJoCo tessellates capsules and spheres for a full screen (28 slices, 16 stacks); llvmpipe's
        # time grows with the triangles, and a small frame shows no difference with fewer
        # (mimic's eight figures at 320x240: 33 -> ~18 ms a frame with 15 slices and 8 stacks)
        slices = min(28, max(12, height // 16))
        task.model.vis.quality.numslices, task.model.vis.quality.numstacks = slices, max(8, slices * 16 // 28)
        self.renderer = open_renderer(task.model, width, height)
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.distance, self.camera.elevation = self.shot.distance, self.shot.elevation
        self.camera.azimuth = self.shot.azimuth
        self.camera.lookat[:] = self.shot.focus(task, agent)
        if self.shot.span is not None:
            self.camera.distance = self.shot.span(task, agent)
        self.state: dict = {}

    def frame(self) -> np.ndarray:
        """uint8 [height, width, 3] of the current state."""
        task = self.task
        if self.shot.follow:  # ease towards the agent: a walk's sway does not shake the picture
            self.camera.lookat[:] += 0.5 * (self.shot.focus(task, self.agent) - self.camera.lookat)
        if self.shot.span is not None:
            self.camera.distance += 0.5 * (self.shot.span(task, self.agent) - self.camera.distance)
        self.renderer.update_scene(task.data, self.camera)
        if task.name == "ball3d":  # the plates float: a floor under them gives the picture depth
            add_geom(self.renderer.scene, mujoco.mjtGeom.mjGEOM_PLANE, (40, 40, 1), (0, 0, 0), rgba=FLOOR)
        cues = CUES.get(task.name)
        if cues is not None:
            cues(task, self.agent, self.renderer.scene, self.state)
        return self.renderer.render()

    def close(self) -> None:
        self.renderer.close()
