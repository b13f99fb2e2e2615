"""Data-parallel ranks: K trainer processes, each with its own simulators, train ONE policy.

Started by ``srun -n K mlagents-like-learn ...`` (inside docker/slurm/train.sbatch or any
allocation) or ``torchrun --nproc-per-node K -m trainer.cli ...``; docs/cluster.md describes the
design and its costs. This module owns everything about ranks: who we are (from the launcher's
variables, read by trainer/config/env_vars.py), the torch.distributed process group (gloo on the
CPU, NCCL for --torch-device cuda) and every collective. The run loop (trainer/run.py) calls it at
a few points: ``start`` and ``close``, ``adopt`` (a new brain), ``agree`` (after each exchange
with the simulators; a collective every MLAGENTS_LIKE_DIST_SYNC_EVERY-th), ``gather_stats`` (at
a summary) and ``after_update``. Alone (world size 1) each of them is a no-op or the
single-process rule, and torch.distributed is never imported.

What stays identical on every rank, and how:
  * weights, optimiser moments, step: rank 0's brain is broadcast to the others when every rank
    knows the brain (``_join``); from then on the same averaged gradients (``average_``, called
    by Adam on its one flat gradient buffer per minibatch step: trainer/common/adam.py) and the
    same Adam arithmetic keep them bit-identical;
  * the step count is global: each rank's new experiences are summed at every exchange;
  * observation normalisers: each rank only accumulates its new observations' sums
    (trainer/common/normalizer.py ``defer``); ``agree`` adds every rank's sums and all ranks fold
    the same total in. (Alone, the normaliser updates at once, per trajectory, as ML-Agents.)
  * the YAML means the same on any number of ranks: buffer_size and batch_size are global, so
    each of K ranks collects buffer_size / K and steps on minibatches of batch_size / K
    (``split``; ``--batch-per-rank`` keeps the YAML's values on every rank instead). The mean of
    the K ranks' minibatch gradients is then the gradient of one batch_size minibatch, and the
    advantages are normalised with the mean and std of all ranks' buffers (``sum_``);
  * when to update: when EVERY rank's buffer holds more than its share of buffer_size;
    all take the minibatches of the smallest buffer (PPOTrainer.update's ``rows``);
  * when to stop: a stop signal on any rank, or max_steps, is acted on by all at the same
    exchange, so none waits in a collective for a rank that left. A rank that dies or hangs
    (``MLAGENTS_LIKE_DIST_TIMEOUT_S``) makes the others' next collective fail: ``RankLost``,
    handled like a stop signal (rank 0 writes its final checkpoint and ONNX).

Rank 0 alone writes files (checkpoints, ONNX, TensorBoard, status, console summaries); the
other ranks' statistics reach it at every summary (``gather_stats``).
"""
from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import logging
import os
import socket
import struct
import subprocess
import zlib
from dataclasses import dataclass, field
from datetime import timedelta

import numpy as np

from trainer.config.env_vars import EnvVars, RankEnv
from trainer.errors import ConfigError
from trainer.stop import STOP, GracefulStop

logger = logging.getLogger("mlagents_like")

# MASTER_PORT under Slurm when not set: MASTER_PORT_BASE + job id mod MASTER_PORT_SPAN, below
# the simulators' ports that train.sbatch hands out (10000-32000)
MASTER_PORT_BASE, MASTER_PORT_SPAN = 9000, 1000
RESEED = 7919  # rank r's sampling / shuffling generators start from their seed + r x RESEED


class RankLost(Exception):
    """A collective failed: another rank died, hung, or left. Handled like a stop signal."""


# --------------------------------------------------------------------------------- discovery
def master_address(ranks: RankEnv, run=subprocess.run) -> tuple[str, int]:
    """(MASTER_ADDR, MASTER_PORT): as set, else under Slurm the first node of the job
    (``scontrol show hostnames``; its NodeAddr when Slurm knows one) and a port from the job id."""
    addr = ranks.master_addr
    if addr is None:
        if not ranks.job_nodelist:
            raise ConfigError("MASTER_ADDR is not set and this is not a Slurm job (no SLURM_JOB_NODELIST); "
                              "set MASTER_ADDR to rank 0's host, or start the ranks with torchrun or srun.")
        addr = _first_node_address(ranks.job_nodelist, run)
    port = ranks.master_port
    if port is None:
        if ranks.job_id is None:
            raise ConfigError("MASTER_PORT is not set and there is no SLURM_JOB_ID to derive it from; "
                              "set MASTER_PORT to a free port on rank 0's host.")
        port = MASTER_PORT_BASE + ranks.job_id % MASTER_PORT_SPAN
    return addr, port


