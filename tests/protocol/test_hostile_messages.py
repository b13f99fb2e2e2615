"""Property tests on random and mutated messages (docs/reliability.md, "Wire and messages").

* the codec (``codec.decode_message``): valid simulator messages of every shape
  (test_codec_properties' strategy), then bytes flipped, cut or inserted -> the records path
  (forced with ``records.MIN_ROWS`` = 1) and the protobuf path (``MIN_ROWS`` out of reach) give
  equal steps or both raise ProtocolError; no other exception escapes either;
* hostile specs -> one ProtocolError before anything is allocated for them (the limits of
  docs/protocol.md, "Behavior spec"), checked under an address-space limit in a subprocess;
* the side-channel parser (``SideChannelRouter.dispatch``): random bytes and mutated valid
  messages -> decoded values or ProtocolError, nothing else; valid ones round-trip.
"""
from __future__ import annotations

import subprocess
import sys
import textwrap
import uuid

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protos import records
from protos import side_channels as sc
from protos.communicator_objects import unity_message_pb2
from protos.errors import ProtocolError
from protos.types import StatsAggregationMethod
from tests.protocol.conftest import agent_info, brain_params, port  # noqa: F401 (port: a fixture)
from tests.protocol.test_codec_properties import NAMES, behaviors, brain_parameters, patched
from trainer.protocol import codec

PROPERTY = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.data_too_large])


@st.composite
def mutated(draw, data: bytes) -> bytes:
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        if not out:
            break
        at = draw(st.integers(0, len(out) - 1))
        how = draw(st.sampled_from(["flip", "flip", "cut", "insert", "varint"]))
        if how == "flip":
            out[at] ^= draw(st.integers(1, 255))
        elif how == "cut":
            del out[at:at + draw(st.integers(1, 16))]
        elif how == "insert":
            out[at:at] = draw(st.binary(min_size=1, max_size=8))
        else:  # a huge varint where a length or count may sit
            out[at:at + 1] = b"\xff\xff\xff\xff\x07"
    return bytes(out)


def _decode(payload: bytes, known, min_rows: int):
    with patched(records, "MIN_ROWS", min_rows):
        try:
            return codec.decode_message(payload, known)
        except ProtocolError as error:  # the only exception a message may cause
            return error


def _same(a, b) -> None:
    if isinstance(a, ProtocolError) or isinstance(b, ProtocolError):
        assert isinstance(a, ProtocolError) and isinstance(b, ProtocolError), (a, b)
        return
    if a.result is None or b.result is None:
        assert a.result is None and b.result is None
        return
    assert a.result.specs == b.result.specs and set(a.result.steps) == set(b.result.steps)
    assert {k: (d.count, d.deciding, d.kept.tolist()) for k, d in a.result.dropped.items()} == \
        {k: (d.count, d.deciding, d.kept.tolist()) for k, d in b.result.dropped.items()}
    for name in a.result.steps:
        for x, y in zip(a.result.steps[name], b.result.steps[name]):
            for field in ("reward", "agent_id", "group_id", "group_reward", "interrupted"):
                if hasattr(x, field):
                    np.testing.assert_array_equal(getattr(x, field), getattr(y, field), err_msg=field)
            for got, want in zip(x.obs, y.obs):
                np.testing.assert_array_equal(got, want)
            for got, want in zip(getattr(x, "action_mask", None) or (), getattr(y, "action_mask", None) or ()):
                np.testing.assert_array_equal(got, want)


@st.composite
def messages(draw) -> tuple[bytes, dict]:
    scene = draw(st.dictionaries(NAMES, behaviors(), min_size=1, max_size=2))
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 200
    for name, (spec, infos) in scene.items():
        message.unity_output.rl_output.agentInfos[name].value.extend(infos)
        message.unity_output.rl_initialization_output.brain_parameters.append(brain_parameters(name, spec.action_spec))
    known = draw(st.sampled_from([{}, {name: spec for name, (spec, _) in scene.items()}]))
    return message.SerializeToString(), known


