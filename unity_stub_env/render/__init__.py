"""Pictures of the stub tasks: ``unity-stub-env --task T --play POLICY --video FILE`` (``play``).

MuJoCo tasks are drawn with MuJoCo's offscreen renderer (``scene``: a camera that frames and
follows one agent, the cues a viewer needs drawn into the scene); runner, which has no MuJoCo
model, is drawn top-down (``runner_view``). ``video`` writes the frames as H.264 .mp4 or .gif
with a caption. Nothing here is imported while training: only the CLI's ``--play`` and
``--evaluate --video`` and the trainer's ``--record-video`` subprocess load it."""
from __future__ import annotations


class RenderError(RuntimeError):
    """Rendering cannot start (no OpenGL, bad policy or output): the message says what to do."""
