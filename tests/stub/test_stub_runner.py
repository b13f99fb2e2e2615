"""The runner task (the runner thesis, docs/stub-tasks.md): specs, the track generator, the
kinematics by hand, the shipped models, and the hmm sampler's sequences arriving through the
side-channel encoding."""
from __future__ import annotations

import math

import numpy as np
import pytest

from protos import side_channels as sc
from trainer.config.env_params import hmm_model, hmm_sequences, structure_environment_parameters
from trainer.curriculum import EnvironmentParameterManager
from trainer.side_channel_payloads import environment_parameter_messages
from unity_stub_env.communicator import SideChannelState
from unity_stub_env.tasks import EnvironmentParameters, make_task
from unity_stub_env.tasks import runner as R
from unity_stub_env.tasks.runner.data import make_models


def _params(**values) -> EnvironmentParameters:
    params = EnvironmentParameters()
    for key, value in values.items():
        params.set(key, lambda value=value: float(value))
    return params


def _centre_line(obs: np.ndarray) -> np.ndarray:
    """A hand-written driver: feed the current platform's turn forward, steer back to y = 0, θ = 0."""
    y, theta, turn = obs[:, 0] * R.HALF_WIDTH, np.arctan2(obs[:, 1], obs[:, 2]), obs[:, 4]
    return np.clip(turn * R.CURVATURE * R.SPEED / R.MAX_TURN_RATE - 0.5 * y - 1.5 * theta, -1, 1)[:, None]


def test_specs_and_observation_layout():
    task = make_task("runner", num_areas=2, seed=0)
    assert (task.behavior_name, task.num_agents, task.action_spec.continuous_size) == ("Runner", 8, 1)
    assert task.action_spec.discrete_branches == ()
    obs = task.observe()
    assert len(obs) == 1 and obs[0].shape == (8, 29) and obs[0].dtype == np.float32
    first = obs[0][0]
    assert first[:4].tolist() == [0.0, 0.0, 1.0, 0.25]  # centred, straight, 1 m into the start platform
    assert first[4:9].tolist() == [0, 0, 0, 0, 0]  # the start platform: straight, no props
    assert "runner: behavior 'Runner'" in R.RunnerTask.describe()


def test_a_track_is_a_pure_function_of_its_seed_and_follows_the_zone_rules():
    a, b = R.generate_track(42), R.generate_track(42)
    assert (a.kinds, a.zones, a.props) == (b.kinds, b.zones, b.props)
    assert R.generate_track(43).kinds != a.kinds
    for seed in range(20):
        track = R.generate_track(seed, zones=4, zone_length_min=3, zone_length_max=5)
        assert track.kinds[0] == "Start" and track.kinds.count("Transition") == 3
        # zones cycle urban -> rural -> desert, each 3..5 platforms, a transition between two
        runs = " ".join(track.kinds[1:]).split("Transition")
        assert [3 <= len(run.split()) <= 5 for run in runs] == [True] * 4
        first = track.zones[1]
        starts = [1] + [i + 1 for i, kind in enumerate(track.kinds) if kind == "Transition"]
        assert [track.zones[i] for i in starts] == [(first + z) % 3 for z in range(4)]
        assert set(track.kinds[1:]) <= {"Left", "Right", "Straight", "Transition"}
        for kind, zone, row in zip(track.kinds, track.zones, track.props):
            assert len(row) == 3
            if kind in ("Start", "Transition"):
                assert row == [[], [], []]
            assert any(not spawn or spawn[0] == "coin" for spawn in row)  # never a blocked platform
            for spawn, most in zip(row, R.SPAWN_STACKS[R.ZONES[zone]]):
                assert len(spawn) <= most and "-" not in spawn
                assert len({label == "coin" for label in spawn}) <= 1  # coins or obstacles, not both


