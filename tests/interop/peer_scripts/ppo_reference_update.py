"""Runs INSIDE .venv-interop: the real mlagents 1.1.0 PPO on the weights, trajectories and minibatch
that tests/interop/test_ppo_matches_reference.py prepared with our trainer (argv[1], an .npz).
Prints one JSON line with the largest differences it found."""
import numpy as np, torch  # noqa: E401
from mlagents.trainers.settings import TrainerSettings, NetworkSettings, RewardSignalSettings, RewardSignalType, ScheduleType
from mlagents.trainers.ppo.trainer import PPOSettings, get_gae
from mlagents.trainers.policy.torch_policy import TorchPolicy
from mlagents.trainers.ppo.optimizer_torch import TorchPPOOptimizer
from mlagents.trainers.torch_entities.networks import SimpleActor
from mlagents.trainers.buffer import AgentBuffer, BufferKey, RewardSignalUtil
from mlagents.trainers.trajectory import ObsUtil
from mlagents_envs.base_env import BehaviorSpec, ObservationSpec, DimensionProperty, ObservationType, ActionSpec
import json, sys
d = dict(np.load(sys.argv[1]))
spec = BehaviorSpec([ObservationSpec((8,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v")], ActionSpec(2, ()))
ts = TrainerSettings(hyperparameters=PPOSettings(batch_size=64, buffer_size=200, learning_rate=3e-4, beta=5e-3, epsilon=0.2,
                                                 lambd=0.95, num_epoch=1),
                     network_settings=NetworkSettings(normalize=True, hidden_units=16, num_layers=2),
                     reward_signals={RewardSignalType.EXTRINSIC: RewardSignalSettings(gamma=0.99, strength=1.0)},
                     max_steps=1_000_000)
pol = TorchPolicy(1, spec, ts.network_settings, SimpleActor, {"conditional_sigma": False, "tanh_squash": False})
opt = TorchPPOOptimizer(pol, ts)
def load(prefix):
    for tag, mod in (("actor/", pol.actor), ("critic/", opt.critic)):
        sd = mod.state_dict()
        for k in list(sd):
            key = prefix + tag + k.replace("network_body.processors.0.", "network_body.observation_encoder.processors.0.")
            if key in d:
                sd[k] = torch.as_tensor(d[key])
        mod.load_state_dict(sd)
load("init/")
def worst(prefix):
    w = 0.0
    for tag, mod in (("actor/", pol.actor), ("critic/", opt.critic)):
        for k, v in mod.state_dict().items():
            key = prefix + tag + k.replace("network_body.processors.0.", "network_body.observation_encoder.processors.0.")
            if key in d:
                w = max(w, float(np.max(np.abs(v.numpy() - d[key]))))
    return w
update_buffer = AgentBuffer()
values_seen = []
for i in range(4):
    obs, rew, act, logp = d[f"traj{i}/obs"], d[f"traj{i}/rew"], d[f"traj{i}/act"], d[f"traj{i}/logp"]
    done, interrupted = d[f"traj{i}/flags"]
    b = AgentBuffer()
    for t in range(len(rew)):
        b[ObsUtil.get_name_at(0)].append(obs[t])
        b[BufferKey.CONTINUOUS_ACTION].append(act[t]); b[BufferKey.DISCRETE_ACTION].append(np.zeros(0, np.int32))
        b[BufferKey.CONTINUOUS_LOG_PROBS].append(logp[t]); b[BufferKey.DISCRETE_LOG_PROBS].append(np.zeros(0, np.float32))
        b[BufferKey.ENVIRONMENT_REWARDS].append(rew[t]); b[BufferKey.MASKS].append(True)
        b[BufferKey.ACTION_MASK].append(np.ones(0, np.float32))
    pol.actor.update_normalization(b)
    opt.critic.update_normalization(b)
    values, value_next, _ = opt.get_trajectory_value_estimates(b, [d[f"traj{i}/next"]], bool(done and not interrupted))
    v = values["extrinsic"]
    adv = get_gae(rewards=rew, value_estimates=v, value_next=value_next["extrinsic"], gamma=0.99, lambd=0.95)
    # exactly what mlagents 1.1.0's _process_trajectory does: value estimates go under
    # value_estimates_key, which IS returns_key, and are then replaced by the returns
    b[RewardSignalUtil.value_estimates_key("extrinsic")].extend(v)
    b[RewardSignalUtil.returns_key("extrinsic")].set(adv + v)
    values_seen.append(v)
    b[BufferKey.ADVANTAGES].extend(adv)
    b.resequence_and_append(update_buffer, batch_size=None, training_length=1)
report = {"processed_weights": worst("processed/"),
          "values": float(np.max(np.abs(np.concatenate(values_seen) - d["buf/values:extrinsic"])))}
for key, ours in (("returns:extrinsic", RewardSignalUtil.returns_key("extrinsic")), ("advantages", BufferKey.ADVANTAGES)):
    ref = np.array(update_buffer[ours].get_batch(), np.float32)
    report[key] = float(np.max(np.abs(ref - d["buf/" + key])))
a = np.array(update_buffer[BufferKey.ADVANTAGES].get_batch(), np.float32)
update_buffer[BufferKey.ADVANTAGES].set((a - a.mean()) / (a.std() + 1e-10))
pol.set_step(int(sum(len(d[f"traj{i}/rew"]) for i in range(4))))
step = pol.get_current_step()
report["schedule"] = [opt.decay_learning_rate.get_value(step), opt.decay_beta.get_value(step), opt.decay_epsilon.get_value(step)]
stats = opt.update(update_buffer.make_mini_batch(0, 64), 64)
report["policy_loss"], report["value_loss"] = stats["Losses/Policy Loss"], stats["Losses/Value Loss"]
report["updated_weights"] = worst("updated/")
print(json.dumps(report))
