"""Demonstrations in the trainer: the loader's pairing (trainer/demonstrations.py), behavioral
cloning (trainer/behavioral_cloning.py) and GAIL (trainer/common/reward_providers.py), against
hand-computed values and, for GAIL, recorded ball3d demonstrations."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from protos import demo_file
from protos.communicator_objects.agent_action_pb2 import AgentActionProto
from protos.communicator_objects.agent_info_pb2 import AgentInfoProto
from protos.communicator_objects.brain_parameters_pb2 import BrainParametersProto
from protos.communicator_objects.observation_pb2 import ObservationProto
from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.artifacts.checkpoints import load_checkpoint, save_checkpoint
from trainer.behavioral_cloning import BehavioralCloning
from trainer.config.settings import BehavioralCloningSettings
from trainer.config.support import check_demo_paths
from trainer.demonstrations import DemoExperiences, load_demonstrations
from trainer.errors import ConfigError
from trainer.common.hyperparams import SignalNetwork
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.common.policy import Policy
from trainer.common.reward_providers import Experience, GAILProvider
from trainer.ppo.trainer import PPOTrainer

@pytest.fixture(autouse=True)
def one_torch_thread():
    """One intra-op thread, as the trainer runs (trainer/run_setup.py): two threads on a loaded 2-CPU
    machine made these small networks 10x slower."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


