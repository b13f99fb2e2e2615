"""Our PPO against the real mlagents 1.1.0 PPO, number for number.

Our trainer processes four trajectories (done, interrupted, time-horizon cut) and takes one
minibatch step; the reference (its own venv and process) loads the same initial weights and the
same trajectories and does the same with its own code (normaliser updates, value estimates, GAE,
advantage normalisation, schedules, optimizer.update). Everything must agree to float precision,
including the reference's value-loss behaviour (see PPOTrainer._minibatch_loss).
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from protos.types import (
    ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType,
)
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer, normalize_advantages

PEER = Path(__file__).parent / "peer_scripts" / "ppo_reference_update.py"


def prepare_our_update() -> dict:
    """Our trainer: 4 trajectories processed, then one minibatch update; every number the reference needs."""
    spec = BehaviorSpec((ObservationSpec((8,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),), ActionSpec(2, ()))
    hp = PPOHyperparams(batch_size=64, buffer_size=200, learning_rate=3e-4, beta=5e-3, epsilon=0.2, lambd=0.95, num_epoch=1,
                        normalize=True, hidden_units=16, num_layers=2, max_steps=1_000_000, reward_signals={"extrinsic": (0.99, 1.0)})
    tr = PPOTrainer("B", spec, hp, seed=7)
    A = {"log_sigma": "action_model._continuous_distribution.log_sigma", "mu.weight": "action_model._continuous_distribution.mu.weight",
         "mu.bias": "action_model._continuous_distribution.mu.bias"}
    def ref_name(k, critic):
        k = k.replace("network_body.observation_encoder.encoders.0.", "network_body.observation_encoder.processors.0.")
        k = k.replace("network_body.hidden.", "network_body._body_endoder.seq_layers.")
        k = k.replace("value_heads.extrinsic", "value_heads.value_heads.extrinsic")
        return ("critic/" if critic else "actor/") + A.get(k, k)
    def dump(prefix):
        out = {}
        for critic, mod in ((False, tr.policy.actor), (True, tr.critic)):
            for k, v in mod.state_dict().items():
                if "vector" in k or k == "version_number": continue
                out[prefix + ref_name(k, critic)] = v.detach().numpy().copy()
        return out
    data = dump("init/")
    rng = np.random.default_rng(3)
    spec_traj = [(60, True, False), (45, True, True), (70, False, False), (30, True, False)]
    for i, (T, done, interrupted) in enumerate(spec_traj):
        obs = (rng.standard_normal((T, 8)) * 3 + 1).astype(np.float32)
        out = tr.policy.act([obs])
        nxt = (rng.standard_normal(8) * 3 + 1).astype(np.float32)
        rew = rng.standard_normal(T).astype(np.float32)
        traj = Trajectory([obs], [nxt], rew, out.continuous_raw, np.zeros((T, 0), np.int32), out.log_probs, None, done, interrupted)
        data[f"traj{i}/obs"], data[f"traj{i}/next"], data[f"traj{i}/rew"] = obs, nxt, rew
        data[f"traj{i}/act"], data[f"traj{i}/logp"] = out.continuous_raw, out.log_probs
        data[f"traj{i}/flags"] = np.array([done, interrupted])
        tr.process_trajectory(traj)
    buf = tr.buffer.concatenated()
    for k in ("values:extrinsic", "returns:extrinsic", "advantages"):
        data["buf/" + k] = buf[k]
    data.update(dump("processed/"))
    # one minibatch (first 64, no shuffle) with advantages normalised over the whole buffer
    lr, beta, eps = tr.current_schedule()
    data["sched"] = np.array([lr, beta, eps])
    buf["advantages"] = normalize_advantages(buf["advantages"])
    t = {k: torch.as_tensor(v[:64]) for k, v in buf.items()}
    t["allowed"] = (~t.pop("action_masks")).float()
    for g in tr.optimizer.param_groups: g["lr"] = lr
    loss, stats = tr._minibatch_loss(t, beta, eps)
    tr.optimizer.zero_grad(); loss.backward(); tr.optimizer.step()
    data["loss"] = np.array([loss.item(), stats["Losses/Policy Loss"], stats["Losses/Value Loss"]])
    data.update(dump("updated/"))
    return data


def test_one_update_matches_mlagents_1_1_0(tmp_path, interop_python):
    data = prepare_our_update()
    np.savez(tmp_path / "ours.npz", **data)
    done = subprocess.run([str(interop_python), str(PEER), str(tmp_path / "ours.npz")],
                          capture_output=True, text=True, timeout=180)
    lines = [l for l in done.stdout.splitlines() if l.startswith("{")]
    assert done.returncode == 0 and lines, done.stdout[-2000:] + done.stderr[-3000:]
    ref = json.loads(lines[-1])
    assert ref["processed_weights"] == 0.0  # identical normaliser updates
    assert ref["values"] < 1e-5 and ref["returns:extrinsic"] < 1e-5 and ref["advantages"] < 1e-5
    np.testing.assert_allclose(ref["schedule"], data["sched"], rtol=1e-6)
    assert ref["policy_loss"] == pytest.approx(data["loss"][1], rel=1e-5)
    assert ref["value_loss"] == pytest.approx(data["loss"][2], rel=1e-5)
    assert ref["updated_weights"] < 1e-6, ref  # every actor and critic weight after the step
