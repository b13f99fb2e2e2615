"""Which OpenGL MuJoCo renders with, and one clear error when there is none.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when ``mujoco`` is first imported: unset, it
tries GLFW, which needs a display. ``headless_default`` (called by ``unity_stub_env`` before
anything imports MuJoCo) chooses EGL on a Linux machine without a display, so a headless
``--play`` works with no setup; a value the user set is kept.

``open_renderer`` loads triton's library (when triton is installed) before the first OpenGL context:
Mesa's software driver brings its own LLVM into the process, and triton loaded after it crashes
(docs/python-versions.md, "triton and Mesa's LLVM in one process")."""
from __future__ import annotations

import functools
import importlib.util
import os
import sys
import warnings

from unity_stub_env.render import RenderError

INSTALL_HINT = (
    "Headless Linux needs Mesa's EGL (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri; Fedora: "
    "dnf install mesa-libEGL mesa-dri-drivers) with MUJOCO_GL=egl, or OSMesa (apt-get install libosmesa6) "
    "with MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa; with a display, MUJOCO_GL=glfw.")


def headless_default() -> None:
    if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ \
            and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def open_renderer(model, width: int, height: int):
    """A ``mujoco.Renderer`` of ``width`` x ``height`` for ``model``; RenderError naming MUJOCO_GL
    and the packages to install when no OpenGL context can be made."""
    import mujoco

    load_triton_first()
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    try:
        with warnings.catch_warnings():  # GLFW warns before it fails: the one message below says it all
            warnings.simplefilter("ignore")
            return mujoco.Renderer(model, height, width)
    except Exception as error:  # FatalError, ImportError, AttributeError: each backend fails its own way
        backend = os.environ.get("MUJOCO_GL", "(unset: GLFW)")
        if backend != _backend_at_import():
            backend += (f", but mujoco was imported before it was set and uses "
                        f"{_backend_at_import() or '(unset: GLFW)'}: set MUJOCO_GL before importing mujoco")
        raise RenderError(f"MuJoCo cannot render: no usable OpenGL with MUJOCO_GL={backend} "
                          f"({type(error).__name__}: {str(error).strip().splitlines()[-1] if str(error).strip() else ''}). "
                          f"{INSTALL_HINT}") from None


@functools.cache  # once per process: a library stays loaded
def load_triton_first() -> str | None:
    """Loads triton's compiled library, if triton is installed and its library not yet loaded, and
    returns its path; call it before the process's first OpenGL context.

    Why (docs/python-versions.md, "triton and Mesa's LLVM in one process"): making a context loads
    Mesa's driver, which brings Debian's libLLVM into the process's global symbol scope; triton's
    library carries its own LLVM with exported symbols, and loaded after that it binds thousands of
    them to Mesa's LLVM instead and crashes in its initialisers (a segmentation fault at ``import
    triton``, which torch.optim's first optimizer and torch.compile do). Loaded first, with every
    symbol bound at once (RTLD_NOW) and kept out of the global scope (RTLD_LOCAL, as Python loads
    extensions), it keeps its own and Mesa's driver never sees it. Only the shared library is
    loaded: no triton module is imported, and ``import triton`` later finds it already mapped."""
    spec = importlib.util.find_spec("triton") if "triton" not in sys.modules else None
    if spec is None or not spec.submodule_search_locations:
        return None  # not installed (PyTorch's CPU builds), or already imported: nothing to order
    import ctypes

    for folder in spec.submodule_search_locations:
        library = os.path.join(folder, "_C", "libtriton.so")
        if os.path.exists(library):
            try:
                ctypes.CDLL(library, mode=os.RTLD_NOW | os.RTLD_LOCAL)
            except OSError:
                return None  # a broken triton fails its own import later, with its own message
            return library
    return None


def _backend_at_import() -> str:
    """The MUJOCO_GL value MuJoCo chose its backend by (it reads it once, at import)."""
    try:
        from mujoco.rendering.classic import gl_context
    except ImportError:
        return os.environ.get("MUJOCO_GL", "")
    return getattr(gl_context, "_MUJOCO_GL", os.environ.get("MUJOCO_GL", ""))
