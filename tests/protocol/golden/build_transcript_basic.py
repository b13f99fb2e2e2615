"""Writes ``transcript_basic.json``: a Basic-environment session as raw protobuf bytes.

Run by hand after changing the scenario: ``python tests/protocol/golden/build_transcript_basic.py``.
``test_golden_transcript.py`` also rebuilds it in memory and checks the stored file is current.

The requests are what Unity's C# ``RpcCommunicator`` (com.unity.ml-agents 3.0, communication
API 1.5.0) sends for a scene with two Basic agents; the responses are what a trainer speaking
API 1.5.0 / package 1.1.0 must answer (docs/protocol.md, "Handshake, message by message", "Trainer → simulator" and "Side
channels"). Every byte is written down from
the protobuf wire format with ``protowire`` — no generated message classes are used here.

Field numbers used (docs/protocol.md, "Message schema"):
  UnityMessageProto      1 header, 2 unity_output, 3 unity_input
  HeaderProto            1 status
  UnityOutputProto       1 rl_output, 2 rl_initialization_output
  UnityInputProto        1 rl_input, 2 rl_initialization_input
  UnityRLOutputProto     2 agentInfos (map<string, ListAgentInfoProto{1 value}>), 3 side_channel
  UnityRLInputProto      1 agent_actions (map<string, ListAgentActionProto{1 value}>), 4 command, 5 side_channel
  UnityRLInitializationOutputProto  1 name, 2 communication_version, 5 brain_parameters,
                                    7 package_version, 8 capabilities
  UnityRLInitializationInputProto   1 seed, 2 communication_version, 3 package_version,
                                    4 capabilities, 5 num_areas
  UnityRLCapabilitiesProto          1..7 bools
  BrainParametersProto   7 brain_name, 8 is_training, 9 action_spec
  ActionSpecProto        1 num_continuous_actions, 2 num_discrete_actions, 3 discrete_branch_sizes
  AgentInfoProto         7 reward, 8 done, 9 max_step_reached, 10 id, 11 action_mask, 13 observations
  ObservationProto       1 shape, 4 float_data{1 data}, 6 dimension_properties, 8 name
  AgentActionProto       1 vector_actions_deprecated, 6 continuous_actions, 7 discrete_actions
"""
from __future__ import annotations

import json
import struct
import sys
import uuid
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from protowire import (  # noqa: E402
    float_field, int_field, ld, map_entry, packed_floats, packed_varints, string_field,
)

BEHAVIOR = "Basic?team=0"
SEED = 7
NUM_AREAS = 2
STATUS_OK, STATUS_CLOSING = 200, 400
RESET, STEP = 1, 0
STATS_CHANNEL = uuid.UUID("a1d8f7b7-cec8-50f9-b78b-d3e165a78520")
ENGINE_CONFIG_CHANNEL = uuid.UUID("e951342c-4f7e-11ea-b238-784f4387d1f7")
# mlagents-learn's engine settings defaults: 84x84, quality 5, time scale 20, target fps -1, capture 60
ENGINE_SETTINGS = dict(width=84, height=84, quality_level=5, time_scale=20.0,
                       target_frame_rate=-1, capture_frame_rate=60)
STEP_ACTIONS = ([[2], [1]], [[0], [2]])  # discrete actions answering M3 and M4, one row per deciding agent


# ------------------------------------------------------------------ side channel bytes (docs/protocol.md, "Framing")
def side_channel_message(channel: uuid.UUID, payload: bytes) -> bytes:
    """16-byte .NET-order GUID, int32 LE length, payload."""
    return channel.bytes_le + struct.pack("<i", len(payload)) + payload


def engine_config_side_channel() -> bytes:
    """Five engine-config messages, types 0..4 (docs/protocol.md, "Known channels")."""
    s = ENGINE_SETTINGS
    payloads = [
        struct.pack("<iii", 0, s["width"], s["height"]),
        struct.pack("<ii", 1, s["quality_level"]),
        struct.pack("<if", 2, s["time_scale"]),
        struct.pack("<ii", 3, s["target_frame_rate"]),
        struct.pack("<ii", 4, s["capture_frame_rate"]),
    ]
    return b"".join(side_channel_message(ENGINE_CONFIG_CHANNEL, p) for p in payloads)


def stats_side_channel(key: str, value: float, aggregation: int) -> bytes:
    """Stats message: string (int32 length + ASCII), float32 value, int32 aggregation."""
    raw_key = key.encode("ascii")
    payload = struct.pack("<i", len(raw_key)) + raw_key + struct.pack("<fi", value, aggregation)
    return side_channel_message(STATS_CHANNEL, payload)


# ------------------------------------------------------------------ messages
def header(status: int) -> bytes:
    return ld(1, int_field(1, status))


def capabilities() -> bytes:
    return b"".join(int_field(n, 1) for n in range(1, 8))


def one_hot(position: int) -> list[float]:
    return [1.0 if i == position else 0.0 for i in range(20)]


