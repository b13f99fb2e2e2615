"""Our Adam against torch.optim.Adam and against the update written out by hand."""
import math

import torch

from trainer.ppo.adam import Adam


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
    assert math.isclose(opt.exp_avg[0][1].item(), -0.4, rel_tol=1e-6)
    assert math.isclose(opt.exp_avg_sq[0][1].item(), 0.016, rel_tol=1e-5)


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
