"""SAC with curiosity and RND (the providers of trainer/common/reward_providers.py): the Q targets use
each provider's reward of the sampled minibatch and bootstrap through episode ends, the learners
step at reward_signal_steps_per_update, their rewards fall on revisited states, their statistics
are those of the reference, and they survive a checkpoint."""
from __future__ import annotations

import io

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.common.trajectory import Trajectory
from trainer.common.hyperparams import SignalNetwork
from trainer.sac import losses
from trainer.sac.hyperparams import SACHyperparams
from trainer.sac.trainer import SACTrainer


def vector(size: int) -> ObservationSpec:
    return ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "vector")


def make_trainer(signals=("rnd",), strength=0.5, **kw) -> SACTrainer:
    reward_signals = {"extrinsic": (0.99, 1.0), **{name: (0.9, strength) for name in signals}}
    networks = {name: SignalNetwork(learning_rate=1e-3, hidden_units=16) for name in signals}
    hyper = SACHyperparams(**{"batch_size": 8, "buffer_size": 200, "hidden_units": 8,
                              "reward_signals": reward_signals, "reward_signal_networks": networks, **kw})
    return SACTrainer("B", BehaviorSpec([vector(4)], ActionSpec(2, (3,))), hyper, seed=0)


def trajectory(trainer: SACTrainer, length: int, seed: int, done: bool = False, episode=0) -> Trajectory:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length, 4)).astype(np.float32)
    out = trainer.policy.act([obs])
    return Trajectory(obs=[obs], next_obs=[rng.normal(size=4).astype(np.float32)],
                      rewards=rng.normal(size=length).astype(np.float32),
                      continuous_actions=out.continuous_raw, discrete_actions=out.discrete,
                      log_probs=out.log_probs, action_masks=None, done=done, interrupted=False, episode=episode)


def test_q_targets_use_the_providers_reward_and_ignore_done():
    """Q2 loss of one step, recomputed by hand from the networks before it: the extrinsic target
    stops at done, the RND target is RND's reward of the sampled rows x strength and bootstraps."""
    trainer = make_trainer(("rnd",), strength=0.5)
    trainer.process_trajectory(trajectory(trainer, 16, 0, done=True))
    batch = trainer.buffer.sample(8, torch.Generator().manual_seed(1))
    batch["done"][:] = 1.0  # every row ends its episode: only RND bootstraps
    t = {k: torch.as_tensor(v) for k, v in batch.items()}
    rnd_reward = trainer.providers["rnd"].evaluate(trainer._experience(batch)) * 0.5
    with torch.no_grad():
        next_v = trainer.target_network([t["next_obs_0"]])
        q2 = trainer.q_network.q2_network([t["obs_0"]], t["continuous_actions"])
        expected = []
        for name, reward, gamma in (("extrinsic", t["rewards"], 0.99), ("rnd", torch.as_tensor(rnd_reward), 0.9)):
            taken = losses.chosen_q(q2[name], t["discrete_actions"], [3])
            backup = reward + gamma * next_v[name] * (0.0 if name == "extrinsic" else 1.0)
            expected.append(0.5 * torch.mean((backup - taken) ** 2))
    stats = trainer.gradient_step(batch)
    assert stats["Losses/Q2 Loss"] == pytest.approx(float(torch.stack(expected).mean()), rel=1e-5)
    assert float(np.abs(rnd_reward).sum()) > 0  # the RND term was not zero


def test_reward_signal_steps_per_update_sets_the_learners_pace():
    trainer = make_trainer(("curiosity", "rnd"), steps_per_update=1.0, reward_signal_steps_per_update=4.0)
    before = [p.detach().clone() for p in trainer.providers["curiosity"].network.parameters()]
    trainer.process_trajectory(trajectory(trainer, 32, 0))
    stats = trainer.update()
    # 32 agent steps: 31 gradient steps (32 / k > 1 for k < 32) and 7 learner steps (32 / k > 4 for k < 8)
    assert trainer.update_steps == 32 and trainer.reward_signal_update_steps == 8
    assert trainer.providers["rnd"].optimizer.state_dict()["state"][0]["step"] == 7
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.providers["curiosity"].network.parameters()))
    for key in ("Losses/Curiosity Forward Loss", "Losses/Curiosity Inverse Loss", "Losses/RND Loss"):
        assert np.isfinite(stats[key])
    # without intrinsic signals nothing else is stepped and the counter stays
    plain = make_trainer(())
    plain.process_trajectory(trajectory(plain, 32, 0))
    plain.update()
    assert plain.reward_signal_update_steps == 1


def test_rnd_reward_falls_on_revisited_states():
    trainer = make_trainer(("rnd",), steps_per_update=1.0, reward_signal_steps_per_update=1.0, batch_size=16)
    seen = trajectory(trainer, 32, 0)
    rnd = trainer.providers["rnd"]
    first = rnd.evaluate(trainer._experience(_columns(trainer, seen))).mean()
    for repeat in range(10):  # the same 32 states, 10 times: 320 agent steps, 319 learner steps
        trainer.process_trajectory(trajectory(trainer, 32, 0))
        trainer.update()
    now = rnd.evaluate(trainer._experience(_columns(trainer, seen))).mean()
    assert now < 0.15 * first  # measured: 4.16 -> 0.39 (0.094x)


def _columns(trainer: SACTrainer, traj: Trajectory) -> dict[str, np.ndarray]:
    return {"obs_0": traj.obs[0], "next_obs_0": np.concatenate([traj.obs[0][1:], traj.next_obs[0][None]]),
            "continuous_actions": traj.continuous_actions, "discrete_actions": traj.discrete_actions}


def test_episode_statistics_have_the_references_names():
    trainer = make_trainer(("curiosity", "rnd"))
    first = trainer.process_trajectory(trajectory(trainer, 10, 0, episode="a"))
    assert "Policy/Rnd Reward" not in first  # the episode goes on
    assert {"Policy/Extrinsic Value", "Policy/Curiosity Value", "Policy/Rnd Value"} <= set(first)
    last = trainer.process_trajectory(trajectory(trainer, 10, 1, done=True, episode="a"))
    rnd = trainer.providers["rnd"]
    expected = sum(float(np.sum(rnd.evaluate(trainer._experience(_columns(trainer, trajectory(trainer, 10, s))))))
                   for s in (0, 1)) * 0.5
    assert last["Policy/Rnd Reward"] == pytest.approx(expected, rel=1e-4)
    assert last["Policy/Curiosity Reward"] == 0.0  # no curiosity update yet: zero, as the reference


def test_providers_and_counters_survive_a_checkpoint():
    trainer = make_trainer(("curiosity", "rnd"), reward_signal_steps_per_update=2.0)
    trainer.process_trajectory(trajectory(trainer, 24, 0))
    trainer.update()
    stream = io.BytesIO()
    torch.save(trainer.state_dict(), stream)
    stream.seek(0)
    state = torch.load(stream, weights_only=True)
    assert {"Module:Curiosity", "Module:RND-pred", "Module:RND-target"} <= set(state)
    copy = make_trainer(("curiosity", "rnd"), reward_signal_steps_per_update=2.0)
    copy.load_state_dict(state)
    assert copy.reward_signal_update_steps == trainer.reward_signal_update_steps == 12
    probe = trainer._experience(_columns(trainer, trajectory(trainer, 6, 5)))
    for name in ("curiosity", "rnd"):
        np.testing.assert_allclose(copy.providers[name].evaluate(probe), trainer.providers[name].evaluate(probe),
                                   rtol=1e-6)
