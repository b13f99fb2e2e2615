"""The running observation normaliser against a sequence worked out by hand."""
from __future__ import annotations

import math

import pytest
import torch

from trainer.common.normalizer import Normalizer


def test_initial_state_is_identity_within_clip():
    normalizer = Normalizer(2)
    assert int(normalizer.normalization_steps) == 1
    x = torch.tensor([[0.5, -2.0]])
    torch.testing.assert_close(normalizer(x), x)


def test_batched_welford_sequence_by_hand():
    normalizer = Normalizer(1)
    normalizer.update(torch.tensor([[1.0], [3.0]]))
    # steps 1 -> 3 ; mean = 0 + (1 + 3)/3 = 4/3 ; var_sum = 1 + (1-4/3)*1 + (3-4/3)*3 = 17/3
    assert int(normalizer.normalization_steps) == 3
    assert normalizer.running_mean.item() == pytest.approx(4 / 3, rel=1e-6)
    assert normalizer.running_variance.item() == pytest.approx(17 / 3, rel=1e-6)
    # (2 - 4/3) / sqrt(17/9) = 2 / sqrt(17)
    assert normalizer(torch.tensor([[2.0]])).item() == pytest.approx(2 / math.sqrt(17), rel=1e-6)

    normalizer.update(torch.tensor([[0.0]]))
    # steps 4 ; mean = 4/3 + (0 - 4/3)/4 = 1 ; var_sum = 17/3 + (0 - 1)(0 - 4/3) = 7
    assert int(normalizer.normalization_steps) == 4
    assert normalizer.running_mean.item() == pytest.approx(1.0, rel=1e-6)
    assert normalizer.running_variance.item() == pytest.approx(7.0, rel=1e-6)
    out = normalizer(torch.tensor([[1.0], [100.0], [-100.0], [2.0]])).squeeze(1)
    torch.testing.assert_close(out, torch.tensor([0.0, 5.0, -5.0, 1 / math.sqrt(7 / 4)]))


def test_dimensions_are_independent():
    normalizer = Normalizer(2)
    normalizer.update(torch.tensor([[1.0, 10.0], [3.0, 10.0]]))
    # second column: mean = 20/3, var_sum = 1 + 2 * (10 - 20/3) * 10 = 1 + 200/3
    torch.testing.assert_close(normalizer.running_mean, torch.tensor([4 / 3, 20 / 3]))
    torch.testing.assert_close(normalizer.running_variance, torch.tensor([17 / 3, 1 + 200 / 3]))


def test_statistics_are_saved_in_state_dict():
    normalizer = Normalizer(3)
    assert set(normalizer.state_dict()) == {"normalization_steps", "running_mean", "running_variance"}
