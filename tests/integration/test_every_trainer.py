"""What every trainer_type must do end to end (real gRPC, the basic stub as a process): a short
training, its ONNX (checked with onnxruntime against the torch actor loaded from the checkpoint),
``--resume`` from the saved step, ``--initialize-from`` starting from the saved weights with the
step count at 0, and ``--inference`` acting without updating anything.

A trainer type becomes trainable by joining trainer.config.settings.TRAINABLE_TRAINER_TYPES; it
must then get a config in ``CONFIGS`` below (``test_every_trainable_type_is_covered`` fails until
it has one), and these tests run for it.
"""
from __future__ import annotations

import hashlib
import json
import re
import signal
import sys
import textwrap

import numpy as np
import onnxruntime as ort
import pytest
import torch

from protos.types import BehaviorSpec
from tests.integration.conftest import free_port_block, learn, run_with_signals
from trainer.artifacts.checkpoints import load_checkpoint
from trainer.behavior import make_trainer
from trainer.config.loader import load_run_options
from trainer.config.settings import TRAINABLE_TRAINER_TYPES
from unity_stub_env.tasks.basic import BasicTask

# per trainer: the hyperparameters block; {frozen} makes a run that never updates (PPO's buffer
# and SAC's buffer_init_steps beyond max_steps), so its final weights are the ones it started from
CONFIGS = {
    "ppo": "hyperparameters: {{batch_size: 32, buffer_size: {frozen}, num_epoch: 3}}",
    "sac": ("hyperparameters: {{batch_size: 32, buffer_size: 5000, buffer_init_steps: {frozen_sac}, "
            "steps_per_update: 10.0, init_entcoef: 0.01, save_replay_buffer: true}}"),
    # basic sends no group ids: every agent is a group of one (the critic attends over itself)
    "poca": "hyperparameters: {{batch_size: 32, buffer_size: {frozen}, num_epoch: 3}}",
}

TEMPLATE = """
behaviors:
  Basic:
    trainer_type: {trainer}
    {hyperparameters}
    network_settings: {{normalize: false, hidden_units: 16, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    keep_checkpoints: 5
    checkpoint_interval: 300
    max_steps: {max_steps}
    time_horizon: 8
    summary_freq: 300
"""


def config(tmp_path, trainer: str, name: str, max_steps: int, frozen: bool = False) -> str:
    hyper = CONFIGS[trainer].format(frozen=100_000 if frozen else 256, frozen_sac=100_000 if frozen else 0)
    path = tmp_path / name
    path.write_text(textwrap.dedent(TEMPLATE.format(trainer=trainer, hyperparameters=hyper, max_steps=max_steps)))
    return str(path)


def test_every_trainable_type_is_covered():
    assert set(TRAINABLE_TRAINER_TYPES) <= set(CONFIGS), "add a CONFIGS entry for the new trainer_type"


