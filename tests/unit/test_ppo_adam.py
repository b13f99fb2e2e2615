"""Our Adam (numpy on the parameters' storage) against torch.optim.Adam and against the update
written out by hand."""
import math

import numpy as np
import pytest
import torch

from trainer.common.adam import Adam
from trainer.common.layers import linear_layer


def _net(seed):
    torch.manual_seed(seed)
    return torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.SiLU(), torch.nn.Linear(8, 2))


def _loss(net, step):
    g = torch.Generator().manual_seed(100 + step)
    x = torch.randn(16, 4, generator=g)
    return (net(x) ** 2).mean() + net[0].weight.abs().sum() * 0.01


def test_matches_torch_adam_over_many_steps():
    ours, ref = _net(0), _net(0)
    opt_ours = Adam(ours.parameters(), lr=3e-3)
    opt_ref = torch.optim.Adam(ref.parameters(), lr=3e-3)
    for step in range(50):
        if step == 25:  # a learning-rate change mid-run, as the linear schedule does
            opt_ours.param_groups[0]["lr"] = 1e-3
            for g in opt_ref.param_groups:
                g["lr"] = 1e-3
        for net, opt in ((ours, opt_ours), (ref, opt_ref)):
            opt.zero_grad()
            _loss(net, step).backward()
            opt.step()
    for a, b in zip(ours.parameters(), ref.parameters()):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)


def test_first_step_by_hand():
    p = torch.nn.Parameter(torch.tensor([1.0, -2.0]))
    opt = Adam([p], lr=0.1)
    p.grad = torch.tensor([0.5, -4.0])
    opt.step()
    # t=1: m = 0.1 g, v = 0.001 g^2; m_hat = g, v_hat = g^2 → p -= lr * g / (|g| + eps)
    expected = [1.0 - 0.1 * 0.5 / (0.5 + 1e-8), -2.0 + 0.1 * 4.0 / (4.0 + 1e-8)]
    assert [round(v, 6) for v in p.tolist()] == [round(v, 6) for v in expected]
    state = opt.state_dict()["state"][0]
    assert math.isclose(state["exp_avg"][1].item(), -0.4, rel_tol=1e-6)
    assert math.isclose(state["exp_avg_sq"][1].item(), 0.016, rel_tol=1e-5)
    assert state["step"].item() == 1.0


def test_state_dict_round_trips_through_torch_adam():
    ours, ref = _net(1), _net(1)
    opt_ours = Adam(ours.parameters(), lr=1e-2)
    for step in range(5):
        opt_ours.zero_grad()
        _loss(ours, step).backward()
        opt_ours.step()
    ref.load_state_dict(ours.state_dict())
    opt_ref = torch.optim.Adam(ref.parameters(), lr=1e-2)
    opt_ref.load_state_dict(opt_ours.state_dict())  # torch accepts our layout
    back = Adam(ours.parameters(), lr=5.0)
    back.load_state_dict(opt_ref.state_dict())  # and we accept torch's
    assert back.step_count == 5 and back.param_groups[0]["lr"] == 1e-2
    for net, opt in ((ours, back), (ref, opt_ref)):
        opt.zero_grad()
        _loss(net, 9).backward()
        opt.step()
    for a, b in zip(ours.parameters(), ref.parameters()):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)


def test_a_stretch_steps_its_parameters_as_a_whole_step_would():
    """The numpy update steps the actor's and the critic's runs of parameters separately, with
    gradients as arrays: the same values and moments as one step over all of them."""
    whole, parts = _net(2), _net(2)
    opt_whole, opt_parts = Adam(whole.parameters(), lr=1e-2), Adam(parts.parameters(), lr=1e-2)
    params = list(parts.parameters())
    first, second = opt_parts.stretch(params[:2]), opt_parts.stretch(params[2:])
    for step in range(1, 4):
        opt_whole.zero_grad()
        _loss(whole, step).backward()
        grads = [p.grad.numpy().copy() for p in whole.parameters()]
        opt_whole.step()
        first.step(grads[:2], step)
        second.step(grads[2:], step)
    for a, b in zip(whole.parameters(), parts.parameters()):
        assert torch.equal(a, b)
    np.testing.assert_array_equal(opt_whole.exp_avg_sq, opt_parts.exp_avg_sq)
    with pytest.raises(ValueError, match="contiguous run"):
        opt_parts.stretch([params[0], params[2]])


def test_a_parameter_without_gradient_keeps_its_value_and_moments():
    net = _net(3)
    opt = Adam(net.parameters(), lr=1e-2)
    frozen = net[2].bias
    before = frozen.detach().clone()
    for step in range(3):
        opt.zero_grad()
        (net[0](torch.ones(2, 4)) ** 2).mean().backward()  # only the first layer gets gradients
        opt.step()
    assert torch.equal(frozen, before) and opt.step_count == 3
    state = opt.state_dict()["state"]
    assert not state[3]["exp_avg"].any() and state[0]["exp_avg"].abs().sum() > 0


def test_load_rejects_another_network_layout():
    opt = Adam(_net(0).parameters())
    other = Adam(torch.nn.Sequential(torch.nn.Linear(4, 9), torch.nn.SiLU(), torch.nn.Linear(9, 2)).parameters())
    other.param_groups[0]["lr"] = 0.5
    for p in other.params:
        p.grad = torch.ones_like(p)
    other.step()
    with pytest.raises(ValueError, match="parameter 0 has shape"):
        opt.load_state_dict(other.state_dict())
    assert opt.step_count == 0 and opt.param_groups[0]["lr"] == 1e-3  # nothing half-loaded


def test_input_major_kernels_match_torch_adam_and_save_in_torch_layout():
    """layers.py stores kernels input-major; the moments follow that memory order inside, and the
    state dict still holds them in the parameters' own shape, as torch.optim.Adam does."""
    def net():
        torch.manual_seed(4)
        return torch.nn.Sequential(linear_layer(4, 8), torch.nn.SiLU(), linear_layer(8, 2))
    ours, ref = net(), net()
    assert ours[0].weight.stride() == (1, 8)  # W [8, 4] stored as W^T
    opt_ours, opt_ref = Adam(ours.parameters(), lr=3e-3), torch.optim.Adam(ref.parameters(), lr=3e-3)
    for step in range(20):
        for model, opt in ((ours, opt_ours), (ref, opt_ref)):
            opt.zero_grad()
            _loss(model, step).backward()
            opt.step()
    for a, b in zip(ours.parameters(), ref.parameters()):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    for ours_state, ref_state in zip(opt_ours.state_dict()["state"].values(), opt_ref.state_dict()["state"].values()):
        torch.testing.assert_close(ours_state["exp_avg_sq"], ref_state["exp_avg_sq"], rtol=1e-4, atol=1e-10)
    back = Adam(net().parameters())
    back.load_state_dict(opt_ours.state_dict())
    np.testing.assert_array_equal(back.exp_avg, opt_ours.exp_avg)
