"""Replays Unity's side of a Basic session as raw bytes against our UnityEndpoint.

A scripted gRPC client (identity serializers: bytes in, bytes out, no generated classes) sends
the C# RpcCommunicator's requests from ``golden/transcript_basic.json`` and the test asserts that
every response of ours is byte-identical to the golden response written down by hand from the
protobuf wire format (see ``golden/build_transcript_basic.py`` and ``golden/protowire.py``).
"""
from __future__ import annotations

import importlib.util
import json
import socket
import threading
from pathlib import Path

import grpc
import numpy as np
import pytest

from protos.side_channels import (
    ENGINE_CONFIG_CHANNEL_ID,
    SideChannelRouter,
    encode_engine_config,
)
from protos.types import (
    ActionSpec,
    ActionTuple,
    DimensionProperty,
    ObservationType,
    StatsAggregationMethod,
)
from trainer.errors import UnityCommunicatorStoppedError
from trainer.protocol.server import UnityEndpoint

GOLDEN = Path(__file__).parent / "golden"
EXCHANGE_PATH = "/communicator_objects.UnityToExternalProto/Exchange"


def _load_transcript() -> dict:
    return json.loads((GOLDEN / "transcript_basic.json").read_text())


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class ScriptedUnity(threading.Thread):
    """Plays Unity: sends each request in turn, blocking in Exchange until the trainer answers."""

    def __init__(self, port: int, requests: list[bytes]) -> None:
        super().__init__(daemon=True)
        self.port = port
        self.requests = requests
        self.responses: list[bytes] = []
        self.error: Exception | None = None

    def run(self) -> None:
        channel = grpc.insecure_channel(f"127.0.0.1:{self.port}")
        exchange = channel.unary_unary(EXCHANGE_PATH)  # no serializers: raw bytes both ways
        try:
            grpc.channel_ready_future(channel).result(timeout=20)
            for request in self.requests:
                self.responses.append(exchange(request, timeout=20))
        except Exception as exc:  # reported by the test thread
            self.error = exc
        finally:
            channel.close()


def _engine_config_side_channel(settings: dict) -> bytes:
    router = SideChannelRouter()
    for payload in encode_engine_config(**settings):
        router.queue(ENGINE_CONFIG_CHANNEL_ID, payload)
    return router.drain()


def _actions(rows: list[list[int]]) -> ActionTuple:
    return ActionTuple(np.zeros((len(rows), 0), dtype=np.float32), np.array(rows, dtype=np.int32))


def _one_hot(position: int) -> np.ndarray:
    row = np.zeros(20, dtype=np.float32)
    row[position] = 1.0
    return row


def _run_session(transcript: dict, unity_closes: bool):
    """Drive the endpoint through the transcript; returns (client, [StepResult M3, StepResult M4], endpoint)."""
    trainer = transcript["trainer"]
    exchanges = transcript["exchanges"] if unity_closes else transcript["exchanges"][:4]
    port = _free_port()
    endpoint = UnityEndpoint(port=port, timeout_wait=20.0)
    endpoint.start()
    client = ScriptedUnity(port, [bytes.fromhex(e["request_hex"]) for e in exchanges])
    client.start()
    results = []
    try:
        endpoint.handshake(seed=trainer["seed"], num_areas=trainer["num_areas"])
        side_channel = _engine_config_side_channel(trainer["engine_settings"])
        assert side_channel == bytes.fromhex(trainer["reset_side_channel_hex"])
        results.append(endpoint.reset(side_channel))
        behavior = trainer["behavior"]
        first_rows, second_rows = trainer["step_discrete_actions"]
        results.append(endpoint.step({behavior: _actions(first_rows)}))
        if unity_closes:
            with pytest.raises(UnityCommunicatorStoppedError):
                endpoint.step({behavior: _actions(second_rows)})
    finally:
        endpoint.close()
        client.join(timeout=20)
    assert client.error is None, f"scripted Unity client failed: {client.error!r}"
    return client, results, endpoint


def test_golden_file_is_current():
    """The stored JSON is exactly what the hand-written builder produces."""
    spec = importlib.util.spec_from_file_location("build_transcript_basic", GOLDEN / "build_transcript_basic.py")
    builder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(builder)
    assert builder.transcript() == _load_transcript()


def test_responses_match_golden_bytes_when_unity_closes():
    transcript = _load_transcript()
    client, _, _ = _run_session(transcript, unity_closes=True)
    expected = [bytes.fromhex(e["response_hex"]) for e in transcript["exchanges"]]
    assert len(client.responses) == len(expected)
    for exchange, got, want in zip(transcript["exchanges"], client.responses, expected):
        assert got.hex() == want.hex(), exchange["name"]


def test_trainer_close_answers_pending_call_with_400():
    transcript = _load_transcript()
    client, _, _ = _run_session(transcript, unity_closes=False)
    expected = [bytes.fromhex(e["response_hex"]) for e in transcript["exchanges"][:3]]
    expected.append(bytes.fromhex(transcript["trainer_close_response_hex"]))  # 0a 03 08 90 03
    assert [r.hex() for r in client.responses] == [w.hex() for w in expected]


def test_decoded_steps_match_the_scripted_agents():
    transcript = _load_transcript()
    _, (first, second), endpoint = _run_session(transcript, unity_closes=True)
    behavior = transcript["trainer"]["behavior"]

    spec = endpoint.behavior_specs[behavior]
    assert spec.action_spec == ActionSpec(0, (3,))
    (obs_spec,) = spec.observation_specs
    assert obs_spec.shape == (20,)
    assert tuple(obs_spec.dimension_property) == (DimensionProperty.NONE,)
    assert obs_spec.observation_type == ObservationType.DEFAULT
    assert obs_spec.name == "VectorSensor_size20"
    assert set(first.specs) == {behavior} and second.specs == {}

    decision, terminal = first.steps[behavior]
    np.testing.assert_array_equal(decision.agent_id, [0, 1])
    np.testing.assert_array_equal(decision.obs[0], np.stack([_one_hot(10), _one_hot(0)]))
    np.testing.assert_array_equal(decision.reward, [0.0, 0.0])
    np.testing.assert_array_equal(decision.action_mask[0], [[False, False, False], [False, True, False]])
    assert len(terminal) == 0
    assert SideChannelRouter().dispatch(first.side_channel).stats == [
        ("Custom/Foo", 1.5, StatsAggregationMethod.MOST_RECENT)
    ]

    decision, terminal = second.steps[behavior]
    np.testing.assert_array_equal(terminal.agent_id, [0])
    np.testing.assert_array_equal(terminal.reward, np.array([0.99], dtype=np.float32))
    np.testing.assert_array_equal(terminal.interrupted, [False])
    np.testing.assert_array_equal(terminal.obs[0], _one_hot(17)[None])
    np.testing.assert_array_equal(decision.agent_id, [2, 1])
    np.testing.assert_array_equal(decision.reward, np.array([0.0, -0.01], dtype=np.float32))
    np.testing.assert_array_equal(decision.obs[0], np.stack([_one_hot(10), _one_hot(1)]))