def saved_files(folder) -> dict[str, str]:
    """sha256 of every checkpoint, ONNX and replay-buffer file of a behavior folder."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()
            if p.suffix in (".pt", ".onnx", ".npz")}


@pytest.mark.parametrize("trainer", TRAINABLE_TRAINER_TYPES)
def test_train_export_resume_initialize_and_infer(trainer, tmp_path, env_no_proxy):
    results = tmp_path / "results"
    common = ["--env", "stub:basic", "--seed", "3", "--results-dir", str(results),
              "--base-port", str(free_port_block())]
    first_cfg = config(tmp_path, trainer, "a.yaml", 600)
    r = learn([first_cfg, *common, "--run-id", "a"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    status_file = results / "a/run_logs/training_status.json"
    first_step = json.loads(status_file.read_text())["Basic"]["final_checkpoint"]["steps"]
    assert first_step >= 600

    # ONNX: the exported actor decides as the torch actor of the saved checkpoint
    settings = load_run_options(first_cfg).behaviors["Basic"]
    spec = BehaviorSpec(BasicTask.observation_specs, BasicTask.action_spec)
    reloaded = make_trainer("Basic", spec, settings, seed=99, device="cpu", use_numpy_update=True)
    reloaded.load_state_dict(load_checkpoint(results / "a/Basic/checkpoint.pt"))
    assert reloaded.step == first_step
    obs = np.concatenate([np.eye(20, dtype=np.float32),
                          np.random.default_rng(0).uniform(size=(12, 20)).astype(np.float32)])
    masks = np.zeros((len(obs), 3), bool)
    masks[0, 1] = True  # as the stub masks at the corridor's ends
    session = ort.InferenceSession(str(results / "a/Basic.onnx"))
    names = [o.name for o in session.get_outputs()]
    out = dict(zip(names, session.run(None, {"obs_0": obs, "action_masks": (~masks).astype(np.float32)})))
    expected = reloaded.policy.act([obs], masks, deterministic=True)
    np.testing.assert_array_equal(out["deterministic_discrete_actions"], expected.discrete)
    assert out["discrete_actions"][0, 0] != 1 and out["version_number"].tolist() == [3.0]

    # --resume: continues at the saved step
    r = learn([config(tmp_path, trainer, "b.yaml", 900), *common, "--run-id", "a", "--resume"],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"for behavior Basic at step {first_step}" in r.stdout + r.stderr
    resumed = json.loads(status_file.read_text())["Basic"]
    assert resumed["final_checkpoint"]["steps"] >= 900
    trained = load_checkpoint(results / "a/Basic/checkpoint.pt")

    # --initialize-from: step 0, the saved weights (a run that never updates ends with them)
    r = learn([config(tmp_path, trainer, "c.yaml", 300, frozen=True), *common, "--run-id", "c",
               "--initialize-from", "a"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "for behavior Basic at step 0" in r.stdout + r.stderr
    started = load_checkpoint(results / "c/Basic/checkpoint.pt")
    assert 300 <= int(started["global_step"]["step"]) < 600
    for key, value in trained["Policy"].items():
        assert torch.equal(started["Policy"][key], value), key
    fresh_cfg = config(tmp_path, trainer, "d.yaml", 300, frozen=True)  # the same run without it differs
    r = learn([fresh_cfg, *common, "--run-id", "d"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    fresh = load_checkpoint(results / "d/Basic/checkpoint.pt")
    assert any(not torch.equal(fresh["Policy"][k], v) for k, v in trained["Policy"].items())

    # --inference: the saved policy plays whole episodes and its steps count on from the saved
    # step, with the environment summaries at summary_freq (as mlagents-learn --inference), past
    # max_steps (900) too; no checkpoint, ONNX or training status is written
    before = saved_files(results / "a/Basic")
    status_before = status_file.read_text()
    saved_step = resumed["final_checkpoint"]["steps"]
    cmd = [sys.executable, "-m", "trainer.cli", config(tmp_path, trainer, "b.yaml", 900), *common,
           "--run-id", "a", "--inference"]
    second = (saved_step // 300 + 2) * 300  # the second summary label of the inference run, > max_steps
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy,
                                  [((f"Basic. Step: {second}.", "Not Training."), signal.SIGTERM)], timeout=120)
    assert code == 0, text[-3000:]
    assert f"at step {saved_step}" in text
    assert re.search(r"Basic: step [\d,]+ ·", text) and "/900 (" not in text  # the progress line has no end
    assert saved_files(results / "a/Basic") == before
    assert status_file.read_text() == status_before
    rewards = scalars(results / "a/Basic", "Environment/Cumulative Reward")
    lengths = scalars(results / "a/Basic", "Environment/Episode Length")
    inferred = [e.step for e in rewards if e.step > saved_step]
    assert inferred[:2] == [second - 300, second], inferred
    assert {e.step for e in lengths} >= {second - 300, second}
    # basic pays -0.01 a step and +0.1 / +1 at the ends: a finished episode's return is at most 1
    assert all(-1.0 <= e.value <= 1.0 for e in rewards if e.step > saved_step)
    assert not any(e.step > saved_step for e in scalars(results / "a/Basic", "Losses/Policy Loss", missing_ok=True))


def scalars(folder, tag: str, missing_ok: bool = False) -> list:
    """The TensorBoard scalars of ``tag`` in a run folder, all event files read back."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    if missing_ok and tag not in acc.Tags()["scalars"]:
        return []
    return sorted(acc.Scalars(tag), key=lambda e: e.step)
