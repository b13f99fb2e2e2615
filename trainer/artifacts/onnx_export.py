"""Export a policy's actor to the ONNX model Unity's inference engine loads (docs/outputs.md, "The ONNX model").

Legacy TorchScript exporter, opset 9. Inputs obs_0..obs_{n-1} (+ action_masks, float 1 = allowed, only
with discrete branches; + recurrent_in [batch, 1, memory_size], only with memory). Outputs, in order:
version_number, memory_size, then for continuous actions continuous_actions /
continuous_action_output_shape / deterministic_continuous_actions, then for discrete actions
discrete_actions / discrete_action_output_shape / deterministic_discrete_actions, then with memory
recurrent_out [batch, 1, memory_size] (h then c, as Unity feeds back into recurrent_in).
Sampling (RandomNormalLike, Multinomial) and observation normalisation happen inside the graph.
"""
from __future__ import annotations

import copy
import io
import os
import warnings

import torch
# torch loads torch.onnx on first use: imported with this module, it loads in the background import
# (trainer/warmup.py), not at the run's first export, which the end of a short run waits for
# (38 modules, 0.07 CPU-s of the first export's 0.12; docs/performance.md, "Start-up and exit")
import torch.onnx  # noqa: F401
from torch import nn

from trainer.artifacts.atomic import atomic_write
from trainer.common.networks import Actor
from trainer.common.policy import CONTINUOUS_CLIP, Policy

ONNX_OPSET = 9
BATCH_AXIS = "batch"


class ExportableActor(nn.Module):
    """Wraps an Actor with the positional inputs and tuple outputs the ONNX contract names."""

    def __init__(self, actor: Actor, n_obs: int):
        super().__init__()
        self.actor = actor
        self.n_obs = n_obs
        self.has_discrete = len(actor.action_spec.discrete_branches) > 0
        self.has_memory = actor.network_body.lstm is not None

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        observations = list(inputs[: self.n_obs])
        allowed = inputs[self.n_obs] if self.has_discrete else None
        memories_out = None
        if self.has_memory:  # [batch, 1, m] in the graph's interface, [1, batch, m] for the LSTM
            memories = torch.transpose(inputs[-1], 0, 1)
            encoding, memories_out = self.actor.network_body.forward_memory(observations, memories, 1)
        else:
            encoding = self.actor.network_body(observations)
        mu, logits = self.actor.heads_of(encoding, allowed)
        outputs = [self.actor.version_number, self.actor.memory_size_vector]
        if mu is not None:
            sigma = torch.exp(self.actor.log_sigma_of(encoding, mu))
            sample = mu + torch.randn_like(mu) * sigma
            if self.actor.squashed:  # SAC: tanh of the sample; deterministic tanh(mu) (docs/sac.md)
                outputs += [torch.tanh(sample), self.actor.continuous_act_size_vector, torch.tanh(mu)]
            else:
                outputs += [
                    torch.clamp(sample, -CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP,
                    self.actor.continuous_act_size_vector,
                    torch.clamp(mu, -CONTINUOUS_CLIP, CONTINUOUS_CLIP) / CONTINUOUS_CLIP,
                ]
        if logits:
            probs = [torch.softmax(branch, dim=1) for branch in logits]
            outputs += [
                torch.cat([torch.multinomial(p, 1) for p in probs], dim=1),
                self.actor.discrete_act_size_vector,
                torch.cat([torch.argmax(p, dim=1, keepdim=True) for p in probs], dim=1),
            ]
        if memories_out is not None:
            outputs.append(torch.transpose(memories_out, 0, 1))
        return tuple(outputs)


def _names(policy: Policy) -> tuple[list[str], list[str]]:
    spec = policy.action_spec
    inputs = [f"obs_{i}" for i in range(len(policy.behavior_spec.observation_specs))]
    outputs = ["version_number", "memory_size"]
    if spec.continuous_size > 0:
        outputs += ["continuous_actions", "continuous_action_output_shape", "deterministic_continuous_actions"]
    if spec.discrete_branches:
        inputs.append("action_masks")
        outputs += ["discrete_actions", "discrete_action_output_shape", "deterministic_discrete_actions"]
    if policy.memory_size:
        inputs.append("recurrent_in")
        outputs.append("recurrent_out")
    return inputs, outputs


def export_to_bytes(policy: Policy) -> bytes:
    """Serialize the policy's actor to ONNX bytes (CPU copy; the live actor is not touched)."""
    actor = copy.deepcopy(policy.actor).to("cpu").eval()
    n_obs = len(policy.behavior_spec.observation_specs)
    dummy = [torch.zeros((1, *spec.shape)) for spec in policy.behavior_spec.observation_specs]
    if policy.action_spec.discrete_branches:
        dummy.append(torch.ones((1, sum(policy.action_spec.discrete_branches))))
    if policy.memory_size:
        dummy.append(torch.zeros((1, 1, policy.memory_size)))
    input_names, output_names = _names(policy)
    dynamic_axes = {name: {0: BATCH_AXIS} for name in input_names}
    for name in ("continuous_actions", "discrete_actions", "recurrent_out"):
        if name in output_names:
            dynamic_axes[name] = {0: BATCH_AXIS}
    buffer = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            ExportableActor(actor, n_obs), tuple(dummy), buffer,
            opset_version=ONNX_OPSET, input_names=input_names, output_names=output_names,
            dynamic_axes=dynamic_axes, dynamo=False,
        )
    return buffer.getvalue()


def export_policy(policy: Policy, path: str | os.PathLike[str]) -> None:
    """Write ``path`` (.onnx) atomically: a temp file in the same folder, fsync, then os.replace."""
    payload = export_to_bytes(policy)
    atomic_write(path, lambda f: f.write(payload))
