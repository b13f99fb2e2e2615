"""The pure pieces of data-parallel ranks (trainer/distributed.py), by hand: rank discovery from
the launchers' variables, MASTER_ADDR / MASTER_PORT under Slurm, the normaliser's deferred
merge, the stats merge, the one gradient hook of Adam, and the run alone (every call a no-op)."""
from __future__ import annotations

import subprocess

import numpy as np
import pytest
import torch

from protos.types import ActionSpec, BehaviorSpec
from trainer.artifacts.stats import StatsAggregationMethod, StatsAggregator
from trainer.config.env_vars import EnvVars, RankEnv
from trainer.distributed import MASTER_PORT_BASE, Ranks, master_address
from trainer.errors import ConfigError
from trainer.common.adam import Adam
from trainer.common.normalizer import Normalizer
from tests.unit.test_ppo_numpy_update import _filled_trainer, _state, vec


# ------------------------------------------------------------------ discovery
def test_torchrun_variables_come_first():
    r = RankEnv.from_environ({"RANK": "1", "WORLD_SIZE": "4", "LOCAL_RANK": "1", "MASTER_ADDR": "h0",
                              "MASTER_PORT": "29500", "SLURM_PROCID": "3", "SLURM_STEP_NUM_TASKS": "8"})
    assert r == RankEnv(rank=1, world_size=4, local_rank=1, master_addr="h0", master_port=29500,
                        launcher="torchrun")


def test_srun_tasks_are_ranks_and_a_batch_script_alone_is_one():
    r = RankEnv.from_environ({"SLURM_PROCID": "1", "SLURM_STEP_NUM_TASKS": "2", "SLURM_LOCALID": "0",
                              "SLURM_JOB_NODELIST": "node[07-08]", "SLURM_JOB_ID": "4242", "SLURM_NTASKS": "2"})
    assert (r.rank, r.world_size, r.local_rank, r.launcher) == (1, 2, 0, "srun")
    assert (r.job_nodelist, r.job_id, r.master_addr, r.master_port) == ("node[07-08]", 4242, None, None)
    # sbatch --ntasks=2 runs the script once, without a step: not two ranks
    assert RankEnv.from_environ({"SLURM_PROCID": "0", "SLURM_NTASKS": "2", "SLURM_JOB_ID": "1"}) == RankEnv()
    assert EnvVars.from_environ({"RANK": "0", "WORLD_SIZE": "2"}).ranks.world_size == 2
    tuned = EnvVars.from_environ({"MLAGENTS_LIKE_DIST_SYNC_EVERY": "3", "MLAGENTS_LIKE_DIST_TIMEOUT_S": "60"})
    assert (tuned.dist_sync_every, tuned.dist_timeout_s, EnvVars().dist_sync_every) == (3, 60.0, 8)


@pytest.mark.parametrize("environ, named", [
    ({"RANK": "2", "WORLD_SIZE": "2"}, "RANK=2"),
    ({"RANK": "x", "WORLD_SIZE": "2"}, "RANK='x'"),
    ({"SLURM_PROCID": "0", "SLURM_STEP_NUM_TASKS": "-1"}, "SLURM_STEP_NUM_TASKS='-1'"),
    ({"RANK": "0", "WORLD_SIZE": "2", "MASTER_PORT": "70000"}, "MASTER_PORT='70000'"),
    ({"MLAGENTS_LIKE_DIST_TIMEOUT_S": "0"}, "MLAGENTS_LIKE_DIST_TIMEOUT_S='0'"),
    ({"MLAGENTS_LIKE_DIST_SYNC_EVERY": "0"}, "MLAGENTS_LIKE_DIST_SYNC_EVERY='0'"),
])
def test_bad_values_are_named(environ, named):
    with pytest.raises(ConfigError, match=named.replace("(", r"\(")):
        EnvVars.from_environ(environ)


def _scontrol(node_addr: str | None):
    calls = []

    def run(cmd, **_):
        calls.append(cmd)
        if cmd[:3] == ["scontrol", "show", "hostnames"]:
            return subprocess.CompletedProcess(cmd, 0, "node07\nnode08\n", "")
        line = f"NodeName=node07 Arch=x86_64 NodeAddr={node_addr} State=ALLOCATED" if node_addr else "NodeName=node07"
        return subprocess.CompletedProcess(cmd, 0, line + "\n", "")

    return run, calls


def test_master_is_the_first_node_at_slurms_address_and_the_port_follows_the_job():
    slurm = RankEnv(rank=0, world_size=2, job_nodelist="node[07-08]", job_id=4242, launcher="srun")
    run, calls = _scontrol("10.0.0.7")
    assert master_address(slurm, run) == ("10.0.0.7", MASTER_PORT_BASE + 242)
    assert calls[0] == ["scontrol", "show", "hostnames", "node[07-08]"]
    assert master_address(slurm, _scontrol(None)[0]) == ("node07", 9242)
    given = RankEnv(rank=0, world_size=2, master_addr="h", master_port=1234, job_nodelist="x", job_id=1)
    assert master_address(given, run) == ("h", 1234)
    with pytest.raises(ConfigError, match="MASTER_ADDR is not set"):
        master_address(RankEnv(rank=0, world_size=2, launcher="torchrun"), run)


