"""MA-POCA learns the cooperative stub task: fixed seed, real gRPC, bounded steps."""
from __future__ import annotations

import pytest

from tests.integration.conftest import ROOT, train_on_stub

pytestmark = pytest.mark.slow


def test_poca_pushes_the_block_home_within_40k_steps(tmp_path, env_no_proxy):
    """configs/pushblock_poca.yaml cut to 40,000 steps, 8 areas (16 agents), seed 1. A group that
    never moves the block returns -0.5, one agent pushing alone at most ~0.2, both pushing from
    the start 1.875. Thresholds: the first summary below 0, the last >= 0.5 and at least 1.0 above
    the first, and some groups bring the block home (measured: -0.457 at 4k, 1.001 at 40k, success
    0 -> 0.452; an earlier version gave the same numbers on a rerun; since the initialisation is
    drawn in numpy, 2026-11-28: -0.439 at 4k, 0.962 at 40k, success 0 -> 0.406)."""
    cfg = tmp_path / "pushblock.yaml"
    text = (ROOT / "configs" / "pushblock_poca.yaml").read_text().replace("max_steps: 60000", "max_steps: 40000")
    cfg.write_text(text)
    assert "max_steps: 40000" in text
    acc = train_on_stub(tmp_path, cfg, "pushblock", "PushBlock", env_no_proxy, num_areas=8, seed=1, run_id="p",
                        timeout=600)
    curve = [(e.step, e.value) for e in acc.Scalars("Environment/Group Cumulative Reward")]
    success = [e.value for e in acc.Scalars("PushBlock/Success")]
    print(curve, success)
    assert curve[-1][0] == 40000
    assert curve[0][1] < 0.0, curve
    assert curve[-1][1] >= 0.5 and curve[-1][1] - curve[0][1] >= 1.0, curve
    assert success[0] == 0.0 and success[-1] >= 0.3, success


def test_poca_learns_the_sacrifice_within_28k_steps(tmp_path, env_no_proxy):
    """configs/dungeon_poca.yaml cut to 28,000 steps, 8 areas (24 agents), seed 1. Random actions
    escape in about 21 % of the group episodes (tests/stub/test_stub_dungeon.py); the escape needs
    one agent to be eaten first, whose own episode ends with nothing paid, so only the credit POCA
    gives it for its group's later +1 teaches it (independent PPO: bench/RESULTS.md). Thresholds:
    the first summary's success rate below 0.6, the last at least 0.8 and 0.3 above the first, and
    the per-agent return (Policy/Extrinsic Reward, at most 0.75: three of the four agent episodes of
    an escape earn the +1) at least 0.25 above the first summary's (measured, seed 1, the same numbers
    on a rerun: success 0.40 at 4k -> 0.92 at 28k, return 0.26 -> 0.69)."""
    cfg = tmp_path / "dungeon.yaml"
    text = (ROOT / "configs" / "dungeon_poca.yaml").read_text().replace("max_steps: 60000", "max_steps: 28000")
    cfg.write_text(text)
    assert "max_steps: 28000" in text
    acc = train_on_stub(tmp_path, cfg, "dungeon", "Dungeon", env_no_proxy, num_areas=8, seed=1, run_id="d",
                        timeout=600)
    success = [(e.step, e.value) for e in acc.Scalars("Dungeon/Success")]
    returns = [e.value for e in acc.Scalars("Policy/Extrinsic Reward")]
    print(success, returns)
    assert success[-1][0] == 28000
    assert success[0][1] < 0.6 and success[-1][1] >= 0.8 and success[-1][1] - success[0][1] >= 0.3, success
    assert returns[-1] - returns[0] >= 0.25, returns
