"""SAC end to end on the basic stub: TensorBoard tags, ONNX, the replay buffer saved with the
checkpoints and continued by --resume, --initialize-from and --inference."""
from __future__ import annotations

import json
import signal
import sys
from pathlib import Path

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
                "Policy/Discrete Entropy Coeff", "Policy/Entropy", "Policy/Extrinsic Value", "Policy/Learning Rate"):
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


def test_sac_with_memory_curiosity_and_rnd_trains_exports_and_resumes(tmp_path, env_no_proxy):
    """The features that were refused with SAC, end to end: an LSTM (recurrent ONNX), curiosity
    and RND (their TensorBoard tags as the reference), and a resume that brings them back."""
    text = Path(sac_config(tmp_path, "m.yaml", 600)).read_text()
    text = text.replace("      hidden_units: 20\n", "      hidden_units: 20\n      memory: {memory_size: 8, sequence_length: 4}\n")
    text = text.replace("        strength: 1.0\n", "        strength: 1.0\n"
                        "      curiosity: {gamma: 0.99, strength: 0.02, network_settings: {hidden_units: 16}}\n"
                        "      rnd: {gamma: 0.99, strength: 0.01, network_settings: {hidden_units: 8, num_layers: 1}}\n")
    assert "memory_size: 8" in text and "rnd:" in text
    cfg, cfg2 = tmp_path / "m.yaml", tmp_path / "m2.yaml"
    cfg.write_text(text)
    cfg2.write_text(text.replace("max_steps: 600", "max_steps: 1000"))
    common = ["--env", "stub:basic", "--seed", "5", "--run-id", "m", "--results-dir", str(tmp_path / "results"),
              "--base-port", str(free_port_block())]
    r = learn([str(cfg), *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/m/Basic")
    for tag in ("Losses/Curiosity Forward Loss", "Losses/Curiosity Inverse Loss", "Losses/RND Loss",
                "Policy/Curiosity Reward", "Policy/Rnd Reward", "Policy/Curiosity Value", "Policy/Rnd Value",
                "Losses/Q1 Loss"):
        assert tag in tags, tag
    assert all(v > 0 for _, v in tags["Policy/Rnd Reward"])  # prediction errors
    session = ort.InferenceSession(str(tmp_path / "results/m/Basic.onnx"))
    assert [i.name for i in session.get_inputs()] == ["obs_0", "action_masks", "recurrent_in"]
    out = session.run(["recurrent_out"], {"obs_0": np.eye(20, dtype=np.float32)[:2],
                                          "action_masks": np.ones((2, 3), np.float32),
                                          "recurrent_in": np.zeros((2, 1, 8), np.float32)})
    assert out[0].shape == (2, 1, 8) and np.abs(out[0]).sum() > 0
    r2 = learn([str(cfg2), *common, "--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    assert "starts untrained" not in r2.stdout + r2.stderr  # curiosity and RND came back
    status = json.loads((tmp_path / "results/m/run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] >= 1000
