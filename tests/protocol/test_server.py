"""UnityEndpoint against a real gRPC client ("Unity") in a thread, on a free port."""
from __future__ import annotations

import logging
import socket
import threading
import time

import grpc
import numpy as np
import pytest

from protos.communicator_objects import command_pb2, unity_to_external_pb2_grpc
from protos.types import ActionTuple
from tests.protocol.conftest import (
    ScriptedUnity,
    agent_info,
    brain_params,
    free_port,
    m1,
    m2,
    rl_message,
)
from trainer.errors import (
    PortInUseError,
    SimulatorExitedError,
    UnityCommunicatorStoppedError,
    UnityTimeOutError,
    UnityVersionError,
)
from trainer.protocol.server import TRANSPORTS, UnityEndpoint

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(params=TRANSPORTS, autouse=True)
def transport(request):
    """Every test runs against both server transports (our HTTP/2 one and grpcio's)."""
    return request.param


@pytest.fixture
def endpoint(port, transport):
    ep = UnityEndpoint(port, transport=transport, timeout_wait=10.0)
    ep.start()
    yield ep
    ep.close()


def test_full_handshake_reset_and_step(endpoint, port):
    first = rl_message(
        {"Ball?team=0": [agent_info(0, obs=[[1, 2]], reward=0.0), agent_info(1, obs=[[3, 4]])]},
        [brain_params("Ball?team=0", 2)],
        side_channel=b"from-unity",
    )
    second = rl_message(
        {"Ball?team=0": [agent_info(0, obs=[[5, 6]], reward=1.0, done=True), agent_info(2, obs=[[7, 8]]), agent_info(1, obs=[[9, 9]])]}
    )
    unity = ScriptedUnity(port, [m1(), m2(), first, second, m2()])
    unity.start()
    init = endpoint.handshake(seed=1234, num_areas=3)
    assert init.communication_version == "1.5.0" and init.name == "AcademySingleton"
    result = endpoint.reset(b"reset-sc")
    assert result.side_channel == b"from-unity"
    assert set(endpoint.behavior_specs) == {"Ball?team=0"}
    decision, _ = result.steps["Ball?team=0"]
    np.testing.assert_array_equal(decision.obs[0], [[1, 2], [3, 4]])
    result = endpoint.step({"Ball?team=0": ActionTuple(np.array([[0.5, -0.5], [1.0, 0.0]], np.float32), np.zeros((2, 0), np.int32))}, b"step-sc")
    decision, terminal = result.steps["Ball?team=0"]
    np.testing.assert_array_equal(decision.agent_id, [2, 1])
    np.testing.assert_array_equal(terminal.reward, [1.0])
    endpoint.send_step({"Ball?team=0": ActionTuple(np.array([[0.1, 0.2], [0.3, 0.4]], np.float32), None)}, b"")
    endpoint.receive()  # the final m2-like message, left pending
    endpoint.close()
    unity.finish()
    assert unity.error is None
    r1, r2, r3, r4, r5 = unity.responses
    # M1 answer: initialization input only
    assert r1.header.status == 200 and not r1.unity_input.HasField("rl_input")
    init_input = r1.unity_input.rl_initialization_input
    assert (init_input.seed, init_input.num_areas) == (1234, 3)
    assert (init_input.communication_version, init_input.package_version) == ("1.5.0", "1.1.0")
    assert all(getattr(init_input.capabilities, f.name) for f in init_input.capabilities.DESCRIPTOR.fields)
    # M2 answer: RESET with the side channel, no actions
    assert r2.unity_input.rl_input.command == command_pb2.RESET
    assert r2.unity_input.rl_input.side_channel == b"reset-sc" and len(r2.unity_input.rl_input.agent_actions) == 0
    assert not r2.unity_input.HasField("rl_initialization_input")
    # STEP: one action per deciding agent, in order
    step = r3.unity_input.rl_input
    assert step.command == command_pb2.STEP and step.side_channel == b"step-sc"
    assert [list(a.continuous_actions) for a in step.agent_actions["Ball?team=0"].value] == [[0.5, -0.5], [1.0, 0.0]]
    assert [list(a.continuous_actions) for a in r4.unity_input.rl_input.agent_actions["Ball?team=0"].value] == [
        pytest.approx([0.1, 0.2]), pytest.approx([0.3, 0.4])
    ]
    # close() answered the pending call with 400 and no input
    assert r5.header.status == 400 and not r5.HasField("unity_input")


