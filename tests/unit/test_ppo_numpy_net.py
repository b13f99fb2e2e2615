"""The numpy actor and critic (numpy_net.py) must equal the torch modules they read and follow
every change of their weights and normalisers by themselves: they are views, not copies."""
import numpy as np
import torch

from protos.types import ActionSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.networks import Actor
from trainer.common.numpy_net import NumpyActor, supports

HP = PPOHyperparams(hidden_units=16, num_layers=2, normalize=True)


def vec(n):
    return ObservationSpec((n,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v")


def torch_heads(actor, obs, allowed):
    with torch.no_grad():
        mu, logits = actor.heads([torch.from_numpy(o) for o in obs],
                                 None if allowed is None else torch.from_numpy(allowed))
    return (None if mu is None else mu.numpy()), [lg.numpy() for lg in logits]


def test_hybrid_heads_match_torch_and_follow_updates():
    torch.manual_seed(0)
    actor = Actor((vec(3), vec(5)), ActionSpec(2, (3, 2)), HP)
    fast = NumpyActor(actor)
    rng = np.random.default_rng(1)
    obs = [rng.standard_normal((7, 3)).astype(np.float32) * 4, rng.standard_normal((7, 5)).astype(np.float32)]
    allowed = np.ones((7, 5), np.float32)
    allowed[:, 1] = 0.0
    for round_ in range(3):
        mu, logits, _ = fast.heads(obs, allowed == 0)
        t_mu, t_logits = torch_heads(actor, obs, allowed)
        np.testing.assert_allclose(mu, t_mu, rtol=1e-5, atol=1e-6)
        for a, b in zip(logits, t_logits):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-4)
        assert np.all(logits[0][:, 1] < -1e7)  # the masked option
        # change everything in place, as a trajectory and an optimiser step do: normaliser
        # statistics and weights (nobody tells the numpy actor)
        actor.update_normalization([torch.from_numpy(o * (round_ + 2)) for o in obs])
        with torch.no_grad():
            for p in actor.parameters():
                if p.requires_grad:
                    p.add_(0.05)


def test_weights_are_views_of_the_torch_parameters():
    """No copies to keep in step: the numpy actor's kernels are the torch parameters' memory,
    contiguous as W^T (layers.py stores Linear kernels input-major)."""
    torch.manual_seed(0)
    actor = Actor((vec(3),), ActionSpec(2, ()), HP)
    fast = NumpyActor(actor)
    obs = [np.array([[1.0, -2.0, 0.5], [4.0, 3.0, -1.0]], np.float32)]
    before, _, _ = fast.heads(obs, None)
    layers = [actor.network_body.hidden[0], actor.network_body.hidden[2], actor.mu]
    for (kernel, bias), layer in zip([*fast.body.kernels, fast.mu], layers):
        assert kernel.flags.c_contiguous and np.shares_memory(kernel, layer.weight.detach().numpy())
        assert np.shares_memory(bias, layer.bias.detach().numpy())
    np.testing.assert_array_equal(fast.mu[0], actor.mu.weight.detach().numpy().T)
    actor.update_normalization([torch.from_numpy(obs[0] * 10)])
    after, _, _ = fast.heads(obs, None)
    np.testing.assert_allclose(after, torch_heads(actor, obs, None)[0], rtol=1e-5, atol=1e-6)
    assert not np.allclose(before, after)
    with torch.no_grad():
        actor.network_body.hidden[0].weight.add_(0.1)
        actor.log_sigma.add_(1.0)
    moved, _, _ = fast.heads(obs, None)
    np.testing.assert_allclose(moved, torch_heads(actor, obs, None)[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(fast.gaussian()[0], np.exp(actor.log_sigma.detach().numpy()), rtol=1e-6)


def test_load_state_dict_is_seen_and_visual_actors_are_not_supported():
    torch.manual_seed(0)
    a, b = Actor((vec(4),), ActionSpec(1, ()), HP), Actor((vec(4),), ActionSpec(1, ()), HP)
    fast = NumpyActor(a)
    obs = [np.ones((2, 4), np.float32)]
    before, _, _ = fast.heads(obs, None)
    a.load_state_dict(b.state_dict())
    after, _, _ = fast.heads(obs, None)
    np.testing.assert_allclose(after, torch_heads(b, obs, None)[0], rtol=1e-5, atol=1e-6)
    assert not np.allclose(before, after)
    visual = ObservationSpec((3, 36, 36), (DimensionProperty.NONE, DimensionProperty.TRANSLATIONAL_EQUIVARIANCE,
                                           DimensionProperty.TRANSLATIONAL_EQUIVARIANCE), ObservationType.DEFAULT, "cam")
    assert not supports(Actor((visual, vec(2)), ActionSpec(1, ()), HP))


def test_numpy_critic_matches_torch_and_follows_normaliser_and_weight_changes():
    from trainer.common.numpy_net import NumpyCritic
    from trainer.common.networks import Critic

    torch.manual_seed(0)
    critic = Critic((vec(3), vec(5)), ["extrinsic", "curiosity"], HP)
    fast = NumpyCritic(critic)
    rng = np.random.default_rng(2)
    obs = [rng.standard_normal((9, 3)).astype(np.float32) * 3 + 1, rng.standard_normal((9, 5)).astype(np.float32)]
    for round_ in range(3):
        got = fast(obs)
        with torch.no_grad():
            want = critic([torch.from_numpy(o) for o in obs])
        assert set(got) == {"extrinsic", "curiosity"}
        for name in want:
            assert got[name].shape == (9,)
            np.testing.assert_allclose(got[name], want[name].numpy(), rtol=1e-5, atol=1e-6)
        critic.update_normalization([torch.from_numpy(o * (round_ + 2)) for o in obs])
        with torch.no_grad():
            for p in critic.parameters():
                if p.requires_grad:
                    p.mul_(1.1)
