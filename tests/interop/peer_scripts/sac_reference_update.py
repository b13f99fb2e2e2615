"""Runs INSIDE .venv-interop: the real mlagents 1.1.0 SAC optimizer's ``update`` on the weights and
minibatches that tests/interop/test_sac_matches_reference.py prepared with our trainer.
argv[1]: JSON {"npz": path}. The .npz holds the action spec, every network's initial weights (in
named_parameters order), the minibatches and the noise seed of each step, and our trainer's
statistics and weights after them. Prints one JSON line: the reference's statistics per step and
the largest weight difference per module after the last step."""
import json
import sys

import numpy as np
import torch
from mlagents.trainers.buffer import AgentBuffer, BufferKey, RewardSignalUtil
from mlagents.trainers.policy.torch_policy import TorchPolicy
from mlagents.trainers.sac.optimizer_torch import SACSettings, TorchSACOptimizer
from mlagents.trainers.settings import NetworkSettings, RewardSignalSettings, RewardSignalType, ScheduleType, TrainerSettings
from mlagents.trainers.torch_entities.networks import SimpleActor
from mlagents.trainers.trajectory import ObsUtil
from mlagents_envs.base_env import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType

d = dict(np.load(json.loads(sys.argv[1])["npz"]))
continuous, branches = int(d["continuous"]), tuple(int(b) for b in d["branches"])
obs_size, hidden, steps = int(d["obs_size"]), int(d["hidden"]), int(d["steps"])
spec = BehaviorSpec([ObservationSpec((obs_size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v")],
                    ActionSpec(continuous, branches))
h = d["hyper"]  # lr, init_entcoef, tau, gamma, batch
settings = TrainerSettings(
    trainer_type="sac",
    hyperparameters=SACSettings(batch_size=int(h[4]), buffer_size=1000, learning_rate=float(h[0]),
                                learning_rate_schedule=ScheduleType.CONSTANT, buffer_init_steps=0, tau=float(h[2]),
                                steps_per_update=1.0, init_entcoef=float(h[1])),
    network_settings=NetworkSettings(normalize=False, hidden_units=hidden, num_layers=2),
    reward_signals={RewardSignalType.EXTRINSIC: RewardSignalSettings(gamma=float(h[3]), strength=1.0)})
policy = TorchPolicy(1, spec, settings.network_settings, SimpleActor, {"conditional_sigma": True, "tanh_squash": True})
opt = TorchSACOptimizer(policy, settings)
modules = {"actor": policy.actor, "critic": opt._critic, "q1": opt.q_network.q1_network,
           "q2": opt.q_network.q2_network, "target": opt.target_network}


def trained(module):
    return [p for _, p in module.named_parameters() if p.requires_grad]


with torch.no_grad():
    for name, module in modules.items():
        params = trained(module)
        assert len(params) == int(d[f"count/{name}"]), (name, [n for n, p in module.named_parameters() if p.requires_grad])
        for i, p in enumerate(params):
            p.copy_(torch.as_tensor(d[f"init/{name}/{i}"]))
    if branches:
        opt._log_ent_coef.discrete.copy_(torch.as_tensor(d["init/log_alpha_d"]))
    if continuous:
        opt._log_ent_coef.continuous.copy_(torch.as_tensor(d["init/log_alpha_c"]))

report = {"stats": []}
for k in range(steps):
    n = len(d[f"b{k}/rewards"])
    batch = AgentBuffer()
    batch[ObsUtil.get_name_at(0)].extend(list(d[f"b{k}/obs"]))
    batch[ObsUtil.get_name_at_next(0)].extend(list(d[f"b{k}/next_obs"]))
    batch[BufferKey.CONTINUOUS_ACTION].extend(list(d[f"b{k}/continuous"]))
    batch[BufferKey.DISCRETE_ACTION].extend(list(d[f"b{k}/discrete"]))
    batch[BufferKey.ACTION_MASK].extend(list(1.0 - d[f"b{k}/masks"].astype(np.float32)))  # 1 = allowed here
    batch[BufferKey.MASKS].extend([1.0] * n)
    batch[BufferKey.DONE].extend(list(d[f"b{k}/done"]))
    batch[RewardSignalUtil.rewards_key("extrinsic")].extend(list(d[f"b{k}/rewards"]))
    torch.manual_seed(int(d[f"b{k}/seed"]))  # the policy's reparameterised sample: its first draw
    report["stats"].append(opt.update(batch, n))
report["weights"] = {}
for name, module in modules.items():
    report["weights"][name] = max(float(np.max(np.abs(p.detach().numpy() - d[f"after/{name}/{i}"])))
                                  for i, p in enumerate(trained(module)))
if branches:
    report["weights"]["log_alpha_d"] = float(np.max(np.abs(opt._log_ent_coef.discrete.detach().numpy() - d["after/log_alpha_d"])))
if continuous:
    report["weights"]["log_alpha_c"] = float(np.max(np.abs(opt._log_ent_coef.continuous.detach().numpy() - d["after/log_alpha_c"])))
print(json.dumps(report))
