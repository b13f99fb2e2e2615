"""``render_mode="rgb_array"`` frames of a MuJoCo stub task: the stub's own view
(``unity_stub_env.render.scene.MujocoView``: the camera on the first agent, the task's cues), so a
Gymnasium frame shows what ``unity-stub-env --play`` films. Tasks without a MuJoCo scene
(``basic``, ``runner``, ``mirror``) have no frames here.

MuJoCo picks its OpenGL backend once, when it is first imported, from MUJOCO_GL; importing
``unity_stub_env`` sets the headless default (docs/video.md)."""
from __future__ import annotations

import numpy as np

DEFAULT_SIZE = (480, 640)  # height, width


def can_render(task) -> bool:
    from unity_stub_env.render.scene import SHOTS

    return task.name in SHOTS


class FrameRenderer:
    def __init__(self, task, height: int = DEFAULT_SIZE[0], width: int = DEFAULT_SIZE[1]) -> None:
        from unity_stub_env.render.scene import MujocoView

        self.view = MujocoView(task, agent=0, width=width, height=height)

    def frame(self) -> np.ndarray:
        """uint8 [height, width, 3] of the scene as it is now."""
        import mujoco

        # positions of the bodies from qpos: a reset writes qpos only, and mj_step recomputes
        # these anyway, so the simulation does not depend on whether anyone renders
        mujoco.mj_kinematics(self.view.task.model, self.view.task.data)
        return self.view.frame()

    def close(self) -> None:
        self.view.close()


class SceneFrames:
    """The frames of one in-process env (single-agent, vector or PettingZoo): the renderer opens at
    the first ``render()`` and is dropped when the scene rebuilds its task (a seeded reset makes a
    new MjModel) or the env closes."""

    def __init__(self, scene, render_mode: str | None) -> None:
        self.scene, self.render_mode = scene, render_mode
        self._renderer: FrameRenderer | None = None

    def frame(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = FrameRenderer(self.scene.task)
        return self._renderer.frame()

    def drop(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
