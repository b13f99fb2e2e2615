"""The stub as a separate process against a scripted trainer: the wire behaviour of a Unity player."""
from __future__ import annotations

import signal

import numpy as np
import pytest

from protos import side_channels as sc
from protos.types import StatsAggregationMethod
from tests.stub.conftest import (
    QUIT,
    RESET,
    command_answer,
    handshake,
    init_answer,
    step_answer,
)

BASIC = "Basic?team=0"
BALL = "3DBall?team=0"


def infos_of(message, key=BASIC):
    return list(message.unity_output.rl_output.agentInfos[key].value)


def position(info) -> int:
    data = list(info.observations[0].float_data.data)
    assert sorted(data) == [0.0] * 19 + [1.0]
    return data.index(1.0)


@pytest.mark.parametrize("transport", ["http2", "grpcio"])
def test_handshake_m1_m2_and_brain_parameters_only_first_time(trainer, launch, transport):
    # the stub's own HTTP/2 client (default) and grpcio's channel (--transport grpcio)
    process = launch(trainer.port, "basic", "--transport", transport)
    first, second, third = handshake(trainer, num_areas=2)
    # the client the flag chose made the calls (grpcio's says grpc-python/..., ours mlagents-like-http2/1)
    assert {agent.split("/")[0] for agent in trainer.user_agents} == {
        "grpc-python" if transport == "grpcio" else "mlagents-like-http2"}

    assert first.header.status == 200
    init = first.unity_output.rl_initialization_output
    assert (init.name, init.communication_version, init.package_version) == ("AcademySingleton", "1.5.0", "3.0.0")
    caps = init.capabilities
    assert all([caps.baseRLCapabilities, caps.concatenatedPngObservations, caps.compressedChannelMapping,
                caps.hybridActions, caps.trainingAnalytics, caps.variableLengthObservation,
                caps.multiAgentGroups])
    assert len(init.brain_parameters) == 0
    assert not first.unity_output.HasField("rl_output")
    assert second.header.status == 200 and not second.HasField("unity_output")

    (brain,) = third.unity_output.rl_initialization_output.brain_parameters
    assert brain.brain_name == BASIC and brain.is_training
    assert (brain.action_spec.num_continuous_actions, brain.action_spec.num_discrete_actions) == (0, 1)
    assert list(brain.action_spec.discrete_branch_sizes) == [3]
    infos = infos_of(third)
    assert [info.done for info in infos] == [False, False]
    assert [position(info) for info in infos] == [10, 10]
    assert len({info.id for info in infos}) == 2
    obs = infos[0].observations[0]
    assert list(obs.shape) == [20] and list(obs.dimension_properties) == [1]
    assert list(infos[0].action_mask) == [False, False, False]

    fourth = trainer.exchange(step_answer(BASIC, discrete=[[0], [0]]))
    assert not fourth.unity_output.HasField("rl_initialization_output")
    assert len(infos_of(fourth)) == 2
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_actions_are_applied_by_position(trainer, launch):
    process = launch(trainer.port, "basic", "--num-areas", "3")
    _, _, third = handshake(trainer, num_areas=1)  # --num-areas overrides the trainer's 1
    assert len(infos_of(third)) == 3
    after = trainer.exchange(step_answer(BASIC, discrete=[[0], [1], [2]]))  # stay, left, right
    infos = infos_of(after)
    assert [position(info) for info in infos] == [10, 9, 11]
    assert np.allclose([info.reward for info in infos], [-0.01, -0.01, -0.01])
    after = trainer.exchange(step_answer(BASIC, discrete=[[2], [1], [0]]))
    assert [position(info) for info in infos_of(after)] == [11, 8, 11]
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_terminal_and_next_first_info_share_a_message_with_new_ids_and_stats(trainer, launch):
    process = launch(trainer.port, "basic")
    _, _, message = handshake(trainer)
    (start,) = infos_of(message)
    first_id = start.id
    for _ in range(6):  # 10 -> 16
        message = trainer.exchange(step_answer(BASIC, discrete=[[2]]))
        assert [info.done for info in infos_of(message)] == [False]
    message = trainer.exchange(step_answer(BASIC, discrete=[[2]]))  # 16 -> 17: large goal
    terminal, fresh = infos_of(message)
    assert (terminal.done, terminal.max_step_reached, terminal.id) == (True, False, first_id)
    assert np.isclose(terminal.reward, -0.01 + 1.0)
    assert position(terminal) == 17
    assert (fresh.done, position(fresh), fresh.reward) == (False, 10, 0.0)
    assert fresh.id != first_id

    stats = [sc.decode_stat(payload) for channel, payload in
             sc.unpack_messages(message.unity_output.rl_output.side_channel) if channel == sc.STATS_CHANNEL_ID]
    assert ("Basic/Large Goal Reached", 1.0, StatsAggregationMethod.AVERAGE) in stats
    assert ("Basic/Last Final Position", 17.0, StatsAggregationMethod.MOST_RECENT) in stats

    second_id = fresh.id
    for _ in range(3):  # 10 -> 7: small goal
        message = trainer.exchange(step_answer(BASIC, discrete=[[1]]))
    terminal, fresh = infos_of(message)
    assert (terminal.done, terminal.id, position(terminal)) == (True, second_id, 7)
    assert np.isclose(terminal.reward, -0.01 + 0.1)
    assert fresh.id not in (first_id, second_id)
    trainer.respond(command_answer(QUIT))
    assert process.wait(timeout=10) == 0


