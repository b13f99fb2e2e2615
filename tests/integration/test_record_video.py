"""mlagents-like-learn --record-video: checkpoints' ONNX filmed in the background (as the CPU budget
allows, the final one always) to <Behavior>-<step>.mp4 beside it and into TensorBoard as an animated
image, read back with TensorBoard's own loader (EventAccumulator) and decoded; the clips play the
run's environment parameters."""
from __future__ import annotations

import io
import textwrap

import pytest

from tests.integration.conftest import free_port_block, learn

CONFIG = """
behaviors:
  3DBall:
    trainer_type: ppo
    hyperparameters: {batch_size: 64, buffer_size: 1200, learning_rate: 3.0e-4, beta: 1.0e-3,
                      epsilon: 0.2, lambd: 0.99, num_epoch: 1}
    network_settings: {normalize: true, hidden_units: 32, num_layers: 1}
    reward_signals: {extrinsic: {gamma: 0.99, strength: 1.0}}
    checkpoint_interval: 1200
    max_steps: 2400
    time_horizon: 100
    summary_freq: 1200
environment_parameters:
  clip_check: {sampler_type: uniform, sampler_parameters: {min_value: 1.0, max_value: 2.0}}
"""


def test_record_video_films_checkpoints_into_tensorboard(tmp_path):
    av = pytest.importorskip("av")
    from PIL import Image
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    config = tmp_path / "ball3d.yaml"
    config.write_text(textwrap.dedent(CONFIG))
    r = learn([str(config), "--env", "stub:ball3d", "--seed", "1", "--run-id", "v", "--record-video",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    brain = tmp_path / "results" / "v" / "3DBall"
    clips = sorted(brain.glob("3DBall-*.mp4"))
    log = (tmp_path / "results" / "v" / "run_logs" / "clips.log").read_text()
    assert clips, (sorted(p.name for p in brain.iterdir()), log[-2000:])
    steps = sorted(int(p.stem.split("-")[1]) for p in clips)
    onnx_steps = {int(p.stem.split("-")[1]) for p in brain.glob("3DBall-*.onnx")}
    assert set(steps) <= onnx_steps and steps[-1] == max(onnx_steps)  # the final model's clip: always made
    # the clips play the run's environment parameters, as its simulators got them
    assert log.count("environment parameters: clip_check~uniform(1.0, 2.0)") == len(clips), log[-2000:]
    assert not list((brain / "clips").glob("*.onnx"))  # the models' copies are gone
    with av.open(str(clips[-1])) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 200 and frames[0].shape == (240, 320, 3)  # 10 s at 20 fps
    accumulator = EventAccumulator(str(brain / "clips"), size_guidance={"images": 0})
    accumulator.Reload()
    assert "3DBall/clip" in accumulator.Tags()["images"]
    images = accumulator.Images("3DBall/clip")
    assert sorted(e.step for e in images) == steps
    gif = Image.open(io.BytesIO(images[-1].encoded_image_string))
    assert gif.format == "GIF" and gif.n_frames == 100 and gif.size == (160, 120)
    assert (images[-1].width, images[-1].height) == (160, 120)
