"""MA-POCA end to end on the pushblock stub: the reference's POCA TensorBoard tags, the actor's
ONNX (onnxruntime), --resume, --initialize-from, --inference, and curiosity + rnd beside it."""
from __future__ import annotations

import json
import signal
import sys

import numpy as np
import onnxruntime as ort

from tests.integration.conftest import ROOT, free_port_block, learn, run_with_signals
from tests.integration.test_sac_run import tb_scalars

POCA_TAGS = ("Environment/Group Cumulative Reward", "Environment/Cumulative Reward", "Environment/Episode Length",
             "Losses/Baseline Loss", "Losses/Value Loss", "Losses/Policy Loss", "Policy/Entropy",
             "Policy/Extrinsic Baseline Estimate", "Policy/Extrinsic Value Estimate", "Policy/Extrinsic Reward",
             "Policy/Learning Rate", "Policy/Beta", "Policy/Epsilon")


def poca_config(tmp_path, name: str, max_steps: int, extra_signals: str = "") -> str:
    text = (ROOT / "configs" / "pushblock_poca.yaml").read_text()
    text = (text.replace("max_steps: 60000", f"max_steps: {max_steps}")
                .replace("checkpoint_interval: 20000", "checkpoint_interval: 1000")
                .replace("summary_freq: 4000", "summary_freq: 500")
                .replace("buffer_size: 1024", "buffer_size: 256").replace("batch_size: 128", "batch_size: 64")
                .replace("hidden_units: 64", "hidden_units: 16"))
    if extra_signals:
        text = text.replace("        strength: 1.0\n", "        strength: 1.0\n" + extra_signals, 1)
    assert f"max_steps: {max_steps}" in text and "summary_freq: 500" in text
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_poca_trains_exports_resumes_and_initializes(tmp_path, env_no_proxy):
    res = str(tmp_path / "results")
    common = ["--env", "stub:pushblock", "--num-areas", "4", "--seed", "2", "--results-dir", res,
              "--base-port", str(free_port_block())]
    r = learn([poca_config(tmp_path, "a.yaml", 1500), *common, "--run-id", "p"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/p/PushBlock")
    for tag in POCA_TAGS:
        assert tag in tags, tag
    # a group's return: -0.5 when it never moves the block, at most ~1.9 (both pushing from the start)
    assert all(-1.0 < value < 2.0 for _, value in tags["Environment/Group Cumulative Reward"])
    session = ort.InferenceSession(str(tmp_path / "results/p/PushBlock.onnx"))
    out = session.run(["deterministic_discrete_actions", "discrete_actions"],
                      {"obs_0": np.zeros((3, 11), np.float32), "action_masks": np.ones((3, 5), np.float32)})
    assert out[0].shape == (3, 1) and out[1].shape == (3, 1) and ((0 <= out[0]) & (out[0] < 5)).all()

    r2 = learn([poca_config(tmp_path, "b.yaml", 2500), *common, "--run-id", "p", "--resume"], cwd=tmp_path,
               env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    status = json.loads((tmp_path / "results/p/run_logs/training_status.json").read_text())
    assert status["PushBlock"]["final_checkpoint"]["steps"] >= 2500
    steps = [s for s, _ in tb_scalars(tmp_path / "results/p/PushBlock")["Policy/Extrinsic Baseline Estimate"]]
    assert len(steps) == len(set(steps)) and max(steps) >= 2500  # resumed: every summary written once

    r3 = learn([poca_config(tmp_path, "c.yaml", 600), *common, "--run-id", "q", "--initialize-from", "p"],
               cwd=tmp_path, env=env_no_proxy)
    assert r3.returncode == 0, r3.stderr[-3000:]
    assert "at step 0" in r3.stdout + r3.stderr
    status = json.loads((tmp_path / "results/q/run_logs/training_status.json").read_text())
    assert 600 <= status["PushBlock"]["final_checkpoint"]["steps"] < 2500

    status_file = tmp_path / "results/p/run_logs/training_status.json"
    before = json.loads(status_file.read_text())["PushBlock"]
    cmd = [sys.executable, "-m", "trainer.cli", poca_config(tmp_path, "b.yaml", 2500), *common, "--run-id", "p",
           "--inference"]
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy, [(("Loaded", "checkpoint.pt"), signal.SIGTERM)])
    assert code == 0, text
    assert json.loads(status_file.read_text())["PushBlock"] == before
    assert f"at step {before['final_checkpoint']['steps']}" in text


def test_poca_trains_with_curiosity_and_rnd(tmp_path, env_no_proxy):
    """ML-Agents 1.1.0 cannot (its issue #6038); here both intrinsic signals train beside POCA's critic."""
    signals = ("      curiosity:\n        gamma: 0.99\n        strength: 0.02\n"
               "      rnd:\n        gamma: 0.99\n        strength: 0.01\n")
    r = learn([poca_config(tmp_path, "cr.yaml", 1000, signals), "--env", "stub:pushblock", "--num-areas", "4",
               "--seed", "3", "--run-id", "c", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/c/PushBlock")
    for tag in ("Losses/Curiosity Forward Loss", "Losses/Curiosity Inverse Loss", "Losses/RND Loss",
                "Policy/Curiosity Reward", "Policy/Rnd Reward", "Policy/Curiosity Baseline Estimate",
                "Policy/Rnd Value Estimate", "Losses/Baseline Loss"):
        assert tag in tags, tag
    # curiosity pays nothing before its first update (as the reference), then a positive reward
    assert tags["Policy/Curiosity Reward"][-1][1] > 0 and all(v > 0 for _, v in tags["Policy/Rnd Reward"])