def test_max_step_gives_an_interrupted_terminal(trainer, launch):
    process = launch(trainer.port, "basic")
    handshake(trainer)
    for step in range(100):
        message = trainer.exchange(step_answer(BASIC, discrete=[[0]]))
        if step < 99:
            assert len(infos_of(message)) == 1
    terminal, fresh = infos_of(message)
    assert terminal.done and terminal.max_step_reached and not fresh.done
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_reset_starts_new_episodes_without_terminals(trainer, launch):
    process = launch(trainer.port, "basic", "--num-areas", "2")
    _, _, message = handshake(trainer)
    old_ids = {info.id for info in infos_of(message)}
    message = trainer.exchange(step_answer(BASIC, discrete=[[2], [1]]))
    message = trainer.exchange(command_answer(RESET))
    infos = infos_of(message)
    assert [info.done for info in infos] == [False, False]
    assert [position(info) for info in infos] == [10, 10]
    assert not old_ids & {info.id for info in infos}
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def _ball_velocity_z_after_one_decision(trainer, gravity_payload: bytes | None) -> list[float]:
    side = sc.pack_messages([(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, gravity_payload)]) if gravity_payload else b""
    message = trainer.exchange(command_answer(RESET, side))
    n = len(infos_of(message, BALL))
    message = trainer.exchange(step_answer(BALL, continuous=[[0.0, 0.0]] * n))
    return [info.observations[0].float_data.data[7] for info in infos_of(message, BALL)]


def test_gravity_environment_parameter_changes_ball3d(trainer, launch):
    process = launch(trainer.port, "ball3d")
    _, _, message = handshake(trainer)
    assert len(infos_of(message, BALL)) == 12
    # Free fall for 0.1 s (5 control steps of 0.02 s) from 4 m above the plate: v_z = -g * 0.1.
    default = _ball_velocity_z_after_one_decision(trainer, None)
    assert np.allclose(default, -9.81 * 0.1, atol=1e-4)
    lunar = _ball_velocity_z_after_one_decision(trainer, sc.encode_env_float("gravity", 1.62))
    assert np.allclose(lunar, -1.62 * 0.1, atol=1e-4)
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_status_400_answer_makes_the_stub_exit_0(trainer, launch):
    process = launch(trainer.port, "ball3d")
    handshake(trainer)
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_sigterm_sends_status_400_then_exits_0(trainer, launch):
    process = launch(trainer.port, "basic")
    handshake(trainer)  # M3 is now waiting for our answer
    process.send_signal(signal.SIGTERM)
    closing = trainer.exchange(step_answer(BASIC, discrete=[[0]]))
    assert closing.header.status == 400 and not closing.HasField("unity_output")
    trainer.respond(command_answer(0, status=400))
    assert process.wait(timeout=10) == 0


def test_incompatible_trainer_version_exits_1_with_message(trainer, launch):
    process = launch(trainer.port, "basic")
    trainer.receive(timeout=20)
    closing = trainer.exchange(init_answer(version="2.0.0"))
    assert closing.header.status == 400
    trainer.respond(command_answer(0, status=400))
    _, err = process.communicate(timeout=10)
    assert process.returncode == 1
    assert "2.0.0" in err and "incompatible" in err
