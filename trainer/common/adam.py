"""Adam, the one optimiser of every network here (actor and critic on both update paths,
curiosity, RND): numpy arithmetic on the torch parameters' own storage.

Update, per parameter p with gradient g at step t (bias-corrected, no weight decay, no amsgrad,
as torch.optim.Adam with default betas and eps, which ML-Agents' PPO uses):
    m = b1*m + (1-b1)*g ;  v = b2*v + (1-b2)*g^2
    p -= lr * (m / (1-b1^t)) / (sqrt(v) / sqrt(1-b2^t) + eps)

The moments of all parameters are two flat float32 vectors; the parameters are written through
numpy views of the torch tensors (no copies to keep in step). Each parameter's stretch of the
vectors follows its memory order, not its index order: Linear kernels are stored input-major
(layers.py), and a step writes them contiguously (a strided write of a 128 x 128 kernel took 44 us
against 2 us). Gradients come either from autograd (``step``: ``param.grad``, laid out as its
parameter) or from the hand-written backward of numpy_update.py (``Stretch.step``: arrays, best
laid out as their parameters, for a contiguous run of the parameters, e.g. the critic's alone).
``state_dict`` has torch.optim.Adam's layout, so checkpoints load into torch.optim.Adam and back.

Why not torch.optim.Adam: for networks this small its per-step overhead is several times this
class's whole step, and an update takes hundreds of minibatch steps per network, so it would add
about half again to a ball3d update and more than double a basic one; constructing the first
torch.optim optimizer also imports torch._dynamo, seconds at every start. The measurements:
docs/performance.md, "The PPO update in numpy and on two CPUs".
tests/unit/test_ppo_adam.py compares this class with torch.optim.Adam step by step.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import torch


class Adam:
    def __init__(self, params: Iterable[torch.nn.Parameter], lr: float = 1e-3,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        self.params = list(params)
        self.param_groups = [{"lr": float(lr), "betas": tuple(betas), "eps": float(eps)}]
        self.step_count = 0
        sizes = [p.numel() for p in self.params]
        ends = np.cumsum(sizes).tolist()
        self.bounds = list(zip([0] + ends[:-1], ends))  # each parameter's stretch of the moments
        self.exp_avg = np.zeros(sum(sizes), dtype=np.float32)
        self.exp_avg_sq = np.zeros(sum(sizes), dtype=np.float32)
        # each parameter's axes from the largest stride to the smallest: transposed so, it is
        # contiguous (see ``flat``)
        self.orders = [tuple(np.argsort([-stride for stride in p.stride()], kind="stable")) for p in self.params]
        # live numpy views of the parameters, flat in memory order (the optimizer is built after
        # the modules reached their device, and torch updates parameters in place, so the views
        # stay valid); a network on a GPU (--torch-device) is copied to the CPU and back around
        # each step
        self.on_cpu = all(p.device.type == "cpu" for p in self.params)
        self.arrays = None
        if self.on_cpu:
            self.arrays = [self.flat(p.detach().numpy(), i) for i, p in enumerate(self.params)]
            if not all(np.may_share_memory(a, p.detach().numpy()) for a, p in zip(self.arrays, self.params)):
                raise ValueError("Adam needs parameters whose elements are dense in memory (no views with gaps)")
        self._all = Stretch(self, 0, len(self.params))
        # data-parallel ranks (trainer/distributed.py): averages a step's flat gradient buffer
        # across the ranks, in place, just before the step uses it; None alone (no cost)
        self.reduce = None

    def flat(self, array: np.ndarray, index: int) -> np.ndarray:
        """``array`` shaped as parameter ``index``, flat in that parameter's memory order (a view
        when ``array`` is laid out as the parameter, else a copy)."""
        return np.transpose(array, self.orders[index]).reshape(-1)

    def logical(self, flat: np.ndarray, index: int) -> np.ndarray:
        """The inverse of ``flat``: parameter ``index``'s shape, C-contiguous."""
        order = self.orders[index]
        shape = self.params[index].shape
        stored = flat.reshape([shape[axis] for axis in order])
        return np.ascontiguousarray(np.transpose(stored, np.argsort(order)))

    def stretch(self, params: Iterable[torch.nn.Parameter]) -> "Stretch":
        """The run of this optimizer's parameters that ``params`` are, in this order."""
        params = list(params)
        if not params:
            return Stretch(self, 0, 0)
        first = next((i for i, p in enumerate(self.params) if p is params[0]), None)
        if first is None or [id(p) for p in self.params[first:first + len(params)]] != list(map(id, params)):
            raise ValueError("these parameters are not a contiguous run of the optimizer's")
        return Stretch(self, first, first + len(params))

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    def step(self) -> None:
        """One step from the gradients autograd left in ``param.grad`` (parameters without one
        keep their values and moments, as in torch.optim.Adam)."""
        live = [p.grad is not None for p in self.params]
        if not any(live):
            return
        self.step_count += 1
        if all(live):
            self._all.step([p.grad.cpu().numpy() for p in self.params], self.step_count)
            return
        for index, (p, has_grad) in enumerate(zip(self.params, live)):
            if has_grad:
                Stretch(self, index, index + 1).step([p.grad.cpu().numpy()], self.step_count)

    # torch.optim.Adam's state_dict layout: parameters are numbered in order
    def state_dict(self) -> dict[str, Any]:
        group = self.param_groups[0]
        state = {}
        if self.step_count > 0:
            for i, (start, end) in enumerate(self.bounds):
                state[i] = {"step": torch.tensor(float(self.step_count)),
                            "exp_avg": torch.from_numpy(self.logical(self.exp_avg[start:end], i)),
                            "exp_avg_sq": torch.from_numpy(self.logical(self.exp_avg_sq[start:end], i))}
        return {
            "state": state,
            "param_groups": [{
                "lr": group["lr"], "betas": group["betas"], "eps": group["eps"], "weight_decay": 0,
                "amsgrad": False, "maximize": False, "foreach": None, "capturable": False,
                "differentiable": False, "fused": None, "params": list(range(len(self.params))),
            }],
        }

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        groups = state_dict["param_groups"]
        if len(groups) != 1 or len(groups[0]["params"]) != len(self.params):
            raise ValueError(
                f"optimizer state has {sum(len(g['params']) for g in groups)} parameters, "
                f"this network has {len(self.params)}"
            )
        state = state_dict["state"]
        for i, p in enumerate(self.params):
            s = state.get(i) if i in state else state.get(str(i))
            if s is not None and tuple(s["exp_avg"].shape) != tuple(p.shape):
                raise ValueError(f"optimizer state for parameter {i} has shape {tuple(s['exp_avg'].shape)}, "
                                 f"the network's is {tuple(p.shape)}")
        group = groups[0]
        self.param_groups[0].update(lr=float(group["lr"]), betas=tuple(group["betas"]), eps=float(group["eps"]))
        self.step_count = 0
        for i, (start, end) in enumerate(self.bounds):
            s = state.get(i) if i in state else state.get(str(i))
            if s is None:
                self.exp_avg[start:end] = 0.0
                self.exp_avg_sq[start:end] = 0.0
                continue
            self.exp_avg[start:end] = self.flat(s["exp_avg"].detach().cpu().numpy(), i)
            self.exp_avg_sq[start:end] = self.flat(s["exp_avg_sq"].detach().cpu().numpy(), i)
            self.step_count = max(self.step_count, int(float(s["step"])))