def agent_info(agent_id: int, reward: float, position: int, mask: list[bool],
               done: bool = False, max_step_reached: bool = False) -> bytes:
    """AgentInfoProto with one VectorSensor_size20 observation (dimension property NONE = 1)."""
    observation = (packed_varints(1, [20]) + ld(4, packed_floats(1, one_hot(position)))
                   + packed_varints(6, [1]) + string_field(8, "VectorSensor_size20"))
    fields = b""
    if reward != 0.0:
        fields += float_field(7, reward)
    if done:
        fields += int_field(8, 1)
    if max_step_reached:
        fields += int_field(9, 1)
    if agent_id != 0:
        fields += int_field(10, agent_id)
    return fields + packed_varints(11, mask) + ld(13, observation)


def unity_output_message(infos: list[bytes], side_channel: bytes, brain_parameters: bool) -> bytes:
    rl_output = map_entry(2, BEHAVIOR, b"".join(ld(1, info) for info in infos))
    if side_channel:
        rl_output += ld(3, side_channel)
    unity_output = ld(1, rl_output)
    if brain_parameters:
        action_spec = int_field(2, 1) + packed_varints(3, [3])
        brain = string_field(7, BEHAVIOR) + int_field(8, 1) + ld(9, action_spec)
        unity_output += ld(2, ld(5, brain))
    return header(STATUS_OK) + ld(2, unity_output)


def m1_initialization() -> bytes:
    init_output = (string_field(1, "AcademySingleton") + string_field(2, "1.5.0")
                   + string_field(7, "3.0.0") + ld(8, capabilities()))
    return header(STATUS_OK) + ld(2, ld(2, init_output))


def m3_first_data() -> bytes:
    infos = [agent_info(0, 0.0, 10, [False, False, False]),
             agent_info(1, 0.0, 0, [False, True, False])]  # at the left wall: "left" masked
    stats = stats_side_channel("Custom/Foo", 1.5, 1)  # MOST_RECENT
    return unity_output_message(infos, stats, brain_parameters=True)


def m4_done_and_successor() -> bytes:
    infos = [agent_info(0, 0.99, 17, [False, False, False], done=True),
             agent_info(2, 0.0, 10, [False, False, False]),
             agent_info(1, -0.01, 1, [False, False, False])]
    return unity_output_message(infos, b"", brain_parameters=False)


def init_response() -> bytes:
    init_input = (int_field(1, SEED) + string_field(2, "1.5.0") + string_field(3, "1.1.0")
                  + ld(4, capabilities()) + int_field(5, NUM_AREAS))
    return header(STATUS_OK) + ld(3, ld(2, init_input))


def reset_response(side_channel: bytes) -> bytes:
    rl_input = int_field(4, RESET) + ld(5, side_channel)
    return header(STATUS_OK) + ld(3, ld(1, rl_input))


def step_response(discrete_rows: list[list[int]]) -> bytes:
    """STEP (command 0 = default, so absent) with one AgentActionProto per deciding agent."""
    actions = b"".join(
        ld(1, packed_floats(1, [float(v) for v in row]) + packed_varints(7, row))
        for row in discrete_rows
    )
    return header(STATUS_OK) + ld(3, ld(1, map_entry(1, BEHAVIOR, actions)))


def transcript() -> dict:
    side_channel = engine_config_side_channel()
    return {
        "description": (
            "Two Basic agents (behavior 'Basic?team=0', discrete branch of 3, one-hot obs of 20). "
            "Requests as Unity's C# RpcCommunicator sends them; responses as a 1.5.0 trainer must "
            "answer. Hand-built from the protobuf wire format by build_transcript_basic.py."
        ),
        "trainer": {
            "seed": SEED, "num_areas": NUM_AREAS, "behavior": BEHAVIOR,
            "engine_settings": ENGINE_SETTINGS, "reset_side_channel_hex": side_channel.hex(),
            "step_discrete_actions": list(STEP_ACTIONS),
        },
        "exchanges": [
            {"name": "M1 initialization", "request_hex": m1_initialization().hex(),
             "response_hex": init_response().hex()},
            {"name": "M2 empty", "request_hex": header(STATUS_OK).hex(),
             "response_hex": reset_response(side_channel).hex()},
            {"name": "M3 first data + brain parameters + stats", "request_hex": m3_first_data().hex(),
             "response_hex": step_response(STEP_ACTIONS[0]).hex()},
            {"name": "M4 done agent and its successor", "request_hex": m4_done_and_successor().hex(),
             "response_hex": step_response(STEP_ACTIONS[1]).hex()},
            {"name": "M5 Unity closes", "request_hex": header(STATUS_CLOSING).hex(),
             "response_hex": header(STATUS_CLOSING).hex()},
        ],
        "trainer_close_response_hex": header(STATUS_CLOSING).hex(),
    }


if __name__ == "__main__":
    out = HERE / "transcript_basic.json"
    out.write_text(json.dumps(transcript(), indent=1) + "\n")
    print(f"wrote {out}")