def _first_node_address(nodelist: str, run) -> str:
    try:
        names = run(["scontrol", "show", "hostnames", nodelist], capture_output=True, text=True, check=True,
                    timeout=30).stdout.split()
    except (OSError, subprocess.SubprocessError) as error:
        if any(c in nodelist for c in "[],"):
            raise ConfigError(f"cannot expand SLURM_JOB_NODELIST={nodelist!r} ({error}); set MASTER_ADDR "
                              f"to the first node's address.") from None
        names = [nodelist]
    if not names:
        raise ConfigError(f"SLURM_JOB_NODELIST={nodelist!r} names no node; set MASTER_ADDR.")
    try:  # the address Slurm itself uses for the node, when it differs from the name
        out = run(["scontrol", "show", "node", "-o", names[0]], capture_output=True, text=True, check=True,
                  timeout=30).stdout
        for item in out.split():
            if item.startswith("NodeAddr=") and item != "NodeAddr=(null)":
                return item.split("=", 1)[1]
    except (OSError, subprocess.SubprocessError):
        pass
    return names[0]


def interface_towards(addr: str) -> str | None:
    """The name of the network interface this host would use to reach ``addr`` (Linux), or None.
    gloo otherwise binds to the address of the host name, which another network namespace or a
    multi-homed node may not reach."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((socket.gethostbyname(addr), 9))
            local = probe.getsockname()[0]
        for _, name in socket.if_nameindex():
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                try:
                    raw = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name.encode()[:15]))  # SIOCGIFADDR
                except OSError:
                    continue
            if socket.inet_ntoa(raw[20:24]) == local:
                return name
    except (OSError, AttributeError):
        return None
    return None


# --------------------------------------------------------------------------------- the split
def split(settings, world: int, per_rank: bool, where: str = "behaviors"):
    """The TrainerSettings one of ``world`` ranks trains with: buffer_size and batch_size (and
    behavioral_cloning's batch_size, when set) divided by ``world``; unchanged alone or with
    ``per_rank`` (--batch-per-rank). ConfigError (exit 2) when a value does not divide evenly."""
    if world == 1 or per_rank:
        return settings
    h = settings.hyperparameters
    for key, value in (("buffer_size", h.buffer_size), ("batch_size", h.batch_size)):
        if value % world or value < world:
            near = [n for n in (value - value % world, value - value % world + world) if n >= world]
            raise ConfigError(
                f"{where}.hyperparameters.{key} is {value}: with {world} data-parallel ranks it must be a multiple "
                f"of {world} (buffer_size and batch_size count all ranks' experiences; each rank takes 1/{world}). "
                f"Use {' or '.join(map(str, near))}, or --batch-per-rank to make both per-rank values "
                f"(docs/cluster.md).")
    memory = settings.network_settings.memory
    if memory is not None and h.batch_size // world < memory.sequence_length:
        raise ConfigError(
            f"{where}.hyperparameters.batch_size {h.batch_size} / {world} ranks = {h.batch_size // world} is "
            f"shorter than network_settings.memory.sequence_length {memory.sequence_length}: each rank's "
            f"minibatch must hold whole sequences. Raise batch_size to at least "
            f"{world * memory.sequence_length}, or use --batch-per-rank (docs/cluster.md).")
    hyperparameters = dataclasses.replace(h, buffer_size=h.buffer_size // world, batch_size=h.batch_size // world)
    bc = settings.behavioral_cloning
    if bc is not None and bc.batch_size is not None:
        bc = dataclasses.replace(bc, batch_size=max(bc.batch_size // world, 1))
    return dataclasses.replace(settings, hyperparameters=hyperparameters, behavioral_cloning=bc)


def check_split(options, world: int) -> None:
    """Refuse, before a simulator starts, a configured behavior whose buffer_size or batch_size
    the ranks cannot share (``split``'s ConfigError)."""
    if world == 1 or options.batch_per_rank:
        return
    configured = [("default_settings", options.default_settings),
                  *((f"behaviors.{name}", s) for name, s in options.behaviors.items())]
    for where, settings in configured:
        if settings is not None:
            split(settings, world, False, where)


# --------------------------------------------------------------------------------- the ranks
@dataclass
class _Brain:
    """One brain's bookkeeping shared by the ranks."""

    synced_step: int  # the step every rank agreed on last: the trainer's step between agreements
    seeds: tuple[int, int]  # this rank's sampling and shuffling seeds
    steps_by_rank: np.ndarray  # experiences each rank contributed since this process started
    joined: bool = False  # rank 0's weights were broadcast
    unsynced: int = 0  # this rank's experiences since the last agreement
    updates: int = 0


@dataclass
class Ranks:
    """This process's place among the ranks; the default is a run alone (every call a no-op)."""

    rank: int = 0
    world: int = 1
    backend: str | None = None
    device: str = "cpu"
    debug_weights: str | None = None
    sync_every: int = 1  # exchanges per agreement (MLAGENTS_LIKE_DIST_SYNC_EVERY)
    per_rank: bool = False  # --batch-per-rank: buffer_size and batch_size are each rank's (``split``)
    exchanges: int = 0
    broken: bool = False  # a collective failed: from now on everything is local
    brains: dict[str, _Brain] = field(default_factory=dict)

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def active(self) -> bool:
        return self.world > 1 and not self.broken

    # ------------------------------------------------------------------ setup
    @classmethod
    def start(cls, env_vars: EnvVars, device: str | None, per_rank: bool = False) -> "Ranks":
        """Join the process group of the launcher's ranks (blocks until all have joined, at most
        MLAGENTS_LIKE_DIST_TIMEOUT_S), or the run alone. ``per_rank``: --batch-per-rank."""
        r = env_vars.ranks
        if r.world_size == 1:
            return cls(debug_weights=env_vars.debug_weights)
        import torch.distributed as dist

        backend = "nccl" if (device or "cpu").startswith("cuda") else "gloo"
        timeout = timedelta(seconds=env_vars.dist_timeout_s)
        if r.launcher == "torchrun":  # torchrun's agent holds the rendezvous store: env://
            init, addr = "env://", r.master_addr
        else:
            addr, port = master_address(r)
            init = f"tcp://{addr}:{port}"
        if backend == "gloo" and addr and "GLOO_SOCKET_IFNAME" not in os.environ:
            interface = interface_towards(addr)
            if interface:
                os.environ["GLOO_SOCKET_IFNAME"] = interface
        if r.rank != 0:  # one console: rank 0's (warnings and errors of every rank still show)
            logger.setLevel(logging.WARNING)
        logger.info("Rank %d of %d (%s, %s over %s): waiting for the other ranks at %s.", r.rank, r.world_size,
                    r.launcher, backend, os.environ.get("GLOO_SOCKET_IFNAME", "the default interface"), init)
        try:
            dist.init_process_group(backend, init_method=init, rank=r.rank, world_size=r.world_size,
                                    timeout=timeout)
        except (RuntimeError, ValueError) as error:
            raise RankLost(f"rank {r.rank} could not join the other ranks at {init}: {error}") from None
        STOP.deferred = True  # stop signals are acted on in ``agree``, by every rank at once
        ranks = cls(rank=r.rank, world=r.world_size, backend=backend,
                    device=f"cuda:{r.local_rank}" if backend == "nccl" else "cpu",
                    debug_weights=env_vars.debug_weights, sync_every=env_vars.dist_sync_every, per_rank=per_rank)
        if backend == "nccl":
            import torch

            torch.cuda.set_device(r.local_rank)
        logger.info("%d data-parallel ranks joined; rank 0 writes every file. %s (docs/cluster.md).", r.world_size,
                    f"--batch-per-rank: buffer_size and batch_size are each rank's, an update uses {r.world_size} x "
                    f"buffer_size experiences, each gradient step {r.world_size} x batch_size" if per_rank else
                    f"buffer_size and batch_size count all ranks' experiences: each rank collects and steps "
                    f"on 1/{r.world_size} of them")
        return ranks

    def close(self) -> None:
        if self.world > 1:
            import torch.distributed as dist

            if dist.is_initialized():
                dist.destroy_process_group()

    # ------------------------------------------------------------------ a new brain
    def settings_for(self, settings, brain: str):
        """The settings this rank trains ``brain`` with (``split``)."""
        return split(settings, self.world, self.per_rank, f"behaviors.{brain}")

    def wire(self, trainer) -> None:
        """With other ranks: ``trainer``'s gradients are averaged (every optimiser's ``reduce``)
        and its advantages normalised over all ranks' buffers (``sum_across_ranks``)."""
        for optimizer in trainer.optimizers():
            optimizer.reduce = self.average_
        trainer.sum_across_ranks = self.sum_

    def adopt(self, runner) -> None:
        """A brain this rank has just created: only rank 0 writes its files; with other ranks,
        gradients are averaged, normaliser updates wait for ``agree``, and this rank samples
        and shuffles with seeds of its own. Its weights come from rank 0 at the next ``agree``."""
        runner.writes_files = self.is_main
        if self.world == 1:
            return
        trainer = runner.trainer
        self.wire(trainer)
        for normalizer in trainer.normalizers():
            normalizer.defer()
        seeds = (trainer.policy.generator.initial_seed() + RESEED * self.rank,
                 trainer.shuffle_generator.initial_seed() + RESEED * self.rank)
        self.brains[runner.brain] = _Brain(trainer.step, seeds, np.zeros(self.world, dtype=np.int64))
        self._reseed(runner)
        if self.is_main:
            h = trainer.hyperparams
            logger.info("%s: %d ranks x buffer_size %d and batch_size %d each (%s): %d experiences per update, "
                        "%d per gradient step.", runner.brain, self.world, h.buffer_size, h.batch_size,
                        "--batch-per-rank" if self.per_rank else "the YAML's split evenly",
                        h.buffer_size * self.world, h.batch_size * self.world)

    def _reseed(self, runner) -> None:
        if self.rank:
            sampling, shuffling = self.brains[runner.brain].seeds
            runner.trainer.policy.reseed_noise(sampling)
            runner.trainer.shuffle_generator.manual_seed(shuffling)

    # ------------------------------------------------------------------ once per exchange
    def agree(self, runners: dict) -> dict[str, int | None]:
        """The brains to update now, each with the buffer length all ranks use (None alone: the
        whole buffer). With other ranks, at every ``sync_every``-th exchange (the same ones on
        every rank: they step their simulators in lockstep, one call per exchange): a stop on any
        rank raises GracefulStop on all; step counts and normalisers are merged; a brain every
        rank knows is joined. Between agreements a trainer's step stays the agreed one (this
        rank's new experiences wait in ``unsynced``), so everything decided from the step
        (max_steps, summaries, checkpoints) happens at the same exchange on every rank."""
        if not self.active:
            return {b: None for b, r in runners.items() if not r.done and r.trainer.ready_to_update()}
        import torch

        for name, runner in runners.items():
            brain = self.brains[name]
            brain.unsynced += runner.trainer.step - brain.synced_step
            runner.trainer.step = brain.synced_step
        self.exchanges += 1
        if (self.exchanges - 1) % self.sync_every:  # the 1st exchange, then every sync_every-th
            return {}
        names = sorted(runners)
        header = np.array([float(STOP.requested is not None), float(zlib.crc32("\n".join(names).encode())),
                           float(len(names))])
        rows = self._all_gather(header)
        if rows[:, 0].max() > 0:
            STOP.raised = True
            raise GracefulStop(STOP.requested or "stop on another rank")
        if not names or (rows[:, 1:] != rows[0, 1:]).any():
            return {}  # some rank has not met every brain yet: collect on
        for name in names:
            if not self.brains[name].joined:
                self._join(runners[name])
        parts = []
        for name in names:
            trainer, brain = runners[name].trainer, self.brains[name]
            parts.append(np.array([brain.unsynced, len(trainer.buffer)], dtype=np.float64))
            brain.unsynced = 0
            parts += [n.take_pending().numpy() for n in trainer.normalizers()]
        rows = self._all_gather(np.concatenate(parts))
        updates: dict[str, int | None] = {}
        at = 0
        for name in names:
            runner, brain = runners[name], self.brains[name]
            trainer = runner.trainer
            added = rows[:, at].astype(np.int64)
            brain.steps_by_rank += added
            brain.synced_step += int(added.sum())
            trainer.step = brain.synced_step
            shortest = int(rows[:, at + 1].min())
            at += 2
            for normalizer in trainer.normalizers():
                size = normalizer.running_mean.shape[0]
                total = torch.from_numpy(rows[:, at:at + 1 + 2 * size].sum(axis=0))
                normalizer.apply(int(total[0]), total[1:1 + size], total[1 + size:])
                at += 1 + 2 * size
            if not runner.done and shortest > trainer.hyperparams.buffer_size:
                updates[name] = shortest
        return updates

    def _join(self, runner) -> None:
        """Every rank has this brain: rank 0's state (weights, moments, normalisers, step,
        schedule) goes to all. What the others collected before is dropped (it was judged by
        their own first weights): at most the first exchange's trajectories."""
        brain, trainer = self.brains[runner.brain], runner.trainer
        sent = None
        if self.is_main:
            sent = {"state": trainer.state_dict(), "step": brain.synced_step,
                    "next_summary": runner.next_summary, "next_checkpoint": runner.next_checkpoint}
        sent = self._broadcast(sent)
        brain.joined = True
        if self.is_main:
            return
        trainer.load_state_dict(sent["state"])
        trainer.step = brain.synced_step = sent["step"]
        brain.unsynced = 0
        runner.next_summary, runner.next_checkpoint = sent["next_summary"], sent["next_checkpoint"]
        trainer.buffer.clear()
        for normalizer in trainer.normalizers():
            normalizer.defer()
        self._reseed(runner)

    # ------------------------------------------------------------------ summaries, updates
    def gather_stats(self, reporter, brain: str) -> None:
        """Every rank's statistics of ``brain`` since the last summary into rank 0's reporter,
        with the experience each rank contributed (``Ranks/Steps of rank r``)."""
        if not self.active:
            return
        import torch.distributed as dist

        mine = None if self.is_main else reporter.take(brain)
        gathered = [None] * self.world if self.is_main else None
        self._collective(dist.gather_object, mine, gathered, dst=0)
        if self.is_main:
            for other in gathered[1:]:
                reporter.merge(brain, other)
            counts = self.brains[brain].steps_by_rank
            for r, steps in enumerate(counts):
                reporter.set(brain, f"Ranks/Steps of rank {r}", float(steps))
            logger.info("%s: experiences per rank since start: %s", brain,
                        ", ".join(f"rank {r}: {int(s)}" for r, s in enumerate(counts)))

    def after_update(self, runner) -> None:
        """MLAGENTS_LIKE_DEBUG_WEIGHTS: append '<update> <step> <sha256 of the weights and
        normalisers>' to <path>.rank<r>."""
        if self.debug_weights is None:
            return
        brain = self.brains.get(runner.brain)
        count = 0
        if brain is not None:
            brain.updates += 1
            count = brain.updates
        digest = hashlib.sha256()
        for module in (runner.trainer.policy.actor, runner.trainer.critic):
            for key, tensor in sorted(module.state_dict().items()):
                digest.update(key.encode())
                digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
        with open(f"{self.debug_weights}.rank{self.rank}", "a", encoding="utf-8") as out:
            out.write(f"{runner.brain} {count} {runner.trainer.step} {digest.hexdigest()}\n")

    # ------------------------------------------------------------------ collectives
    def average_(self, flat: np.ndarray) -> None:
        """Replace ``flat`` (float32, this rank's gradients) by the mean over the ranks."""
        if not self.active:
            return
        import torch
        import torch.distributed as dist

        tensor = torch.from_numpy(flat)  # zero-copy
        if self.backend == "nccl":
            on_device = tensor.to(self.device)
            self._collective(dist.all_reduce, on_device)
            tensor.copy_(on_device.cpu())
        else:
            self._collective(dist.all_reduce, tensor)
        flat /= np.float32(self.world)

    def sum_(self, values: np.ndarray) -> np.ndarray:
        """The sum over the ranks of ``values`` (float64; alone: ``values``)."""
        if not self.active:
            return values
        import torch
        import torch.distributed as dist

        tensor = torch.from_numpy(np.array(values, dtype=np.float64)).to(self.device)
        self._collective(dist.all_reduce, tensor)
        return tensor.cpu().numpy()

    def _all_gather(self, row: np.ndarray) -> np.ndarray:
        """Every rank's ``row`` (float64, the same length on every rank) as [world, length]."""
        import torch
        import torch.distributed as dist

        mine = torch.from_numpy(np.ascontiguousarray(row, dtype=np.float64)).to(self.device)
        out = [torch.empty_like(mine) for _ in range(self.world)]
        self._collective(dist.all_gather, out, mine)
        return np.stack([t.cpu().numpy() for t in out])

    def _broadcast(self, obj):
        import torch.distributed as dist

        box = [obj]
        self._collective(dist.broadcast_object_list, box, src=0)
        return box[0]

    def _collective(self, call, *args, **kwargs) -> None:
        try:
            call(*args, **kwargs)
        except (RuntimeError, ValueError) as error:  # gloo / NCCL errors, timeouts included
            self.broken = True
            reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
            raise RankLost(f"rank {self.rank}: another rank is gone ({reason})") from None