VECTOR = ObservationSpec((2,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v")
HYBRID = BehaviorSpec((VECTOR,), ActionSpec(1, (3,)))


def _brain(continuous=1, branches=(3,)) -> BrainParametersProto:
    brain = BrainParametersProto(brain_name="B?team=0")
    brain.action_spec.num_continuous_actions = continuous
    brain.action_spec.num_discrete_actions = len(branches)
    brain.action_spec.discrete_branch_sizes.extend(branches)
    return brain


def _record(path, rows, brain=None):
    """rows: (obs value, reward, done, continuous, discrete) per record."""
    with demo_file.DemoWriter(str(path), "t", brain or _brain()) as writer:
        for value, reward, done, continuous, discrete in rows:
            obs = ObservationProto(shape=[2], dimension_properties=[1])
            obs.float_data.data.extend([value, 2 * value])
            writer.record(AgentInfoProto(reward=reward, done=done, id=1, observations=[obs]),
                          AgentActionProto(continuous_actions=continuous, discrete_actions=discrete))
    return str(path)


# ----------------------------------------------------------------------------- the loader
def test_experience_t_pairs_record_t_with_the_reward_and_done_of_record_t_plus_1(tmp_path):
    path = _record(tmp_path / "a.demo", [
        (0.0, 0.0, False, [0.5], [2]),
        (1.0, 0.25, False, [-0.5], [1]),
        (2.0, 1.0, True, [], []),  # Unity's terminal record carries no action
        (3.0, 0.0, False, [0.1], [0]),
    ])
    demo = load_demonstrations(path, HYBRID, "behaviors.B.behavioral_cloning.demo_path")
    assert len(demo) == 3
    np.testing.assert_array_equal(demo.obs[0], [[0, 0], [1, 2], [2, 4]])
    np.testing.assert_array_equal(demo.continuous, [[0.5], [-0.5], [0.0]])
    np.testing.assert_array_equal(demo.discrete, [[2], [1], [0]])
    np.testing.assert_array_equal(demo.rewards, [0.25, 1.0, 0.0])
    np.testing.assert_array_equal(demo.done, [False, True, False])


def test_old_files_with_only_vector_actions_read_as_the_branch_choices(tmp_path):
    path = tmp_path / "old.demo"
    with demo_file.DemoWriter(str(path), "t", _brain(0, (3,))) as writer:
        for value in (0.0, 1.0, 2.0):
            obs = ObservationProto(shape=[2])
            obs.float_data.data.extend([value, value])
            writer.record(AgentInfoProto(id=1, observations=[obs]),
                          AgentActionProto(vector_actions_deprecated=[value]))
    demo = load_demonstrations(str(path), BehaviorSpec((VECTOR,), ActionSpec(0, (3,))), "k")
    np.testing.assert_array_equal(demo.discrete, [[0], [1]])


def test_a_demonstration_of_other_actions_is_refused_naming_the_key(tmp_path):
    path = _record(tmp_path / "a.demo", [(0.0, 0.0, False, [0.5], [2]), (1.0, 0.0, True, [], [])])
    other = BehaviorSpec((VECTOR,), ActionSpec(2, ()))
    with pytest.raises(ConfigError, match=r"behaviors\.B\.reward_signals\.gail\.demo_path: .*1 continuous actions, "
                                          r"discrete branches \[3\].*2 continuous actions"):
        load_demonstrations(path, other, "behaviors.B.reward_signals.gail.demo_path")


def test_missing_demo_paths_are_named_at_start(tmp_path):
    from trainer.config.loader import load_run_options

    (tmp_path / "c.yaml").write_text(
        "behaviors:\n  B:\n    reward_signals: {gail: {demo_path: nowhere.demo}}\n"
        "    behavioral_cloning: {demo_path: " + str(tmp_path) + "}\n")
    with pytest.raises(ConfigError) as info:
        check_demo_paths(load_run_options(str(tmp_path / "c.yaml")))
    message = str(info.value)
    assert "'behaviors.B.reward_signals.gail.demo_path': the demonstration file or folder 'nowhere.demo' " \
           "does not exist" in message
    assert "'behaviors.B.behavioral_cloning.demo_path': the demonstration folder" in message


# ----------------------------------------------------------------------------- behavioral cloning
def _demo(n=8, seed=0) -> DemoExperiences:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(n, 2)).astype(np.float32)
    return DemoExperiences([obs], np.tanh(obs[:, :1]).astype(np.float32), (obs[:, 1:] > 0).astype(np.int64) * 2,
                           np.zeros(n, np.float32), np.zeros(n, bool))


def _bc(demo, **settings) -> BehavioralCloning:
    policy = Policy(HYBRID, PPOHyperparams(hidden_units=8, num_layers=1), seed=1)
    return BehavioralCloning(policy, BehavioralCloningSettings(demo_path="x", **settings), demo,
                             policy_learning_rate=1e-3, default_batch_size=4, seed=0)


def test_bc_loss_by_hand_on_a_zeroed_actor():
    """Zero heads: mu = 0, sigma = 1, logits 0. Discrete: cross-entropy log 3 whatever the choice;
    continuous: E[(clamp(eps, -3, 3)/3 - a)^2] with the sample eps ~ N(0, 1) drawn by the module."""
    bc = _bc(_demo())
    with torch.no_grad():
        for layer in (bc.policy.actor.mu, *bc.policy.actor.discrete_branches):
            layer.weight.zero_()
            layer.bias.zero_()
    index = torch.arange(8)
    state = bc.generator.get_state()
    loss = bc.loss(index).item()
    bc.generator.set_state(state)
    eps = torch.randn((8, 1), generator=bc.generator)
    continuous = torch.mean((torch.clamp(eps, -3, 3) / 3 - torch.as_tensor(bc.demo.continuous)) ** 2).item()
    assert loss == pytest.approx(continuous + math.log(3), rel=1e-5)


def test_bc_learning_rate_decays_linearly_over_steps_and_stops_at_the_floor():
    bc = _bc(_demo(), strength=0.5, steps=100)
    assert bc.optimizer.param_groups[0]["lr"] == pytest.approx(5e-4)  # policy lr x strength
    bc.update(step=25)
    assert bc.optimizer.param_groups[0]["lr"] == pytest.approx(5e-4 * 0.75, rel=1e-6)
    bc.update(step=150)
    assert bc.current_lr == pytest.approx(1e-10)
    before = [p.detach().clone() for p in bc.policy.actor.parameters()]
    assert bc.update(step=200) == {"Losses/Pretraining Loss": 0.0}  # nothing left to learn at the floor
    assert all(torch.equal(a, b) for a, b in zip(before, bc.policy.actor.parameters()))


@pytest.mark.parametrize("settings, adam_steps", [
    ({}, 3 * 2),  # 3 epochs x (8 // 4) minibatches
    ({"num_epoch": 2, "batch_size": 2}, 2 * 4),
    ({"num_epoch": 1, "batch_size": 2, "samples_per_update": 4}, 1 * 2),
])
def test_bc_epochs_batches_and_samples_per_update(settings, adam_steps):
    bc = _bc(_demo(), **settings)
    bc.update(step=1)
    assert bc.optimizer.step_count == adam_steps


def test_bc_clones_the_demonstrated_actions():
    demo = _demo(64)
    bc = _bc(demo, num_epoch=10, batch_size=16, strength=10.0)
    first = bc.update(step=0)["Losses/Pretraining Loss"]
    for step in range(20):
        last = bc.update(step=step)["Losses/Pretraining Loss"]
    assert last < 0.3 * first
    out = bc.policy.act(demo.obs, deterministic=True)
    assert np.mean(out.discrete[:, 0] == demo.discrete[:, 0]) >= 0.95
    assert np.abs(out.env_actions.continuous - demo.continuous).mean() < 0.1  # the env's actions, not /3


# ----------------------------------------------------------------------------- GAIL
@pytest.fixture(scope="module")
def ball3d_demos(tmp_path_factory):
    """(spec, expert, random) experiences of ball3d, recorded by the stub (scripted vs uniform actions)."""
    from unity_stub_env import record_demo
    from unity_stub_env.tasks.ball3d import Ball3DTask

    spec = BehaviorSpec(Ball3DTask.observation_specs, Ball3DTask.action_spec)
    folder = tmp_path_factory.mktemp("ball3d")
    record_demo.record("ball3d", str(folder / "expert.demo"), "scripted", steps=1000, seed=1)
    rng = np.random.default_rng(0)
    original = record_demo.SCRIPTED["ball3d"]
    record_demo.SCRIPTED["ball3d"] = lambda task: lambda obs, mask: (
        rng.uniform(-1, 1, (len(obs[0]), 2)).astype(np.float32), np.zeros((len(obs[0]), 0), np.int32))
    try:
        record_demo.record("ball3d", str(folder / "random.demo"), "scripted", steps=1000, seed=2)
    finally:
        record_demo.SCRIPTED["ball3d"] = original
    return (spec, load_demonstrations(str(folder / "expert.demo"), spec, "e"),
            load_demonstrations(str(folder / "random.demo"), spec, "r"))


def _experience(demo: DemoExperiences, rows, raw_scale: float = 3.0) -> Experience:
    """Policy-side columns: continuous as raw samples (the env receives raw / 3)."""
    return Experience([o[rows] for o in demo.obs], None, demo.continuous[rows] * raw_scale, demo.discrete[rows],
                      done=demo.done[rows].astype(np.float32))


def _gail(spec, **network) -> GAILProvider:
    torch.manual_seed(0)
    return GAILProvider(spec, 1.0, SignalNetwork(learning_rate=1e-3, hidden_units=32, num_layers=2,
                                                 normalize=True, **network))


def test_gail_reward_is_minus_log_one_minus_d():
    provider = _gail(HYBRID, use_actions=True)
    with torch.no_grad():  # D = sigmoid(b) everywhere
        provider.network.estimator[0].weight.zero_()
        provider.network.estimator[0].bias.fill_(0.8)
    d = 1 / (1 + math.exp(-0.8))
    exp = _experience(_demo(4), np.arange(4))
    np.testing.assert_allclose(provider.evaluate(exp), -math.log(1 - d * (1 - 1e-7)), rtol=1e-6)
    # discriminator input: the encoded observations, then continuous (1) + one-hot (3) + done (1)
    assert provider.network.encoder.hidden[0].in_features == provider.network.encoder.observation_encoder.output_size + 5


# measured (seeds as here): held-out expert - random reward 0.41 (plain), 0.20 (use_actions), 0.17 (use_vail)
UPDATES, MARGIN = 200, 0.1


@pytest.mark.parametrize("network", [{}, {"use_actions": True}, {"use_vail": True}])
def test_gail_rewards_expert_steps_above_random_ones_after_training(ball3d_demos, network):
    """Trained on 800 expert and 800 random-action steps of ball3d, the discriminator's reward
    on the held-out steps of each (the policy's side as raw samples, which GAIL scales by 1/3)."""
    spec, expert, random_steps = ball3d_demos
    provider = _gail(spec, **network)
    provider.set_demonstrations(DemoExperiences([o[:800] for o in expert.obs], expert.continuous[:800],
                                                expert.discrete[:800], expert.rewards[:800], expert.done[:800]))
    rng = np.random.default_rng(0)
    held_out_expert = _experience(expert, np.arange(800, len(expert)))
    held_out_random = _experience(random_steps, np.arange(800, len(random_steps)))
    before = provider.evaluate(held_out_expert).mean() - provider.evaluate(held_out_random).mean()
    stats = {}
    for _ in range(UPDATES):
        stats = provider.update(_experience(random_steps, rng.integers(0, 800, 64)))
    expert_reward = provider.evaluate(held_out_expert).mean()
    random_reward = provider.evaluate(held_out_random).mean()
    assert abs(before) < 0.2
    assert expert_reward > random_reward + MARGIN, (expert_reward, random_reward)
    assert stats["Policy/GAIL Expert Estimate"] > stats["Policy/GAIL Policy Estimate"]
    keys = {"Losses/GAIL Loss", "Policy/GAIL Expert Estimate", "Policy/GAIL Policy Estimate", "Policy/GAIL Grad Mag Loss"}
    if network.get("use_vail"):
        keys |= {"Policy/GAIL Beta", "Losses/GAIL KL Loss"}
        assert stats["Policy/GAIL Beta"] >= 0.0
    assert set(stats) == keys


def test_resume_keeps_the_gail_discriminator_and_bc_state(tmp_path):
    hyper = PPOHyperparams(hidden_units=16, num_layers=1, batch_size=4, buffer_size=8, num_epoch=1,
                           reward_signals={"extrinsic": (0.99, 1.0), "gail": (0.99, 0.1)},
                           reward_signal_networks={"gail": SignalNetwork(hidden_units=8, use_vail=True)})
    demo = _demo(16)

    def make(seed):
        trainer = PPOTrainer("B", HYBRID, hyper, seed=seed)
        trainer.providers["gail"].set_demonstrations(demo)
        trainer.behavioral_cloning = BehavioralCloning(trainer.policy, BehavioralCloningSettings(demo_path="x"),
                                                       demo, 3e-4, 4, seed=0)
        return trainer

    def train(trainer):
        from trainer.common.trajectory import Trajectory

        out = trainer.policy.act(demo.obs)
        trainer.process_trajectory(Trajectory(
            obs=demo.obs, next_obs=[demo.obs[0][0]], rewards=np.ones(16, np.float32),
            continuous_actions=out.continuous_raw, discrete_actions=out.discrete, log_probs=out.log_probs,
            action_masks=None, done=True, interrupted=False))
        return trainer.update()

    first = make(1)
    stats = train(first)
    assert "Losses/GAIL Loss" in stats and "Losses/Pretraining Loss" in stats
    save_checkpoint(tmp_path / "c.pt", first.state_dict())
    state = load_checkpoint(tmp_path / "c.pt")
    assert {"Module:GAIL", "Optimizer:GAIL", "Optimizer:BC"} <= set(state)
    assert float(state["Module:GAIL"]["beta"]) >= 0.0
    resumed = make(7)
    resumed.load_state_dict(state)
    for key, value in first.providers["gail"].network.state_dict().items():
        assert torch.equal(resumed.providers["gail"].network.state_dict()[key], value), key
    assert train(resumed) == train(first)


def test_sac_runs_behavioral_cloning_after_every_gradient_step_and_keeps_it_in_checkpoints():
    from trainer.common.trajectory import Trajectory
    from trainer.sac.hyperparams import SACHyperparams
    from trainer.sac.trainer import SACTrainer

    spec = BehaviorSpec((VECTOR,), ActionSpec(1, (3,)))
    demo = _demo(16)
    trainer = SACTrainer("B", spec, SACHyperparams(batch_size=8, buffer_size=100, hidden_units=8,
                                                   steps_per_update=4.0), seed=0)
    trainer.behavioral_cloning = BehavioralCloning(trainer.policy, BehavioralCloningSettings(demo_path="x", num_epoch=1),
                                                   demo, 3e-4, 8, seed=0)
    out = trainer.policy.act(demo.obs)
    trainer.process_trajectory(Trajectory(obs=demo.obs, next_obs=[demo.obs[0][0]], rewards=np.ones(16, np.float32),
                                          continuous_actions=out.continuous_raw, discrete_actions=out.discrete,
                                          log_probs=out.log_probs, action_masks=None, done=True, interrupted=False))
    stats = trainer.update()
    gradient_steps = trainer.update_steps - 1
    assert gradient_steps == 3  # (16 - 0) / update_steps > 4 until update_steps = 4
    assert trainer.behavioral_cloning.optimizer.step_count == gradient_steps * (16 // 8)
    assert stats["Losses/Pretraining Loss"] > 0.0
    assert "Optimizer:BC" in trainer.state_dict()


def test_a_recurrent_policy_clones_whole_sequences_from_zero_memory_without_the_padding():
    spec = BehaviorSpec((VECTOR,), ActionSpec(0, (3,)))
    demo = _demo(10)
    demo = DemoExperiences(demo.obs, np.zeros((10, 0), np.float32), demo.discrete, demo.rewards,
                           np.array([0, 0, 1, 0, 0, 0, 0, 0, 0, 1], bool))  # episodes of 3 and 7
    policy = Policy(spec, PPOHyperparams(hidden_units=8, num_layers=1, memory_size=8, sequence_length=4), seed=1)
    bc = BehavioralCloning(policy, BehavioralCloningSettings(demo_path="x", batch_size=8, num_epoch=1), demo,
                           1e-3, 8, seed=0)
    # 3 -> 4 rows, 7 -> 8 rows: 12 rows, 3 sequences, 2 per minibatch
    assert bc._valid.tolist() == [1, 1, 1, 0, 1, 1, 1, 1, 1, 1, 1, 0]
    assert (bc.sequences_per_batch, bc.batch_size) == (2, 8)
    np.testing.assert_array_equal(bc._obs[0][4:11].numpy(), demo.obs[0][3:10])
    # the loss of sequence 1 (rows 4..7) is the cross-entropy of running it from a zero memory
    index = torch.arange(4, 8)
    with torch.no_grad():
        _, logits, _ = policy.actor.heads_with_memory([bc._obs[0][index]], None, torch.zeros(1, 1, 8), 4)
        expected = torch.nn.functional.cross_entropy(logits[0], bc._discrete[index, 0]).item()
        assert bc.loss(index).item() == pytest.approx(expected, rel=1e-6)
        # padding rows do not count: sequence 0 (rows 0..3) averages its 3 real rows only
        index = torch.arange(0, 4)
        _, logits, _ = policy.actor.heads_with_memory([bc._obs[0][index]], None, torch.zeros(1, 1, 8), 4)
        per_row = torch.nn.functional.cross_entropy(logits[0], bc._discrete[index, 0], reduction="none")
        assert bc.loss(index).item() == pytest.approx(per_row[:3].mean().item(), rel=1e-6)
    stats = bc.update(step=1)
    assert bc.optimizer.step_count == 1 and stats["Losses/Pretraining Loss"] > 0  # 3 sequences // 2 per batch


def test_gail_trains_beside_a_recurrent_policy():
    hyper = PPOHyperparams(hidden_units=8, num_layers=1, batch_size=8, buffer_size=8, num_epoch=1, memory_size=8,
                           sequence_length=4, reward_signals={"extrinsic": (0.99, 1.0), "gail": (0.99, 0.1)},
                           reward_signal_networks={"gail": SignalNetwork(hidden_units=8, use_actions=True)})
    trainer = PPOTrainer("B", HYBRID, hyper, seed=0)
    demo = _demo(16)
    trainer.providers["gail"].set_demonstrations(demo)
    from trainer.common.trajectory import Trajectory

    out = trainer.policy.act([demo.obs[0][:10]],
                             memories=np.zeros((10, 8), np.float32))
    trainer.process_trajectory(Trajectory(
        obs=[demo.obs[0][:10]], next_obs=[demo.obs[0][10]], rewards=np.ones(10, np.float32),
        continuous_actions=out.continuous_raw, discrete_actions=out.discrete, log_probs=out.log_probs,
        action_masks=None, done=True, interrupted=False, memories=np.zeros((10, 8), np.float32)))
    stats = trainer.update()
    assert math.isfinite(stats["Losses/GAIL Loss"]) and "Policy/GAIL Grad Mag Loss" in stats


def test_a_trainer_without_a_gail_provider_refuses_gail(tmp_path):
    """A trainer that built no GAIL learner says so (exit 2) instead of training without it; every
    Trainer has the cloning hook (trainer/common/trainer_interface.py), so only GAIL can be missing."""
    from trainer.behavior import attach_demonstrations
    from trainer.config.loader import load_run_options

    path = _record(tmp_path / "a.demo", [(0.0, 0.0, False, [0.5], [2]), (1.0, 1.0, True, [], [])])
    (tmp_path / "c.yaml").write_text(f"behaviors:\n  B:\n    behavioral_cloning: {{demo_path: {path}}}\n"
                                     f"    reward_signals: {{extrinsic: {{}}, gail: {{demo_path: {path}}}}}\n")
    settings = load_run_options(str(tmp_path / "c.yaml")).behaviors["B"]

    class Bare:  # no GAIL provider
        policy = None
        providers: dict = {}

    with pytest.raises(ConfigError, match="behaviors.B.reward_signals.gail: not implemented for trainer_type ppo"):
        attach_demonstrations(Bare(), "B", HYBRID, settings, seed=0)
    hyper = PPOHyperparams(hidden_units=8, num_layers=1, reward_signals={"extrinsic": (0.99, 1.0), "gail": (0.99, 1.0)},
                           reward_signal_networks={"gail": SignalNetwork(hidden_units=8)})
    trainer = PPOTrainer("B", HYBRID, hyper, seed=0)
    attach_demonstrations(trainer, "B", HYBRID, settings, seed=0)
    assert trainer.behavioral_cloning is not None and trainer.providers["gail"].demo is not None


def test_poca_trains_gail_and_cloning_through_the_ppo_hooks():
    from tests.unit.test_poca import trajectory
    from trainer.poca.trainer import POCATrainer

    hyper = PPOHyperparams(hidden_units=8, num_layers=1, batch_size=4, buffer_size=4, num_epoch=1,
                           reward_signals={"extrinsic": (0.99, 1.0), "gail": (0.99, 0.1)},
                           reward_signal_networks={"gail": SignalNetwork(hidden_units=8, use_actions=True)})
    trainer = POCATrainer("B", HYBRID, hyper, seed=0)
    demo = _demo(16)
    trainer.providers["gail"].set_demonstrations(demo)
    trainer.behavioral_cloning = BehavioralCloning(trainer.policy, BehavioralCloningSettings(demo_path="x"), demo,
                                                   3e-4, 4, seed=0)
    for _ in range(2):
        stats = trainer.process_trajectory(trajectory(True, False, True))
    assert "Policy/Gail Value Estimate" in stats and "Policy/Gail Baseline Estimate" in stats
    stats = trainer.update()
    assert math.isfinite(stats["Losses/GAIL Loss"]) and stats["Losses/Pretraining Loss"] > 0
    assert {"Module:GAIL", "Optimizer:BC"} <= set(trainer.state_dict())