# ------------------------------------------------------------------ what is merged
def test_deferred_normaliser_updates_merge_to_the_direct_update():
    """Initial steps 1, mean 0, variance sum 1; observations 1 and 3 (one per 'rank'):
    mean 4/3, variance sum 1 + (1 - 4/3) * 1 + (3 - 4/3) * 3 = 17/3, steps 3."""
    direct, rank_a, rank_b = Normalizer(1), Normalizer(1), Normalizer(1)
    direct.update(torch.tensor([[1.0], [3.0]]))
    for n in (rank_a, rank_b):
        n.defer()
    rank_a.update(torch.tensor([[1.0]]))
    rank_b.update(torch.tensor([[3.0]]))
    assert int(rank_a.normalization_steps) == 1  # deferred: nothing applied yet
    total = rank_a.take_pending() + rank_b.take_pending()  # what Ranks.agree adds up
    assert total.tolist() == [2.0, 4.0, 10.0]  # count, sum(x - 0), sum((x - 0)^2)
    for n in (rank_a, rank_b):
        n.apply(int(total[0]), total[1:2], total[2:3])
        assert int(n.normalization_steps) == 3
        assert n.running_mean.item() == pytest.approx(4 / 3, rel=1e-6)
        assert n.running_variance.item() == pytest.approx(17 / 3, rel=1e-6)
        assert torch.equal(n.running_variance, rank_a.running_variance)
    assert direct.running_mean.item() == pytest.approx(4 / 3, rel=1e-6)
    assert direct.running_variance.item() == pytest.approx(17 / 3, rel=1e-6)
    assert rank_a.take_pending().tolist() == [0.0, 0.0, 0.0]


def test_merged_stats_equal_stats_of_all_values():
    """[1, 2] and [3, 5]: mean 2.75, population std sqrt(8.75 / 4), sum 11; a histogram keeps
    all four values; a MOST_RECENT key keeps rank 0's own."""
    a, b = StatsAggregator(), StatsAggregator()
    a.add_many("r", [1.0, 2.0])
    b.add_many("r", [3.0, 5.0])
    a.add_many("Environment/Cumulative Reward", [1.0])
    b.add_many("Environment/Cumulative Reward", [4.0, 7.0])
    a.add("last", 1.0, StatsAggregationMethod.MOST_RECENT)
    b.add("last", 9.0, StatsAggregationMethod.MOST_RECENT)
    b.add("only b", 6.0, StatsAggregationMethod.MOST_RECENT)
    a.merge_from(b)
    s = a.summarize()
    assert (s["r"].count, s["r"].mean, s["r"].sum) == (4, 2.75, 11.0)
    assert s["r"].std == pytest.approx((8.75 / 4) ** 0.5, rel=1e-12)
    assert s["Environment/Cumulative Reward"].values.tolist() == [1.0, 4.0, 7.0]
    assert s["last"].mean == 1.0 and s["only b"].mean == 6.0


# ------------------------------------------------------------------ the one gradient hook
def test_adam_hands_its_flat_gradient_buffer_to_reduce_before_the_step():
    """A reduce that turns the gradients [1, -2] into [3, 1] (as an average over ranks would):
    the step is the plain step with [3, 1], and differs from the one with [1, -2]."""
    reduced, plain = (Adam([torch.nn.Parameter(torch.zeros(2))], lr=0.1) for _ in range(2))
    seen = []
    reduced.reduce = lambda flat: (seen.append(flat.copy()), flat.__setitem__(slice(None), [3.0, 1.0]))
    reduced.params[0].grad = torch.tensor([1.0, -2.0])
    plain.params[0].grad = torch.tensor([3.0, 1.0])
    for opt in (reduced, plain):
        opt.step()
    assert [s.tolist() for s in seen] == [[1.0, -2.0]]  # one flat buffer per step
    assert torch.equal(reduced.params[0], plain.params[0])  # the step used the reduced gradients
    assert (reduced.params[0] > 0).tolist() == [False, False]  # [1, -2] would have moved it to [-, +]


def test_one_buffer_per_minibatch_gives_the_bits_of_the_separate_halves():
    """The numpy update of data-parallel ranks (actor and critic in one buffer, one reduce per
    minibatch) with an identity reduce: bit for bit the single-process update."""
    spec = BehaviorSpec((vec(6), vec(2, "w")), ActionSpec(1, (3, 2)))
    alone, together = _filled_trainer(spec, True), _filled_trainer(spec, True)
    calls = []
    together.optimizer.reduce = lambda flat: calls.append(flat.size)
    assert alone.update() == together.update()
    assert len(calls) == 2 * (220 // 32)  # one per minibatch step
    assert set(calls) == {together.optimizer.exp_avg.size}  # each the whole actor + critic
    for x, y in zip(_state(alone), _state(together)):
        assert x.tobytes() == y.tobytes()


def test_update_rows_limit_the_minibatches_to_the_shortest_buffer():
    spec = BehaviorSpec((vec(6), vec(2, "w")), ActionSpec(2, ()))
    trainer = _filled_trainer(spec, False)  # 220 experiences, batch 32, 2 epochs
    steps = trainer.optimizer.step_count
    trainer.update(rows=100)
    assert trainer.optimizer.step_count - steps == 2 * (100 // 32)


# ------------------------------------------------------------------ alone
def test_alone_every_call_is_the_single_process_rule():
    ranks = Ranks.start(EnvVars(), None)
    assert (ranks.world, ranks.is_main, ranks.active) == (1, True, False)
    flat = np.array([1.0, 2.0], dtype=np.float32)
    ranks.average_(flat)
    assert flat.tolist() == [1.0, 2.0]
    spec = BehaviorSpec((vec(6), vec(2, "w")), ActionSpec(2, ()))
    trainer = _filled_trainer(spec, False)

    class Runner:  # what agree reads of a BehaviorRunner
        done = False

    ready, full = Runner(), Runner()
    ready.trainer, full.trainer = trainer, trainer
    full.done = True
    assert ranks.agree({"A": ready, "B": full}) == {"A": None}
    assert trainer.optimizer.reduce is None and all(n.pending is None for n in trainer.normalizers())
