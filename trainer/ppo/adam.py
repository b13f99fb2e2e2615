"""Plain Adam, the update ML-Agents' PPO uses (torch.optim.Adam with default betas and eps).

Why not torch.optim.Adam itself: constructing any torch.optim optimizer imports torch._dynamo,
which costs ~2 s at every trainer start on this class of machine (measured with -X importtime;
the whole of `import torch` is ~1.5 s). This class does the same arithmetic with torch's
multi-tensor (_foreach) kernels, and its state_dict has torch's layout, so checkpoints load
into torch.optim.Adam and back. tests/unit/test_ppo_adam.py compares it step by step.

Update, per parameter p with gradient g at step t (bias-corrected, no weight decay, no amsgrad):
    m = b1*m + (1-b1)*g ;  v = b2*v + (1-b2)*g^2
    p -= lr * (m / (1-b1^t)) / (sqrt(v / (1-b2^t)) + eps)
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import torch


class Adam:
    def __init__(self, params: Iterable[torch.nn.Parameter], lr: float = 1e-3,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        self.params = [p for p in params]
        self.param_groups = [{"lr": float(lr), "betas": tuple(betas), "eps": float(eps)}]
        self.step_count = 0
        self.exp_avg = [torch.zeros_like(p, memory_format=torch.preserve_format) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p, memory_format=torch.preserve_format) for p in self.params]

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        group = self.param_groups[0]
        lr, (beta1, beta2), eps = group["lr"], group["betas"], group["eps"]
        live = [i for i, p in enumerate(self.params) if p.grad is not None]
        if not live:
            return
        params = [self.params[i] for i in live]
        grads = [self.params[i].grad for i in live]
        exp_avg = [self.exp_avg[i] for i in live]
        exp_avg_sq = [self.exp_avg_sq[i] for i in live]
        self.step_count += 1
        t = self.step_count
        torch._foreach_lerp_(exp_avg, grads, 1 - beta1)
        torch._foreach_mul_(exp_avg_sq, beta2)
        torch._foreach_addcmul_(exp_avg_sq, grads, grads, 1 - beta2)
        bias1 = 1 - beta1 ** t
        bias2_sqrt = math.sqrt(1 - beta2 ** t)
        denom = torch._foreach_sqrt(exp_avg_sq)
        torch._foreach_div_(denom, bias2_sqrt)
        torch._foreach_add_(denom, eps)
        torch._foreach_addcdiv_(params, exp_avg, denom, -lr / bias1)

    # torch.optim.Adam's state_dict layout: parameters are numbered in order
    def state_dict(self) -> dict[str, Any]:
        group = self.param_groups[0]
        state = {
            i: {"step": torch.tensor(float(self.step_count)), "exp_avg": self.exp_avg[i].clone(),
                "exp_avg_sq": self.exp_avg_sq[i].clone()}
            for i in range(len(self.params)) if self.step_count > 0
        }
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
        group = groups[0]
        self.param_groups[0].update(lr=float(group["lr"]), betas=tuple(group["betas"]), eps=float(group["eps"]))
        state = state_dict["state"]
        self.step_count = 0
        for i, p in enumerate(self.params):
            s = state.get(i) if i in state else state.get(str(i))
            if s is None:
                self.exp_avg[i] = torch.zeros_like(p)
                self.exp_avg_sq[i] = torch.zeros_like(p)
                continue
            if s["exp_avg"].shape != p.shape:
                raise ValueError(f"optimizer state for parameter {i} has shape {tuple(s['exp_avg'].shape)}, "
                                 f"the network's is {tuple(p.shape)}")
            self.exp_avg[i] = s["exp_avg"].to(p.device, p.dtype).clone()
            self.exp_avg_sq[i] = s["exp_avg_sq"].to(p.device, p.dtype).clone()
            self.step_count = max(self.step_count, int(float(s["step"])))