def test_many_agents_and_actions_matched_by_position(endpoint, port):
    n = 300
    infos = [agent_info(i, obs=[[i, -i]], done=(i % 3 == 0), mask=[i % 2 == 0, False]) for i in range(n)]
    unity = ScriptedUnity(port, [m1(), m2(), rl_message({"D": infos}, [brain_params("D", 0, (2,))]), m2()])
    unity.start()
    endpoint.handshake(0, 1)
    decision, terminal = endpoint.reset(b"").steps["D"]
    deciding_ids = [i for i in range(n) if i % 3 != 0]
    np.testing.assert_array_equal(decision.agent_id, deciding_ids)
    np.testing.assert_array_equal(decision.obs[0][:, 1], [-i for i in deciding_ids])
    np.testing.assert_array_equal(terminal.agent_id, [i for i in range(n) if i % 3 == 0])
    np.testing.assert_array_equal(decision.action_mask[0][:, 0], [i % 2 == 0 for i in deciding_ids])
    # each deciding agent gets action = its own id % 2: checks the positional match
    chosen = (decision.agent_id % 2).astype(np.int32).reshape(-1, 1)
    endpoint.send_step({"D": ActionTuple(np.zeros((len(chosen), 0), np.float32), chosen)}, b"")
    endpoint.receive()
    endpoint.close()
    unity.finish()
    sent = unity.responses[2].unity_input.rl_input.agent_actions["D"].value
    assert [a.discrete_actions[0] for a in sent] == [i % 2 for i in deciding_ids]


def test_missing_actions_become_zero_actions_and_wrong_counts_are_refused(endpoint, port):
    infos = [agent_info(i, obs=[[0.0]]) for i in range(3)]
    unity = ScriptedUnity(port, [m1(), m2(), rl_message({"C": infos}, [brain_params("C", 2)]), m2()])
    unity.start()
    endpoint.handshake(0, 1)
    endpoint.reset(b"")
    with pytest.raises(ValueError):
        endpoint.send_step({"C": ActionTuple(np.zeros((2, 2), np.float32), None)}, b"")
    endpoint.send_step({}, b"")
    endpoint.receive()
    endpoint.close()
    unity.finish()
    sent = unity.responses[2].unity_input.rl_input.agent_actions["C"].value
    assert [list(a.continuous_actions) for a in sent] == [[0.0, 0.0]] * 3


def test_wrong_version_raises_and_close_answers_400(endpoint, port):
    unity = ScriptedUnity(port, [m1(version="2.0.0")])
    unity.start()
    with pytest.raises(UnityVersionError, match="2.0.0"):
        endpoint.handshake(0, 1)
    endpoint.close()
    unity.finish()
    assert unity.responses[0].header.status == 400


def test_client_that_never_connects_times_out(port, transport):
    with UnityEndpoint(port, transport=transport, timeout_wait=0.5, describe="env 0") as ep:
        ep.start()
        with pytest.raises(UnityTimeOutError) as err:
            ep.handshake(0, 1)
    message = str(err.value)
    assert str(port) in message and "env 0" in message and "--timeout-wait" in message


@pytest.mark.parametrize("alive_answers", [[False], [True, True, True, False]])
def test_dead_simulator_process_is_reported(port, alive_answers, transport):
    answers = iter(alive_answers)  # runs out (StopIteration) if polled after reporting death
    with UnityEndpoint(port, transport=transport, timeout_wait=1.0, is_alive=lambda: next(answers)) as ep:
        ep.start()
        with pytest.raises(SimulatorExitedError, match=str(port)):
            ep.handshake(0, 1)


def test_unity_status_400_stops_the_communicator(endpoint, port):
    stop = m2()
    stop.header.status = 400
    unity = ScriptedUnity(port, [m1(), m2(), stop])
    unity.start()
    endpoint.handshake(0, 1)
    with pytest.raises(UnityCommunicatorStoppedError):
        endpoint.reset(b"")
    unity.finish()
    assert unity.responses[-1].header.status == 400