class Stretch:
    """Parameters ``first`` to ``end`` - 1 of an Adam and their run of its moment vectors
    (views: stepping a stretch updates the optimizer's moments and the parameters). ``arrays``:
    the parameters as flat views in memory order."""

    def __init__(self, adam: Adam, first: int, end: int) -> None:
        self.adam, self.first = adam, first
        self.params = adam.params[first:end]
        self.arrays = adam.arrays[first:end] if adam.on_cpu else None
        start, stop = (adam.bounds[first][0], adam.bounds[end - 1][1]) if end > first else (0, 0)
        self.bounds = [(lo - start, hi - start) for lo, hi in adam.bounds[first:end]]
        self.exp_avg, self.exp_avg_sq = adam.exp_avg[start:stop], adam.exp_avg_sq[start:stop]
        self._grad = np.empty_like(self.exp_avg)
        self._scratch = np.empty_like(self.exp_avg)  # the one temporary

    def step(self, grads: list[np.ndarray], t: int) -> None:
        """One Adam step number ``t`` (bias correction) with ``grads``, one per parameter of the
        stretch, in order, each of its parameter's shape. The learning rate is param_groups[0]'s."""
        group = self.adam.param_groups[0]
        (beta1, beta2), eps, lr = group["betas"], group["eps"], group["lr"]
        g, flat = self._grad, self.adam.flat
        for index, (grad, (start, end)) in enumerate(zip(grads, self.bounds), self.first):
            g[start:end] = flat(grad, index)
        if self.adam.reduce is not None:
            self.adam.reduce(g)
        m, v = self.exp_avg, self.exp_avg_sq
        step = np.subtract(g, m, out=self._scratch)  # m += (1 - beta1) * (g - m)
        step *= 1 - beta1
        m += step
        v *= beta2
        np.multiply(g, 1 - beta2, out=step)  # v += (1 - beta2) * g * g
        step *= g
        v += step
        update = np.sqrt(v, out=step)  # m / (sqrt(v) / sqrt(1 - beta2^t) + eps)
        update /= math.sqrt(1 - beta2 ** t)
        update += eps
        np.divide(m, update, out=update)
        update *= lr / (1 - beta1 ** t)
        arrays = self.arrays if self.arrays is not None else [
            flat(p.detach().cpu().numpy(), index) for index, p in enumerate(self.params, self.first)]
        for array, (start, end) in zip(arrays, self.bounds):
            array -= update[start:end]
        if self.arrays is None:  # not on the CPU: write the stepped copies back
            with torch.no_grad():
                for index, (p, array) in enumerate(zip(self.params, arrays), self.first):
                    p.copy_(torch.from_numpy(self.adam.logical(array, index)))
