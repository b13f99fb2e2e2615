"""MA-POCA end to end on the pushblock stub: the reference's POCA TensorBoard tags, the actor's
ONNX (onnxruntime), --resume, --initialize-from, --inference, curiosity + rnd beside it, and all
of that again with network_settings.memory (a recurrent actor and critic)."""
from __future__ import annotations

import json
import signal
import sys

import numpy as np
import onnxruntime as ort
import torch

from protos.types import BehaviorSpec
from tests.integration.conftest import ROOT, free_port_block, learn, run_with_signals
from tests.integration.test_sac_run import tb_scalars
from trainer.artifacts.checkpoints import load_checkpoint
from trainer.behavior import make_trainer
from trainer.config.loader import load_run_options

POCA_TAGS = ("Environment/Group Cumulative Reward", "Environment/Cumulative Reward", "Environment/Episode Length",
             "Losses/Baseline Loss", "Losses/Value Loss", "Losses/Policy Loss", "Policy/Entropy",
             "Policy/Extrinsic Baseline Estimate", "Policy/Extrinsic Value Estimate", "Policy/Extrinsic Reward",
             "Policy/Learning Rate", "Policy/Beta", "Policy/Epsilon")


def poca_config(tmp_path, name: str, max_steps: int, extra_signals: str = "", memory: bool = False,
                buffer_size: int = 256) -> str:
    text = (ROOT / "configs" / "pushblock_poca.yaml").read_text()
    text = (text.replace("max_steps: 60000", f"max_steps: {max_steps}")
                .replace("checkpoint_interval: 20000", "checkpoint_interval: 1000")
                .replace("summary_freq: 4000", "summary_freq: 500")
                .replace("buffer_size: 1024", f"buffer_size: {buffer_size}").replace("batch_size: 128", "batch_size: 64")
                .replace("hidden_units: 64", "hidden_units: 16"))
    if extra_signals:
        text = text.replace("        strength: 1.0\n", "        strength: 1.0\n" + extra_signals, 1)
    if memory:
        text = text.replace("      num_layers: 2\n", "      num_layers: 2\n      memory: {memory_size: 16, sequence_length: 8}\n")
        assert "memory_size: 16" in text
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


def test_poca_with_memory_trains_exports_resumes_initializes_and_infers(tmp_path, env_no_proxy):
    res = tmp_path / "results"
    common = ["--env", "stub:pushblock", "--num-areas", "4", "--seed", "4", "--results-dir", str(res),
              "--base-port", str(free_port_block())]
    first_cfg = poca_config(tmp_path, "m.yaml", 1000, memory=True)
    r = learn([first_cfg, *common, "--run-id", "m"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(res / "m/PushBlock")
    assert {"Losses/Baseline Loss", "Losses/Value Loss", "Environment/Group Cumulative Reward"} <= set(tags)
    saved = load_checkpoint(res / "m/PushBlock/checkpoint.pt")
    assert "lstm.lstm.weight_hh_l0" in saved["Optimizer:critic"]  # the critic's own LSTM
    assert "network_body.lstm.lstm.weight_hh_l0" in saved["Policy"]

    # ONNX: recurrent_in / recurrent_out, the same actions and memories as the torch actor of the checkpoint
    settings = load_run_options(first_cfg).behaviors["PushBlock"]
    from unity_stub_env.tasks.pushblock import PushBlockTask
    spec = BehaviorSpec(PushBlockTask.observation_specs, PushBlockTask.action_spec)
    reloaded = make_trainer("PushBlock", spec, settings, seed=99, device="cpu", use_numpy_update=False)
    reloaded.load_state_dict(saved)
    session = ort.InferenceSession(str(res / "m/PushBlock.onnx"))
    assert [i.name for i in session.get_inputs()] == ["obs_0", "action_masks", "recurrent_in"]
    rng = np.random.default_rng(0)
    obs, memory = rng.normal(size=(6, 11)).astype(np.float32), np.zeros((6, 16), np.float32)
    names = [o.name for o in session.get_outputs()]
    for _ in range(3):  # memories fed back, as Unity's inference engine does
        out = dict(zip(names, session.run(None, {"obs_0": obs, "action_masks": np.ones((6, 5), np.float32),
                                                 "recurrent_in": memory[:, None, :]})))
        expected = reloaded.policy.act([obs], None, deterministic=True, memories=memory)
        np.testing.assert_array_equal(out["deterministic_discrete_actions"], expected.discrete)
        np.testing.assert_allclose(out["recurrent_out"][:, 0, :], expected.memories, atol=1e-5)
        memory = expected.memories
    assert np.abs(memory).sum() > 0

    # --resume: the weights and optimizer moments it continues from are the checkpoint's
    r = learn([poca_config(tmp_path, "m2.yaml", 1500, memory=True), *common, "--run-id", "m", "--resume"],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    first_step = int(saved["global_step"]["step"])
    assert f"for behavior PushBlock at step {first_step}" in r.stdout + r.stderr
    status_file = res / "m/run_logs/training_status.json"
    resumed = json.loads(status_file.read_text())["PushBlock"]
    assert resumed["final_checkpoint"]["steps"] >= 1500
    steps = [s for s, _ in tb_scalars(res / "m/PushBlock")["Policy/Extrinsic Baseline Estimate"]]
    assert len(steps) == len(set(steps)) and max(steps) >= 1500

    # --initialize-from: the trained weights at step 0 (a run that never updates ends with them)
    trained = load_checkpoint(res / "m/PushBlock/checkpoint.pt")
    r = learn([poca_config(tmp_path, "m3.yaml", 300, memory=True, buffer_size=100_000), *common, "--run-id", "n",
               "--initialize-from", "m"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "for behavior PushBlock at step 0" in r.stdout + r.stderr
    started = load_checkpoint(res / "n/PushBlock/checkpoint.pt")
    for part in ("Policy", "Optimizer:critic"):
        for key, value in trained[part].items():
            assert torch.equal(started[part][key], value), (part, key)

    # --inference: the recurrent policy plays on, summaries at summary_freq, no file of the run changes
    before = {p.name: p.read_bytes() for p in (res / "m/PushBlock").iterdir() if p.suffix in (".pt", ".onnx")}
    status_before = status_file.read_text()
    cmd = [sys.executable, "-m", "trainer.cli", poca_config(tmp_path, "m2.yaml", 1500, memory=True), *common,
           "--run-id", "m", "--inference"]
    # stopped at its second summary: summaries come every 500 steps (~62 decisions of the 8 agents) and
    # an episode ends by pushblock's 80-decision timeout at the latest, so the first summary has
    # completed episodes only if some group brought its block home early (after 1,500 steps of
    # training, a matter of the seed's luck: "No episode was completed since last summary"); the
    # second always has them. Signal 0 only marks the first summary.
    summary = ("PushBlock. Step:", "Not Training.")
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy, [(summary, 0), (summary, signal.SIGTERM)], timeout=120)
    assert code == 0, text[-3000:]
    assert {p.name: p.read_bytes() for p in (res / "m/PushBlock").iterdir() if p.suffix in (".pt", ".onnx")} == before
    assert status_file.read_text() == status_before
    inferred = [s for s, _ in tb_scalars(res / "m/PushBlock")["Environment/Episode Length"]
                if s > resumed["final_checkpoint"]["steps"]]
    assert inferred