def test_close_is_idempotent_and_never_blocks_without_a_client(port, transport):
    ep = UnityEndpoint(port, transport=transport, timeout_wait=1.0)
    ep.start()
    ep.close()
    ep.close()
    # the port is free again
    again = UnityEndpoint(port, transport=transport)
    again.start()
    again.close()


def test_port_in_use_is_reported(endpoint, port, transport):
    second = UnityEndpoint(port, transport=transport)
    with pytest.raises(PortInUseError, match=rf"{port}.*--base-port"):
        second.start()
    second.close()


def test_grpc_refuses_a_second_server_on_the_port_even_without_the_pre_check(endpoint, port, monkeypatch, transport):
    second = UnityEndpoint(port, transport=transport)
    monkeypatch.setattr(second, "_check_port_free", lambda: None)
    with pytest.raises(PortInUseError, match=str(port)):
        second.start()


def test_missing_base_capabilities_only_warn(endpoint, port, caplog):
    unity = ScriptedUnity(port, [m1(base_caps=False), m2()])
    unity.start()
    with caplog.at_level(logging.WARNING, logger="trainer.protocol.server"):
        endpoint.handshake(0, 1)
    assert "base RL capabilities" in caplog.text
    endpoint.close()
    unity.finish()
    assert unity.responses[1].header.status == 400


def test_port_held_by_a_plain_socket_is_reported(transport):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        with pytest.raises(PortInUseError):
            UnityEndpoint(holder.getsockname()[1], transport=transport).start()


def test_default_bind_is_loopback_only(endpoint, port):
    with socket.create_connection(("127.0.0.1", port), timeout=5):
        pass
    # 127.0.0.2 is another local address on Linux; a 127.0.0.1-only listener refuses it
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.2", port), timeout=5).close()


def test_camera_sized_message_over_4_mib_goes_through(endpoint, port):
    size = 3 * 512 * 800  # 1.2 M floats ≈ 4.9 MB
    pixels = (np.arange(size, dtype=np.float32) % 251) / 251
    info = agent_info(7)
    obs = info.observations.add()
    obs.shape.extend([3, 512, 800])
    obs.float_data.data.extend(pixels)
    message = rl_message({"Cam": [info]}, [brain_params("Cam", 1)])
    assert message.ByteSize() > 4 * 1024 * 1024
    unity = ScriptedUnity(port, [m1(), m2(), message])
    unity.start()
    endpoint.handshake(0, 1)
    got = endpoint.reset(b"").steps["Cam"][0].obs[0]
    np.testing.assert_array_equal(got.reshape(-1), pixels)
    endpoint.close()
    unity.finish()
    assert unity.error is None


def test_client_that_goes_away_mid_call_stops_the_endpoint(endpoint, port):
    channel = grpc.insecure_channel(f"127.0.0.1:{port}")
    stub = unity_to_external_pb2_grpc.UnityToExternalProtoStub(channel)
    future = stub.Exchange.future(m1(), wait_for_ready=True)
    # the trainer takes M1 and answers; then the client's M2 call is cancelled before an answer
    endpoint_thread_result = {}

    def handshake():
        try:
            endpoint.handshake(0, 1)
        except Exception as err:  # noqa: BLE001 - recorded for the assertion below
            endpoint_thread_result["error"] = err

    t = threading.Thread(target=handshake, daemon=True)
    t.start()
    assert future.result(timeout=10).header.status == 200
    m2_future = stub.Exchange.future(m2())
    t.join(10)
    assert not t.is_alive() and "error" not in endpoint_thread_result  # M2 is pending now
    m2_future.cancel()
    channel.close()
    # "mid-call" = before the trainer answers: wait until the server has seen the cancellation
    # (an answer racing the cancel is reported later, by is_alive or --timeout-wait)
    deadline = time.monotonic() + 10
    while not endpoint.client_gone and time.monotonic() < deadline:
        time.sleep(0.01)
    assert endpoint.client_gone
    with pytest.raises(UnityCommunicatorStoppedError, match="dropped"):
        endpoint.reset(b"")