@settings(PROPERTY, max_examples=60)  # two decodes of a message of up to 70 agents each: ~0.25 s an example
@given(drawn=messages(), data=st.data())
def test_mutated_messages_decode_alike_on_both_paths_or_are_refused_by_both(drawn, data):
    payload, known = drawn
    payload = data.draw(mutated(payload))
    _same(_decode(payload, known, 1), _decode(payload, known, 10**9))


@PROPERTY
@given(payload=st.binary(max_size=300))
def test_random_bytes_are_a_protocol_error_or_a_message(payload):
    _same(_decode(payload, {}, 1), _decode(payload, {}, 10**9))


# ------------------------------------------------------------------ hostile specs, memory-limited
HOSTILE_SPECS = [
    ("10^8 continuous actions", "brain_params('B', 10**8)", "declares 100000000 continuous actions"),
    ("10^6 branches", "brain_params('B', 0, [2] * 10**6)", "declares 1000000 discrete branches"),
    ("a branch of 10^9 options", "brain_params('B', 0, [10**9])", "1000000000 discrete options"),
    ("negative continuous count", "brain_params('B', -5)", "declares -5 continuous actions"),
    ("a zero-size branch", "brain_params('B', 0, [3, 0])", "every branch needs at least one option"),
    ("a branch count above its size list", "with_branch_count(brain_params('B', 0, [3, 2]), 5)",
     "declares 5 discrete branches but lists 2 branch sizes [3, 2]"),
    ("a branch count below its size list", "with_branch_count(brain_params('B', 1, [4]), 0)",
     "declares 0 discrete branches but lists 1 branch sizes [4]"),
    ("a negative branch count", "with_branch_count(brain_params('B', 0), -3)",
     "declares -3 discrete branches but lists 0 branch sizes []"),
]


def with_branch_count(params, count: int):
    params.action_spec.num_discrete_actions = count
    return params


@pytest.mark.parametrize("params, fault", [c[1:] for c in HOSTILE_SPECS], ids=[c[0] for c in HOSTILE_SPECS])
def test_hostile_specs_are_refused_in_process(params, fault):
    out = codec.decode_rl_output  # direct, for the message
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 200
    message.unity_output.rl_output.agentInfos["B"].value.append(agent_info(1, obs=[[0.5]]))
    message.unity_output.rl_initialization_output.brain_parameters.append(eval(params))
    with pytest.raises(ProtocolError, match="Behavior 'B' declares") as error:
        out(message.unity_output, {})
    assert fault in str(error.value)


