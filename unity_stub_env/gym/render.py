"""``render_mode="rgb_array"`` frames of a MuJoCo stub task: MuJoCo's offscreen renderer with its
default free camera (the whole scene in view). Tasks that are not MuJoCo scenes (``basic``,
``runner``) have no frames.

MuJoCo picks its OpenGL backend once, when it is first imported, from MUJOCO_GL: on a machine
without a display that must be ``egl`` (or ``osmesa``) before anything imports mujoco."""
from __future__ import annotations

import numpy as np

DEFAULT_SIZE = (480, 640)  # height, width


def can_render(task) -> bool:
    return hasattr(task, "model") and hasattr(task, "data")


class FrameRenderer:
    def __init__(self, task, height: int = DEFAULT_SIZE[0], width: int = DEFAULT_SIZE[1]) -> None:
        import mujoco

        self._mujoco = mujoco
        self.task = task
        try:
            self.renderer = mujoco.Renderer(task.model, height=height, width=width)
        except Exception as error:  # the backend's own errors name neither the cause nor the fix
            raise RuntimeError(f"MuJoCo's offscreen renderer could not start ({error}); without a display, "
                               "set MUJOCO_GL=egl (or osmesa) in the environment before Python starts") from error
        self.camera = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(task.model, self.camera)

    def frame(self) -> np.ndarray:
        """uint8 [height, width, 3] of the scene as it is now."""
        # positions of the bodies from qpos: a reset writes qpos only, and mj_step recomputes
        # these anyway, so the simulation does not depend on whether anyone renders
        self._mujoco.mj_kinematics(self.task.model, self.task.data)
        self.renderer.update_scene(self.task.data, camera=self.camera)
        return self.renderer.render()

    def close(self) -> None:
        self.renderer.close()
