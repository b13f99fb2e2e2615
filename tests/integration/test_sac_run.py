"""SAC end to end on the basic stub: TensorBoard tags, ONNX, the replay buffer saved with the
checkpoints and continued by --resume, --initialize-from and --inference."""
from __future__ import annotations

import json
import signal
import sys

import numpy as np
import onnxruntime as ort
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import ROOT, free_port_block, learn, run_with_signals


def tb_scalars(folder) -> dict[str, list[tuple[int, float]]]:
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def sac_config(tmp_path, name: str, max_steps: int):
    text = (ROOT / "configs" / "basic_sac.yaml").read_text()
    text = (text.replace("max_steps: 20000", f"max_steps: {max_steps}")
                .replace("save_replay_buffer: false", "save_replay_buffer: true")
                .replace("checkpoint_interval: 10000", "checkpoint_interval: 400")
                .replace("summary_freq: 2000", "summary_freq: 200"))
    assert f"max_steps: {max_steps}" in text and "save_replay_buffer: true" in text
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_sac_trains_saves_its_replay_buffer_and_resumes_it(tmp_path, env_no_proxy):
    res = str(tmp_path / "results")
    port = free_port_block()
    common = ["--env", "stub:basic", "--seed", "2", "--results-dir", res, "--base-port", str(port)]
    r = learn([sac_config(tmp_path, "a.yaml", 600), *common, "--run-id", "s"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/s/Basic")
    for tag in ("Losses/Q1 Loss", "Losses/Q2 Loss", "Losses/Value Loss", "Losses/Policy Loss",
                "Policy/Discrete Entropy Coeff", "Policy/Extrinsic Value", "Policy/Learning Rate"):
        assert tag in tags, tag
    assert "Policy/Continuous Entropy Coeff" not in tags  # basic has one discrete branch only
    buffer_file = tmp_path / "results/s/Basic/last_replay_buffer.npz"
    with np.load(buffer_file, allow_pickle=False) as saved:
        first_size = int(saved["__size__"])
    assert first_size > 600  # every experience so far (the final checkpoint's step)
    session = ort.InferenceSession(str(tmp_path / "results/s/Basic.onnx"))
    out = session.run(["deterministic_discrete_actions"], {"obs_0": np.eye(20, dtype=np.float32)[:2],
                                                           "action_masks": np.ones((2, 3), np.float32)})
    assert out[0].shape == (2, 1)

    r2 = learn([sac_config(tmp_path, "b.yaml", 1200), *common, "--run-id", "s", "--resume"], cwd=tmp_path,
               env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    assert f"({first_size} experiences)" in r2.stdout + r2.stderr  # the saved buffer came back
    with np.load(buffer_file, allow_pickle=False) as saved:
        assert int(saved["__size__"]) > 1200  # ...and grew on
    status = json.loads((tmp_path / "results/s/run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] >= 1200

    # --initialize-from: the weights, a fresh step count and replay buffer
    r3 = learn([sac_config(tmp_path, "c.yaml", 300), *common, "--run-id", "t", "--initialize-from", "s"],
               cwd=tmp_path, env=env_no_proxy)
    assert r3.returncode == 0, r3.stderr[-3000:]
    assert "at step 0" in r3.stdout + r3.stderr and "experiences" not in r3.stdout + r3.stderr
    status = json.loads((tmp_path / "results/t/run_logs/training_status.json").read_text())
    assert 300 <= status["Basic"]["final_checkpoint"]["steps"] < 1200

    # --inference: the saved policy acts, nothing is written
    status_file = tmp_path / "results/s/run_logs/training_status.json"
    before = json.loads(status_file.read_text())["Basic"]
    cmd = [sys.executable, "-m", "trainer.cli", sac_config(tmp_path, "b.yaml", 1200), *common, "--run-id", "s",
           "--inference"]
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy, [(("Loaded", "checkpoint.pt"), signal.SIGTERM)])
    assert code == 0, text
    assert json.loads(status_file.read_text())["Basic"] == before
    assert f"at step {before['final_checkpoint']['steps']}" in text