def test_stackable_spawn_points_take_their_share_of_the_chain_bottom_first():
    assert R.stack(["hay", "hay"]) == ["hay", "hay"]
    assert R.stack(["-", "hay"]) == []  # nothing floats above an empty place
    assert R.stack(["rock", "coin", "rock"]) == ["rock"]  # no coin on an obstacle
    assert R.stack(["coin", "coin", "-"]) == ["coin", "coin"]
    track = R.Track(["Start", "Straight"], [0, 0], [[[], [], []], [["car"], ["crate", "crate"], ["coin"]]])
    assert track.prop_codes().tolist() == [[0, 0, 0], [-1, -2, 1]]
    # the seed's largest generator: 20 states, 10 labels (urban props); every zone stacks somewhere
    _, urban = R.zone_models("urban")
    assert (urban.num_states, len(urban.labels)) == (20, 10)
    assert all(max(sizes) > 1 for sizes in R.SPAWN_STACKS.values())
    stacked = [len(spawn) for seed in range(30) for row in R.generate_track(seed).props for spawn in row]
    assert max(stacked) >= 2


def test_the_environment_parameters_choose_zones_and_lengths():
    task = make_task("runner", seed=0, env_params=_params(track_seed=7, zones=2, zone_length_min=10,
                                                          zone_length_max=10, first_zone=2))
    expected = R.generate_track(7, zones=2, zone_length_min=10, zone_length_max=10, first_zone=2)
    assert task.num_platforms.tolist() == [len(expected.kinds)] * 4 == [1 + 10 + 1 + 10] * 4
    assert task.turn[0, :22].tolist() == expected.turns().tolist()
    assert expected.zones[1] == 2 and expected.zones[-1] == 0  # desert, then urban


def test_kinematics_by_hand():
    # all-Left track: one step on the start platform, then the bend
    task = make_task("runner", seed=0, env_params=_params(**{"track.count": 1, "track.length": 3,
                                                             "track.0": 0, "track.1": 0, "track.2": 0}))
    assert task.num_platforms[0] == 4 and task.turn[0, :4].tolist() == [0, 1, 1, 1]
    n = task.num_agents
    result = task.step(np.zeros((n, 1)), np.zeros((n, 0)))
    assert task.s[0] == pytest.approx(1.0 + 0.8) and task.y[0] == 0.0  # 4 m/s for 0.2 s
    assert result.rewards[0] == pytest.approx(0.1 * 0.8 / 4.0)
    task.s[:] = 4.0  # now on the first Left platform: the track turns π/2 per 4 m
    task.step(np.zeros((n, 1)), np.zeros((n, 0)))
    assert task.theta[0] == pytest.approx(-(math.pi / 8) * 4.0 * 0.2)
    assert task.y[0] == pytest.approx(4.0 * math.sin(-(math.pi / 2) * 0.2) * 0.2)
    # full left steering out-turns the bend by half: ω_max = 1.5 κ v
    task.reset()
    task.s[:] = 4.0
    task.step(np.ones((n, 1)), np.zeros((n, 0)))
    assert task.theta[0] == pytest.approx(0.5 * (math.pi / 8) * 4.0 * 0.2)
    # without steering the bend throws the agent off: -1 and the episode ends
    task.reset()
    ends = []
    for _ in range(15):
        result = task.step(np.zeros((n, 1)), np.zeros((n, 0)))
        ends.append(bool(result.done[0]))
        if result.done[0]:
            break
    assert ends[-1] and abs(task.y[0]) > R.HALF_WIDTH and not result.interrupted[0]
    assert result.rewards[0] < -0.9
    assert ("Runner/Track Completed", 0.0, sc.StatsAggregationMethod.AVERAGE) in result.stats


