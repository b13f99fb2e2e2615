"""Our SAC gradient step against the real mlagents 1.1.0 SAC optimizer, number for number.

Our trainer (its numpy step, the path every vector-observation run without memory takes) and the
reference's ``TorchSACOptimizer.update`` (its own venv and process) start from the same weights
and entropy coefficients and take the same ten minibatches; each step's policy sample uses the
same normal draws (the reference's first draw of torch's global generator, ours of the trainer's
noise generator, both seeded alike). Losses, entropy coefficients and every weight of policy,
V, target V, Q1 and Q2 must agree to float32 precision. Continuous actions (tanh-squashed) and
discrete branches with action masks; hybrid actions differ on purpose (docs/sac.md).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.trainer import SACTrainer

OBS, HIDDEN, STEPS, BATCH = 6, 16, 10, 48
LR, INIT_ENTCOEF, TAU, GAMMA = 3e-3, 0.3, 0.05, 0.9
PEER_NAMES = {"obs_0": "obs", "next_obs_0": "next_obs", "continuous_actions": "continuous",
              "discrete_actions": "discrete", "action_masks": "masks"}  # replay-buffer column -> .npz name


def our_steps(action_spec: ActionSpec) -> tuple[dict, list[dict]]:
    hp = SACHyperparams(batch_size=BATCH, buffer_size=1000, hidden_units=HIDDEN, num_layers=2, normalize=False,
                        learning_rate=LR, init_entcoef=INIT_ENTCOEF, tau=TAU, steps_per_update=1.0,
                        reward_signals={"extrinsic": (GAMMA, 1.0)})
    spec = BehaviorSpec((ObservationSpec((OBS,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),), action_spec)
    trainer = SACTrainer("B", spec, hp, seed=5)
    assert trainer._numpy_step is not None
    modules = {"actor": trainer.policy.actor, "critic": trainer.critic, "q1": trainer.q_network.q1_network,
               "q2": trainer.q_network.q2_network, "target": trainer.target_network}
    data: dict[str, np.ndarray] = {"continuous": np.array(action_spec.continuous_size),
                                   "branches": np.array(action_spec.discrete_branches, dtype=np.int64),
                                   "obs_size": np.array(OBS), "hidden": np.array(HIDDEN), "steps": np.array(STEPS),
                                   "hyper": np.array([LR, INIT_ENTCOEF, TAU, GAMMA, BATCH])}

    def dump(prefix: str) -> None:
        for name, module in modules.items():
            params = [p for p in module.parameters() if p.requires_grad]
            data[f"count/{name}"] = np.array(len(params))
            for i, p in enumerate(params):
                data[f"{prefix}/{name}/{i}"] = p.detach().numpy().copy()
        coefficients = trainer.log_ent_coef
        if coefficients.discrete is not None:
            data[f"{prefix}/log_alpha_d"] = coefficients.discrete.detach().numpy().copy()
        if coefficients.continuous is not None:
            data[f"{prefix}/log_alpha_c"] = coefficients.continuous.detach().numpy().copy()

    dump("init")
    rng = np.random.default_rng(4)
    branches = list(action_spec.discrete_branches)
    stats = []
    for k in range(STEPS):
        masks = np.zeros((BATCH, sum(branches)), dtype=bool)
        discrete = np.zeros((BATCH, len(branches)), dtype=np.int64)
        if branches:
            masks[::3, 1] = True  # option 1 of the first branch forbidden in every third row
            discrete = np.stack([rng.integers(0, b, BATCH) for b in branches], axis=1)
            discrete[::3, 0] = np.where(discrete[::3, 0] == 1, 0, discrete[::3, 0])  # taken options are allowed
        batch = {"obs_0": rng.standard_normal((BATCH, OBS)).astype(np.float32),
                 "next_obs_0": rng.standard_normal((BATCH, OBS)).astype(np.float32),
                 "continuous_actions": rng.uniform(-0.99, 0.99, (BATCH, action_spec.continuous_size)).astype(np.float32),
                 "discrete_actions": discrete, "action_masks": masks,
                 "rewards": rng.standard_normal(BATCH).astype(np.float32),
                 "done": (rng.random(BATCH) < 0.2).astype(np.float32)}
        for key, value in batch.items():
            data[f"b{k}/{PEER_NAMES.get(key, key)}"] = value
        data[f"b{k}/seed"] = np.array(100 + k)
        trainer.noise_generator.manual_seed(100 + k)
        stats.append(trainer.gradient_step(batch))
    dump("after")
    return data, stats


@pytest.mark.parametrize("action_spec", [ActionSpec(2, ()), ActionSpec(0, (3, 2))], ids=["continuous", "discrete-masked"])
def test_ten_gradient_steps_match_mlagents_1_1_0(action_spec, tmp_path, run_peer):
    data, ours = our_steps(action_spec)
    np.savez(tmp_path / "ours.npz", **data)
    done, ref = run_peer("sac_reference_update.py", {"npz": str(tmp_path / "ours.npz")}, timeout=180)
    assert done.returncode == 0 and ref, done.stdout[-2000:] + done.stderr[-3000:]
    for step, (mine, theirs) in enumerate(zip(ours, ref["stats"])):
        for key in ("Losses/Policy Loss", "Losses/Value Loss", "Losses/Q1 Loss", "Losses/Q2 Loss"):
            assert mine[key] == pytest.approx(theirs[key], rel=1e-4, abs=1e-6), (step, key)
        kind = "Continuous" if action_spec.continuous_size else "Discrete"
        assert mine[f"Policy/{kind} Entropy Coeff"] == pytest.approx(theirs[f"Policy/{kind} Entropy Coeff"], rel=1e-5)
    # every weight after ten steps of lr 3e-3 (the actor moved by > 1e-3): the same to float32 rounding
    assert max(ref["weights"].values()) < 1e-6, ref["weights"]  # measured: <= 2.4e-7
    moved = max(float(np.abs(data[f"after/actor/{i}"] - data[f"init/actor/{i}"]).max())
                for i in range(int(data["count/actor"])))
    assert moved > 1e-3
