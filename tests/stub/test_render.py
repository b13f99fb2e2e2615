"""unity-stub-env --play: pictures checked by their pixels, videos by decoding them (PyAV), and the
clear errors (exit 2) for no OpenGL, an unknown policy and an unwritable output."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from unity_stub_env.render.play import Player, make_policy
from unity_stub_env.render.scene import SPHERE
from unity_stub_env.tasks import make_task

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
W, H = 160, 120
FILMED = ("ball3d", "dodge", "mimic", "creature", "pushblock", "dungeon", "soccer", "soccer_twos", "runner")


def player(task_name: str, policy: str = "zero", agent: int = 0, seed: int = 0, width: int = W, height: int = H):
    task = make_task(task_name, num_areas=1, seed=seed)
    return Player(task, make_policy(policy, task, seed), agent, width, height, task_name, samples=0)


def segmentation(view) -> np.ndarray:
    """int [H, W]: the model geom id drawn at each pixel, seen by the view's camera (-1: none). The
    scene is made again without the cues: translucent geoms blend segment colours into ids that
    do not exist."""
    renderer = view.renderer
    renderer.update_scene(view.task.data, view.camera)
    renderer.enable_segmentation_rendering()
    try:
        seg = renderer.render()
    finally:
        renderer.disable_segmentation_rendering()
    ids, types = seg[..., 0], seg[..., 1]
    return np.where(types == 5, ids, -1)  # mjOBJ_GEOM


@pytest.mark.parametrize("task_name", FILMED)
def test_a_frame_shows_a_scene(task_name):
    p = player(task_name, "random")
    for _ in range(3):
        p.step()
    frame = p.view.frame()
    p.close()
    assert frame.shape == (H, W, 3) and frame.dtype == np.uint8
    colours = np.unique(frame.reshape(-1, 3) // 16, axis=0)
    assert len(colours) >= 5, f"{task_name}: {len(colours)} colour classes in the frame"
    assert frame.std() > 10


def test_dodge_crouch_changes_the_picture_where_the_body_is():
    """Zero actions vs a full crouch (action 0 = +1) for 20 steps from the same seed: the pixels that
    differ are on character geoms in one of the two pictures, and there are many of them."""
    frames, segs = [], []
    for crouch in (0.0, 1.0):
        task = make_task("dodge", num_areas=1, seed=3)
        action = np.zeros((task.num_agents, 9), np.float32)
        action[:, 0] = crouch
        p = Player(task, lambda obs, mask, a=action: (a, np.zeros((len(a), 0), np.int32)), 0, 320, 240, "dodge",
                   samples=0)
        for _ in range(20):
            p.step()
        frames.append(p.view.frame().astype(int))
        segs.append(segmentation(p.view))
        p.close()
    character = task.geom_agent >= 0
    on_body = [(s >= 0) & character[np.maximum(s, 0)] for s in segs]
    differ = np.abs(frames[0] - frames[1]).sum(axis=2) > 30
    assert differ.sum() > 200, differ.sum()
    inside = differ & (on_body[0] | on_body[1])
    assert inside.sum() / differ.sum() > 0.95, (inside.sum(), differ.sum())


def test_dodge_sphere_is_drawn_in_its_colour_and_moves_before_contact():
    p = player("dodge", "zero", seed=1, width=320, height=240)
    task, ball = p.task, p.task.ball_geom[0]
    centres = []
    for _ in range(4):
        frame = p.view.frame()
        seg = segmentation(p.view)
        pixels = frame[seg == ball].astype(float)
        assert len(pixels) >= 4, "the followed agent's sphere is not in the picture"
        r, g, b = pixels.mean(axis=0)
        assert r > 120 and r > 1.6 * g and r > 3 * b, (r, g, b, SPHERE)
        assert task.last_hit_region[0] == -1  # no contact yet
        centres.append(np.argwhere(seg == ball).mean(axis=0))
        for _ in range(3):
            p.step()
    p.close()
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert (steps > 1.0).all(), steps


def test_mimic_ghost_is_drawn_translucent_blue_over_the_character(monkeypatch):
    """With and without the ghost cue, same state: the pixels that change turn bluer, and they lie
    on or right beside the ragdoll (its reference pose starts where it stands)."""
    from unity_stub_env.render import scene

    p = player("mimic", "random", width=320, height=240)
    for _ in range(10):
        p.step()
    for _ in range(40):  # let the following camera settle: both pictures from one viewpoint
        p.view.frame()
    with_ghost = p.view.frame().astype(int)
    monkeypatch.setitem(scene.CUES, "mimic", lambda *args: None)
    without = p.view.frame().astype(int)
    seg = segmentation(p.view)
    p.close()
    differ = np.abs(with_ghost - without).sum(axis=2) > 30
    assert differ.sum() > 300, differ.sum()
    blue_shift = (with_ghost[differ, 2] - with_ghost[differ, 0]) - (without[differ, 2] - without[differ, 0])
    assert np.median(blue_shift) > 20
    ragdoll = seg >= 0
    ragdoll &= p.task.geom_agent[np.maximum(seg, 0)] == 0
    rows, cols = np.nonzero(ragdoll)
    box = differ[rows.min() - 20: rows.max() + 20, cols.min() - 20: cols.max() + 20]
    assert box.sum() / differ.sum() > 0.9


def _cli(*args, env=None, timeout=240):
    return subprocess.run([sys.executable, "-m", "unity_stub_env.cli", *args], capture_output=True, text=True,
                          cwd=REPO, env=env, timeout=timeout)


def test_video_decodes_to_the_expected_frames(tmp_path):
    av = pytest.importorskip("av")
    out = tmp_path / "ball3d.mp4"
    run = _cli("--task", "ball3d", "--play", "scripted", "--video", str(out), "--seconds", "1.5", "--fps", "12",
               "--width", "320", "--height", "240")
    assert run.returncode == 0, run.stderr
    with av.open(str(out)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 18
    assert frames[0].shape == (240, 320, 3)
    assert frames[-1].std() > 10
    gif = tmp_path / "runner.gif"
    run = _cli("--task", "runner", "--play", "zero", "--video", str(gif), "--seconds", "1", "--fps", "5",
               "--width", "160", "--height", "120")
    assert run.returncode == 0, run.stderr
    from PIL import Image

    with Image.open(gif) as image:
        assert image.n_frames == 5 and image.size == (160, 120)


def test_no_opengl_is_one_clear_message(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(MUJOCO_GL="glfw", PYTHONPATH=REPO)  # GLFW without a display: no context can be made
    run = _cli("--task", "dodge", "--play", "zero", "--video", str(tmp_path / "x.mp4"), "--seconds", "0.2", env=env)
    assert run.returncode == 2
    assert "MUJOCO_GL" in run.stderr and "apt-get install libegl1" in run.stderr
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.mp4").exists()


@pytest.mark.parametrize("args, words", [
    (("--play", "walk", "--video", "{tmp}/x.mp4"), "unknown policy"),
    (("--play", "scripted", "--video", "{tmp}/x.mp4"), "no scripted expert"),
    (("--play", "zero", "--video", "/proc/clip.mp4"), "cannot write there"),
    (("--play", "zero", "--video", "{tmp}/missing/clip.mp4"), "does not exist"),
    (("--play", "zero", "--video", "{tmp}/clip.avi"), ".mp4 (H.264) or .gif"),
])
def test_bad_input_exits_2(tmp_path, args, words):
    run = _cli("--task", "dodge", *[a.format(tmp=tmp_path) for a in args], "--seconds", "0.1")
    assert run.returncode == 2, run.stdout
    assert words in run.stderr and "Traceback" not in run.stderr


def test_an_mp4_whose_ffmpeg_fails_is_an_error_with_its_reason_and_leaves_no_clip(tmp_path):
    """ffmpeg writing to a full disk (/dev/full behind the partial file's name): a RenderError that
    carries ffmpeg's exit status and message, instead of a BrokenPipeError with no reason or a
    truncated clip published as complete; and no clip, partial or not, is left."""
    from unity_stub_env.render import RenderError
    from unity_stub_env.render.video import VideoWriter

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    writer = VideoWriter(str(tmp_path / "clip.mp4"), 30.0)
    os.symlink("/dev/full", writer.partial)
    frame = np.zeros((72, 96, 3), np.uint8)
    with pytest.raises(RenderError) as error:
        try:
            for _ in range(300):
                writer.append(frame)
        finally:
            writer.close()
    assert "clip.mp4" in str(error.value) and "No space left on device" in str(error.value)
    assert "exit status" in str(error.value)
    assert os.listdir(tmp_path) == []


def test_an_mp4_cut_short_by_a_killed_ffmpeg_is_an_error_not_a_clip(tmp_path):
    from unity_stub_env.render import RenderError
    from unity_stub_env.render.video import VideoWriter

    writer = VideoWriter(str(tmp_path / "clip.mp4"), 30.0)
    frame = np.zeros((72, 96, 3), np.uint8)
    writer.append(frame)
    writer.process.kill()
    writer.process.wait()
    with pytest.raises(RenderError, match="exit status -9 after"):
        for _ in range(300):  # a pipe's buffer takes a few frames before the write breaks
            writer.append(frame)
    writer.close()  # as a caller's finally does: nothing more to publish
    assert os.listdir(tmp_path) == []


def test_evaluate_video_films_each_scripted_dodge_throw(tmp_path):
    """One clip per scripted throw, named by number, start side and mark; each shows its throw
    from launch to the end of the episode (a hit or a pass within ~1.5 s)."""
    av = pytest.importorskip("av")
    from unity_stub_env.evaluate import load_policy
    from unity_stub_env.render.evaluate_clips import write
    from unity_stub_env.tasks.dodge import SCRIPTED_THROWS

    clips = write("dodge", {"zero": load_policy("zero", 17, 9, 0)}, 0, str(tmp_path / "clips"), {}, (96, 72), samples=0)
    names = [os.path.basename(c) for c in clips]
    assert len(names) == 17 == len(SCRIPTED_THROWS)
    assert names[0] == "dodge-zero-01-front-left_shoulder.mp4" and names[7] == "dodge-zero-08-right-head.mp4"
    assert sorted(os.listdir(tmp_path / "clips")) == sorted(names)
    with av.open(clips[1]) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert 10 <= len(frames) <= 60 and frames[0].shape == (72, 96, 3)


@pytest.mark.may_skip_in_ci  # triton comes with PyPI's CUDA torch (Python 3.12/3.13 here), not the CPU wheel
def test_triton_imports_after_a_frame_is_rendered():
    """A frame first (Mesa's driver brings its LLVM into the process), then ``import triton``, as
    torch.optim's first optimizer does: without unity_stub_env.render.gl.load_triton_first the
    process died with SIGSEGV in triton's initialisers (docs/python-versions.md, "triton and Mesa's
    LLVM in one process"). In a fresh process: this worker may have loaded triton already."""
    import importlib.util

    if importlib.util.find_spec("triton") is None:
        pytest.skip("triton is not installed (it comes with PyPI's CUDA torch)")
    script = (
        "import numpy as np\n"
        "from unity_stub_env.gym.render import FrameRenderer\n"
        "from unity_stub_env.tasks import make_task\n"
        "frame = FrameRenderer(make_task('ball3d', num_areas=1, seed=0), 60, 80).frame()\n"
        "maps = open('/proc/self/maps').read()\n"
        "import triton, torch\n"
        "torch.optim.Adam([torch.zeros(2, requires_grad=True)])\n"  # imports torch._dynamo, which imports triton
        "print(int(frame.std() * 100), 'libLLVM' in maps, 'libtriton.so' in maps)\n")
    env = {**os.environ, "PYTHONPATH": REPO}
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, f"exit {run.returncode}: {run.stderr[-2000:]}"
    std, llvm, triton_loaded = run.stdout.split()
    assert int(std) > 1000 and triton_loaded == "True"  # a real picture, triton's library loaded before the frame
    print("Mesa's libLLVM in the process:", llvm)