def test_obstacles_and_coins_when_passing_their_spawn_points():
    task = make_task("runner", seed=0, env_params=_params(track_seed=3))
    n = task.num_agents
    task.turn[:] = 0.0
    task.props[:, 1] = [-1, 1, 0]  # platform 1: obstacle left, coin centre, nothing right
    task.s[:] = 4.0 + 1.5  # 0.5 m before platform 1's spawn line
    task.y[:] = [1.0, 0.0, -1.0, 0.5][:n]
    result = task.step(np.zeros((n, 1)), np.zeros((n, 0)))
    progress = 0.1 * 0.8 / 4.0
    assert result.rewards.tolist() == pytest.approx([progress - 0.3, progress + 0.1, progress, progress - 0.3 + 0.1])
    assert task.props[:, 1].tolist() == [[0, 0, 0]] * n  # passed props no longer show
    task.props[:, 2] = [-2, 0, 2]  # platform 2: two stacked obstacles left, two stacked coins right
    task.s[:] = 8.0 + 1.5
    task.y[:] = [1.0, 0.0, -1.0, 0.5][:n]
    result = task.step(np.zeros((n, 1)), np.zeros((n, 0)))
    assert result.rewards.tolist() == pytest.approx([progress - 0.6, progress, progress + 0.2, progress - 0.6])


def test_a_hand_written_driver_finishes_held_out_tracks_and_doing_nothing_does_not():
    seeds = range(R.HELD_OUT_SEED_START, R.HELD_OUT_SEED_START + 40)
    driven = R.evaluate_tracks(_centre_line, seeds)
    idle = R.evaluate_tracks(lambda obs: np.zeros((len(obs), 1)), seeds)
    assert driven["completion_rate"] == 1.0 and driven["mean_return"] > 1.5
    assert idle["completion_rate"] == 0.0 and idle["mean_return"] < -0.5


def test_the_shipped_corpora_and_models_are_what_make_models_writes(tmp_path):
    make_models.build(str(tmp_path))
    for zone in R.ZONES:
        for kind in ("platforms", "props"):
            name = f"{zone}_{kind}"
            for ext in ("txt", "json"):
                with open(f"{R.DATA}/{name}.{ext}", encoding="utf-8") as shipped:
                    assert (tmp_path / f"{name}.{ext}").read_text() == shipped.read(), name
    platforms, props = R.zone_models("urban")
    assert platforms.labels == list(R.PLATFORM_LABELS) and platforms.num_states == 5
    assert "-" in props.labels and "coin" in props.labels


def test_an_hmm_sampler_reaches_the_runner_through_the_side_channel_encoding():
    """Trainer side: YAML -> sampler -> messages; stub side: decode -> EnvironmentParameters ->
    the runner drives exactly the sent platforms."""
    raw = {"track": {"sampler_type": "hmm", "sampler_parameters": {
        "model": f"{R.DATA}/rural_platforms.json", "length": 12, "count": 3, "seed": 5}}}
    manager = EnvironmentParameterManager(structure_environment_parameters(raw), run_seed=0)
    messages = environment_parameter_messages(manager)
    assert len(messages) == 3 + 36
    params = EnvironmentParameters()
    SideChannelState(params).apply(sc.pack_messages(messages))
    assert params.get("track.count", 0) == 3 and params.get("track.labels", 0) == 3
    sampler = manager.current_samplers()["track"]
    codes = hmm_sequences(sampler)
    assert codes.shape == (3, 12) and hmm_model(sampler).labels == ["Left", "Right", "Straight"]
    task = make_task("runner", num_areas=3, seed=1, env_params=params)
    sent = {tuple(np.array([1.0, -1.0, 0.0])[row].tolist()) for row in codes}
    for agent in range(task.num_agents):
        assert task.num_platforms[agent] == 13
        assert tuple(task.turn[agent, 1:13].tolist()) in sent
    # the same seed draws the same sequences; another seed others
    again = EnvironmentParameterManager(structure_environment_parameters(raw), run_seed=9)
    assert np.array_equal(hmm_sequences(again.current_samplers()["track"]), codes)
    raw["track"]["sampler_parameters"]["seed"] = 6
    other = EnvironmentParameterManager(structure_environment_parameters(raw), run_seed=0)
    assert not np.array_equal(hmm_sequences(other.current_samplers()["track"]), codes)
