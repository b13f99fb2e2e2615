"""The stub against our own trainer endpoint (trainer/protocol/server.py UnityEndpoint)."""
from __future__ import annotations

import numpy as np
import pytest

from protos import side_channels as sc
from protos.types import ActionTuple
from trainer.protocol.server import UnityEndpoint


@pytest.fixture
def endpoint():
    with UnityEndpoint(0, timeout_wait=20) as server:
        server.start()
        yield server


def test_endpoint_trains_basic_through_the_stub(endpoint, launch):
    process = launch(endpoint.port, "basic", "--num-areas", "2")
    init = endpoint.handshake(seed=5, num_areas=2)
    assert init.communication_version == "1.5.0"
    result = endpoint.reset(sc.pack_messages([(sc.ENGINE_CONFIG_CHANNEL_ID, payload)
                                              for payload in sc.encode_engine_config(84, 84, 5, 20.0, -1, 60)]))
    spec = result.specs["Basic?team=0"]
    assert spec.action_spec.discrete_branches == (3,) and spec.observation_specs[0].shape == (20,)
    decision, terminal = result.steps["Basic?team=0"]
    assert len(decision) == 2 and len(terminal) == 0
    for _ in range(7):  # agent 0 walks right to the large goal, agent 1 stays
        result = endpoint.step({"Basic?team=0": ActionTuple(np.zeros((2, 0), np.float32),
                                                            np.array([[2], [0]], np.int32))})
    decision, terminal = result.steps["Basic?team=0"]
    assert terminal.reward.tolist() == pytest.approx([0.99])
    assert not terminal.interrupted[0]
    assert len(decision) == 2 and terminal.agent_id[0] not in decision.agent_id.tolist()
    assert np.argmax(decision.obs[0], axis=1).tolist() == [10, 10]  # agent 1 stayed; agent 0 restarted
    endpoint.close()
    assert process.wait(timeout=10) == 0


def test_many_agents_are_decoded_from_bytes_once_and_equal_a_full_parse(endpoint, launch, monkeypatch):
    """72 ball3d agents: the endpoint takes the agent info list out of each message before
    parsing it (records.split_agent_lists) and decodes it from its bytes; every step equals
    what a plain parse of the same message gives, terminal infos included."""
    from protos.communicator_objects import unity_message_pb2
    from protos import records
    from trainer.protocol import codec

    payloads, taken = [], []
    real_split = records.split_agent_lists

    def spy(payload, min_rows):
        payloads.append(payload)
        split = real_split(payload, min_rows)
        taken.append(split is not None)
        return split

    monkeypatch.setattr(records, "split_agent_lists", spy)
    process = launch(endpoint.port, "ball3d", "--num-areas", "6")
    endpoint.handshake(seed=2, num_areas=6)
    result = endpoint.reset()
    key = "3DBall?team=0"
    terminals = 0
    for step in range(40):
        decision, terminal = result.steps[key]
        terminals += len(terminal)
        plain = codec.decode_rl_output(unity_message_pb2.UnityMessageProto.FromString(payloads[-1]).unity_output,
                                       {key: endpoint.behavior_specs[key]} if step else {})
        for got, want in zip(result.steps[key], plain.steps[key]):
            np.testing.assert_array_equal(got.agent_id, want.agent_id)
            np.testing.assert_array_equal(got.reward, want.reward)
            np.testing.assert_array_equal(got.obs[0], want.obs[0])
        actions = np.full((len(decision), 2), 1.0 if step % 2 else -1.0, np.float32)  # balls roll off
        result = endpoint.step({key: ActionTuple(actions, np.zeros((len(decision), 0), np.int32))})
    # the handshake's two messages carry no agents; every later one took the byte path
    assert taken[:2] == [False, False] and all(taken[2:]) and len(taken) == 43
    assert terminals > 0  # including messages that mix terminal infos with decision requests
    endpoint.close()
    assert process.wait(timeout=10) == 0


def test_polling_on_both_ends_changes_nothing_but_the_waiting(launch, tmp_path):
    """The endpoint and the stub both poll for each other's answers (--spin-wait-ms,
    protos/pacing.py): the steps are the same as with plain blocking, the waits are
    timed, and the stub reports at exit how many answers polling found."""
    actions = [np.array([[a], [2 - a]], np.int32) for a in (2, 2, 1, 0, 2, 2, 2, 2, 0, 1) * 3]
    runs = []
    for spin in (0.0, 0.002):
        log = tmp_path / f"Player-{spin}.log"
        with UnityEndpoint(0, timeout_wait=20, spin_wait=spin) as server:
            server.start()
            process = launch(server.port, "basic", "--num-areas", "2", "--spin-wait-ms", f"{spin * 1e3:g}",
                             "-logFile", str(log))
            server.handshake(seed=3, num_areas=2)
            result, seen = server.reset(b""), []
            for discrete in actions:
                result = server.step({"Basic?team=0": ActionTuple(np.zeros((2, 0), np.float32), discrete)})
                decision, terminal = result.steps["Basic?team=0"]
                seen.append((decision.obs[0].tolist(), decision.agent_id.tolist(), terminal.reward.tolist()))
            pace = server._transport.pace
            assert pace.spin_s == spin and pace.arrivals >= 1  # the trainer timed the stub's answers
            server.close()
            assert process.wait(timeout=10) == 0
        runs.append(seen)
        polling_line = [line for line in log.read_text().splitlines() if "found by polling" in line]
        assert len(polling_line) == (1 if spin else 0)
    assert runs[0] == runs[1]
    assert any(reward for _, _, reward in runs[0])  # episodes ended on the way
