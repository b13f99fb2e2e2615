"""tests/conftest.py's XDIST_GROUPS: every entry names a test file (and test) that exists, so a
renamed test cannot silently leave its group and run beside the tests it shares something with;
and the scheduler keeps a group's tests together while every other test is a unit of its own."""
from __future__ import annotations

import re
from pathlib import Path

from tests.conftest import XDIST_GROUPS, xdist_group

ROOT = Path(__file__).resolve().parents[2]


def test_every_entry_names_an_existing_test():
    for prefix in XDIST_GROUPS:
        path, _, name = prefix.partition("::")
        target = ROOT / path
        assert target.exists(), prefix
        if name:
            assert re.search(rf"^def {re.escape(name)}\(", target.read_text(), re.M), prefix
        else:
            assert target.is_dir() or target.suffix == ".py", prefix


def test_groups_keep_their_tests_together_and_leave_the_rest_alone():
    assert xdist_group("tests/slurm/test_ranks.py::test_x") == xdist_group("tests/slurm/test_train_sbatch.py::t") == "slurm"
    assert xdist_group("tests/interop/test_mlagents_learn.py::test_tensorboard_scalars") == "mlagents_learn_run"
    assert xdist_group("tests/unit/test_demonstrations.py::test_gail_rewards_expert_steps_above_random_ones_after_training"
                       "[network1]") == "ball3d_demos"
    assert xdist_group("tests/unit/test_demonstrations.py::test_something_else") is None
    assert xdist_group("tests/unit/test_codec.py::test_a") is None
