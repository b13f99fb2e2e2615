"""PPO loss terms and distribution math against numbers worked out by hand."""
from __future__ import annotations

import math

import pytest
import torch

from trainer.common.distributions import (
    categorical_entropy,
    categorical_log_prob,
    gaussian_entropy,
    gaussian_log_prob,
    mask_logits,
)
from trainer.common.distributions import combined_entropy
from trainer.ppo.losses import policy_loss, ppo_loss, value_loss


def test_policy_loss_per_dimension_ratios_by_hand():
    advantages = torch.tensor([1.0, -2.0])
    log_probs = torch.log(torch.tensor([[1.5, 1.0], [0.5, 1.1]]))
    old = torch.zeros(2, 2)
    # A=+1: min(1.5, 1.2)=1.2, min(1, 1)=1 ; A=-2: min(-1.0, -1.6)=-1.6, min(-2.2, -2.2)=-2.2
    # mean = (1.2 + 1 - 1.6 - 2.2)/4 = -0.4 -> loss 0.4
    assert policy_loss(advantages, log_probs, old, epsilon=0.2).item() == pytest.approx(0.4, rel=1e-6)


def test_value_loss_clipped_and_averaged_over_heads_by_hand():
    values = {"a": torch.tensor([1.0, 2.0]), "b": torch.tensor([0.0, 0.0])}
    old = {"a": torch.tensor([0.5, 2.0]), "b": torch.tensor([0.0, 0.0])}
    returns = {"a": torch.tensor([2.0, 1.0]), "b": torch.tensor([1.0, 3.0])}
    # a: elem0 max((2-1)^2, (2-0.7)^2)=1.69, elem1 = 1 -> 1.345 ; b: (1 + 9)/2 = 5 ; mean = 3.1725
    assert value_loss(values, old, returns, epsilon=0.2).item() == pytest.approx(3.1725, rel=1e-6)


def test_total_loss_by_hand():
    total = ppo_loss(torch.tensor(0.4), torch.tensor(3.1725), torch.tensor([2.0, 4.0]), beta=0.01)
    assert total.item() == pytest.approx(0.4 + 0.5 * 3.1725 - 0.01 * 3.0, rel=1e-6)


def test_entropy_is_mean_over_gaussian_dims_plus_sum_over_branches():
    entropy = combined_entropy(torch.tensor([[1.0, 3.0]]), [torch.tensor([0.5]), torch.tensor([0.25])])
    assert entropy.item() == pytest.approx(2.0 + 0.5 + 0.25)
    assert combined_entropy(None, [torch.tensor([0.5])]).item() == pytest.approx(0.5)
    with pytest.raises(ValueError):
        combined_entropy(None, [])


def test_gaussian_log_prob_and_entropy_by_hand():
    # a = mu + sigma with sigma = 2: -1/2 - ln 2 - ln sqrt(2 pi)
    log_prob = gaussian_log_prob(torch.tensor([[3.0]]), torch.tensor([[1.0]]), torch.tensor([[math.log(2.0)]]))
    assert log_prob.item() == pytest.approx(-0.5 - math.log(2.0) - 0.5 * math.log(2 * math.pi), rel=1e-5)
    assert gaussian_entropy(torch.zeros(1, 1)).item() == pytest.approx(0.5 * math.log(2 * math.pi * math.e), rel=1e-6)


def test_categorical_terms_and_masking_by_hand():
    probs = torch.tensor([[0.5, 0.5], [0.25, 0.75]])
    assert categorical_entropy(probs)[0].item() == pytest.approx(math.log(2.0), rel=1e-5)
    log_prob = categorical_log_prob(probs, torch.tensor([0, 1]))
    torch.testing.assert_close(log_prob, torch.log(torch.tensor([0.5, 0.75])))
    masked = mask_logits(torch.tensor([[1.0, 2.0, 3.0]]), torch.tensor([[1.0, 0.0, 1.0]]))
    torch.testing.assert_close(masked, torch.tensor([[1.0, -1e8, 3.0]]))
    assert torch.softmax(masked, dim=1)[0, 1].item() == 0.0