def test_hostile_specs_and_images_stay_within_a_memory_limit():
    """The same, plus an observation shape of 10^12 floats and 10^4 agents each with a 4096 x
    4096 PNG sensor, in a subprocess whose address space is capped at its size after the imports
    plus 256 MiB: each is a ProtocolError, none a MemoryError."""
    script = textwrap.dedent("""
        import resource, sys
        from protos.communicator_objects import unity_message_pb2, observation_pb2
        from protos.errors import ProtocolError
        from tests.protocol.conftest import agent_info, brain_params, port  # noqa: F401 (port: a fixture)
        from trainer.protocol import codec

        def vm_bytes():
            with open("/proc/self/status") as f:
                return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))
        limit = vm_bytes() + (256 << 20)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        def message(params, infos):
            m = unity_message_pb2.UnityMessageProto()
            m.header.status = 200
            m.unity_output.rl_output.agentInfos["B"].value.extend(infos)
            m.unity_output.rl_initialization_output.brain_parameters.append(params)
            return m.SerializeToString()
        def image_agent(i, shape):
            info = agent_info(i)
            o = info.observations.add()
            o.shape.extend(shape)
            o.compression_type = observation_pb2.PNG
            o.compressed_data = b"\\x89PNG\\r\\n\\x1a\\n"
            return info
        cases = [
            message(brain_params("B", 10**8), [agent_info(1, obs=[[0.5]])]),
            message(brain_params("B", 0, [2] * 10**6), [agent_info(1, obs=[[0.5]])]),
            message(brain_params("B", 1), [image_agent(1, (3, 10**6, 10**6))]),
            message(brain_params("B", 1), [image_agent(i, (3, 4096, 4096)) for i in range(10**4)]),
        ]
        for payload in cases:
            try:
                codec.decode_message(payload, {})
            except ProtocolError as error:
                print("refused:", str(error)[:60])
            else:
                print("accepted")
    """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.count("refused:") == 4, r.stdout + r.stderr[-2000:]


# ------------------------------------------------------------------ side channels
def _valid_side_channel(draw) -> tuple[bytes, list, dict]:
    stats, floats, msgs = [], {}, []
    for _ in range(draw(st.integers(0, 4))):
        kind = draw(st.sampled_from(["stat", "float", "unknown"]))
        key = draw(st.text(alphabet="abcXYZ/ _.", max_size=12))
        value = draw(st.floats(width=32, allow_nan=False))
        if kind == "stat":
            method = draw(st.sampled_from(list(StatsAggregationMethod)))
            msgs.append((sc.STATS_CHANNEL_ID, sc.encode_stat(key, value, method)))
            stats.append((key, value, method))
        elif kind == "float":
            msgs.append((sc.FLOAT_PROPERTIES_CHANNEL_ID, sc.encode_float_property(key, value)))
            floats[key] = value
        else:
            msgs.append((uuid.UUID(int=draw(st.integers(0, 2**128 - 1))), draw(st.binary(max_size=20))))
    return sc.pack_messages(msgs), stats, floats


@st.composite
def side_channels(draw):
    return _valid_side_channel(draw)


@PROPERTY
@given(drawn=side_channels())
def test_valid_side_channel_data_round_trips(drawn):
    data, stats, floats = drawn
    incoming = sc.SideChannelRouter(warned_ids={uuid.UUID(int=0)} | set()).dispatch(data)
    assert [(k, np.float32(v), m) for k, v, m in incoming.stats] == [(k, np.float32(v), m) for k, v, m in stats]
    assert {k: np.float32(v) for k, v in incoming.float_properties.items()} == \
        {k: np.float32(v) for k, v in floats.items()}


@PROPERTY
@given(drawn=side_channels(), data=st.data(), raw=st.booleans())
def test_mutated_or_random_side_channel_data_is_decoded_or_a_protocol_error(drawn, data, raw):
    payload = data.draw(st.binary(max_size=200)) if raw else data.draw(mutated(drawn[0] or b"\0"))
    try:
        incoming = sc.SideChannelRouter().dispatch(payload)
    except ProtocolError:
        return
    assert all(isinstance(key, str) for key, _, _ in incoming.stats)


# ------------------------------------------------------------------ NaN/Inf agents, end to end
def test_agents_with_nan_are_left_out_and_the_simulator_still_gets_an_action_per_agent(port):
    """Over a real connection: the trainer sees only the finite agents and answers them; the
    simulator gets one action per deciding agent it sent, zeros where it sent NaN."""
    from tests.protocol.conftest import ScriptedUnity, m1, m2, rl_message
    from protos.types import ActionTuple
    from trainer.protocol.server import UnityEndpoint

    name = "W?team=0"
    infos = [agent_info(1, obs=[[0.5]]), agent_info(2, obs=[[float("nan")]]), agent_info(3, obs=[[0.25]]),
             agent_info(4, obs=[[1.0]], reward=float("inf"), done=True)]
    sim = ScriptedUnity(port, [m1(), m2(), rl_message({name: infos}, [brain_params(name, 2)])])
    endpoint = UnityEndpoint(port, timeout_wait=10, transport="http2")
    endpoint.start()
    sim.start()
    try:
        endpoint.handshake(seed=0, num_areas=1)
        result = endpoint.reset()
        decision, terminal = result.steps[name]
        assert decision.agent_id.tolist() == [1, 3] and len(terminal) == 0
        assert result.dropped[name].count == 2
        endpoint.send_step({name: ActionTuple(np.array([[0.5, 0.5], [-0.5, -0.5]], np.float32),
                                              np.zeros((2, 0), np.int32))})
    finally:
        endpoint.close()
        sim.finish()
    answered = sim.responses[-1].unity_input.rl_input.agent_actions[name].value
    assert [list(a.continuous_actions) for a in answered] == [[0.5, 0.5], [0.0, 0.0], [-0.5, -0.5]]
