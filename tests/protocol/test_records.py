"""Many AgentInfoProtos decoded from their bytes at once (protos.records) must give
exactly what the agent-by-agent parse gives, and step aside whenever it cannot."""
from __future__ import annotations

import numpy as np
import pytest

from protos import records, wire
from protos.communicator_objects import agent_info_pb2, observation_pb2
from protos.errors import ProtocolError
from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from tests.protocol.conftest import agent_info, brain_params
from tests.protocol.test_codec import output_with
from trainer.protocol import codec


@pytest.fixture(autouse=True)
def matrix_path_for_any_count(monkeypatch):
    """Messages here are small; the codec must take the matrix path for them anyway."""
    monkeypatch.setattr(records, "MIN_ROWS", 1)


def vec(size: int, name: str = "v") -> ObservationSpec:
    return ObservationSpec((size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, name)


def list_of(infos):
    out = output_with({"B": infos}, [brain_params("B", 2, (3, 2))])
    return out.rl_output.agentInfos["B"]


def both_paths(infos, spec):
    """(records path, protobuf path): codec.decode_agent_list on the list's bytes, and
    codec.steps_from_agent_infos on its parsed agents."""
    lst = list_of(infos)
    fast = codec.decode_agent_list("B", lst.SerializeToString(), None, spec)
    slow = codec.steps_from_agent_infos("B", lst.value, spec)
    return fast, slow


def assert_same_steps(a, b):
    for x, y in zip(a, b):  # (DecisionSteps, TerminalSteps)
        for field in ("reward", "agent_id", "group_id", "group_reward") + (("interrupted",) if hasattr(x, "interrupted") else ()):
            got, want = getattr(x, field), getattr(y, field)
            assert got.dtype == want.dtype, field
            np.testing.assert_array_equal(got, want, err_msg=field)
        for got, want in zip(x.obs, y.obs):
            assert got.dtype == want.dtype == np.float32
            np.testing.assert_array_equal(got, want)
        if getattr(x, "action_mask", None) is not None:
            for got, want in zip(x.action_mask, y.action_mask):
                np.testing.assert_array_equal(got, want)


SPEC = BehaviorSpec((vec(3, "pos"), vec(2, "vel")), ActionSpec(2, (3, 2)))


def allowing_an_option_per_branch(mask: np.ndarray, rng) -> list[bool]:
    """SPEC's branches (3, 2): a mask that masks a whole branch is refused (test_codec.py)."""
    for start, end in ((0, 3), (3, 5)):
        if mask[start:end].all():
            mask[start + int(rng.integers(0, end - start))] = False
    return mask.tolist()


def varied_infos(n: int, seed: int):
    """Every field and every varint length the wire can carry, in a realistic mix."""
    rng = np.random.default_rng(seed)
    ids = [1, 127, 128, 16383, 16384, 2**21, 2**31 - 1, -1, -5, 0]
    infos = []
    for k in range(n):
        masked = rng.random() < 0.8
        infos.append(agent_info(
            int(ids[k % len(ids)]) if k < len(ids) else int(rng.integers(0, 300)),
            obs=[rng.normal(size=3).astype(np.float32).tolist(), rng.normal(size=2).astype(np.float32).tolist()],
            reward=float(np.float32(rng.normal())) if rng.random() < 0.7 else 0.0,
            done=bool(rng.random() < 0.2), max_step=bool(rng.random() < 0.1),
            mask=allowing_an_option_per_branch(rng.random(5) < 0.3, rng) if masked else [],
            group_id=int(rng.integers(0, 3)) * int(rng.integers(0, 200)),
            group_reward=float(np.float32(rng.normal())) if rng.random() < 0.3 else 0.0,
        ))
    return infos


@pytest.mark.parametrize("seed", range(6))
def test_matrix_path_equals_agent_by_agent_on_varied_messages(seed, monkeypatch):
    infos = varied_infos(60, seed)
    lst = list_of(infos)
    assert records.decode("B", lst.SerializeToString(), [(3,), (2,)], 5) is not None  # really taken
    fast, slow = both_paths(infos, SPEC)
    assert_same_steps(fast, slow)
    monkeypatch.setattr(records, "decode", lambda *a: pytest.fail("matrix path used for the slow one"))
    codec.steps_from_agent_infos("B", lst.value, SPEC)  # the per-agent path really is another path
    # and against values written by hand for a few agents
    decision, terminal = slow
    expected_ids = [info.id for info in infos if not info.done]
    np.testing.assert_array_equal(fast[0].agent_id, expected_ids)


def test_values_read_by_hand():
    infos = [agent_info(k, obs=[[k, 2.5, -1.0], [0.0, float(k) / 4]], reward=0.5 * k, mask=[k % 2 == 0] + [False] * 4)
             for k in range(24)]
    infos[3] = agent_info(-7, obs=[[3, 2.5, -1.0], [0.0, 0.75]], reward=1.5, done=True, max_step=True, group_id=9,
                          group_reward=-2.0)
    lst = list_of(infos)
    got = records.decode("B", lst.SerializeToString(), [(3,), (2,)], 5)
    assert got.agent_id[:5].tolist() == [0, 1, 2, -7, 4]
    assert got.reward[:5].tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert got.done.tolist() == [k == 3 for k in range(24)]
    assert got.max_step[3] and got.group_id[3] == 9 and got.group_reward[3] == -2.0
    assert got.obs[0][4].tolist() == [4.0, 2.5, -1.0] and got.obs[1][2].tolist() == [0.0, 0.5]
    assert got.mask[:, 0].tolist() == [k % 2 == 0 and k != 3 for k in range(24)]
    assert not got.mask[:, 1:].any()


def test_same_length_different_layouts_are_split_by_layout():
    # reward (field 7) vs group_reward (field 15): both 5 bytes, so the records have one length
    infos = [agent_info(k, obs=[[1, 2, 3], [4, 5]], reward=1.0 if k % 2 else 0.0,
                        group_reward=0.0 if k % 2 else 1.0) for k in range(1, 31)]
    data = list_of(infos).SerializeToString()
    assert len(set(records.split_records(data)[1].tolist())) == 1
    got = records.decode("B", data, [(3,), (2,)], 5)
    assert got.reward.tolist() == [1.0 if k % 2 else 0.0 for k in range(1, 31)]
    assert got.group_reward.tolist() == [0.0 if k % 2 else 1.0 for k in range(1, 31)]
    fast, slow = both_paths(infos, SPEC)
    assert_same_steps(fast, slow)
    assert fast[0].reward.tolist() == [1.0 if k % 2 else 0.0 for k in range(1, 31)]


def test_compressed_observations_and_wrong_shapes_step_aside():
    infos = [agent_info(k, obs=[[1, 2, 3], [4, 5]]) for k in range(1, 31)]
    png = agent_info_pb2.AgentInfoProto()
    png.CopyFrom(infos[0])
    png.observations[1].compression_type = observation_pb2.PNG
    assert records.decode("B", list_of(infos[:29] + [png]).SerializeToString(), [(3,), (2,)], 5) is None
    # a shape other than the spec's: the per-agent parse gives the precise error
    bad = infos[:29] + [agent_info(99, obs=[[1, 2, 3], [4, 5, 6]])]
    assert records.decode("B", list_of(bad).SerializeToString(), [(3,), (2,)], 5) is None
    lst = list_of(bad)
    with pytest.raises(ProtocolError, match="agent id 99"):
        codec.decode_agent_list("B", lst.SerializeToString(), None, SPEC)


def test_non_finite_values_are_still_left_out_on_the_matrix_path():
    infos = [agent_info(k, obs=[[1, 2, 3], [4, 5]], reward=0.1) for k in range(1, 31)]
    for bad in (agent_info(8, obs=[[1, float("nan"), 3], [4, 5]], reward=0.1),
                agent_info(8, obs=[[1, 2, 3], [4, 5]], reward=float("inf"))):
        infos[7] = bad
        lst = list_of(infos)
        assert records.decode("B", lst.SerializeToString(), [(3,), (2,)], 5) is not None
        decision, _ = codec.decode_agent_list("B", lst.SerializeToString(), None, SPEC)
        assert decision.agent_id.tolist() == [k for k in range(1, 31) if k != 8]
        assert np.isfinite(decision.obs[0]).all() and np.isfinite(decision.reward).all()


def test_split_records_rejects_other_fields_and_truncation():
    data = list_of([agent_info(k, obs=[[1, 2, 3], [4, 5]]) for k in range(3)]).SerializeToString()
    starts, lengths = records.split_records(data)
    assert len(starts) == 3 and starts[0] == 2 and int(lengths.sum()) == len(data) - 6
    assert records.split_records(data[:-1]) is None
    assert records.split_records(b"\x12" + data[1:]) is None


def test_records_of_one_length_are_read_in_place():
    infos = [agent_info(k, obs=[[k, 0, 1], [2, -k]], reward=0.25 * k) for k in range(1, 41)]
    data = list_of(infos).SerializeToString()
    starts, lengths = records.split_records(data)
    stride = int(lengths[0]) + 2
    assert (lengths == lengths[0]).all() and starts.tolist() == list(range(2, len(data), stride))
    got = records.decode("B", data, [(3,), (2,)], 5)
    assert got.agent_id.tolist() == list(range(1, 41))
    assert got.reward.tolist() == [0.25 * k for k in range(1, 41)]
    assert got.obs[1][:, 1].tolist() == [-k for k in range(1, 41)]


def test_lengths_that_only_add_up_to_a_fixed_stride_are_not_read_in_place():
    # record lengths 10+1, 8, 12-1, 10: first == last and the total is n * (first + 2), yet the
    # records do not sit at a fixed stride
    infos = [agent_info(1, obs=[[1.0] * 3, [2.0] * 2], reward=0.5), agent_info(2, obs=[[1.0] * 3, [2.0] * 2]),
             agent_info(3, obs=[[1.0] * 3, [2.0] * 2], reward=0.5, done=True, max_step=True),
             agent_info(4, obs=[[1.0] * 3, [2.0] * 2], reward=0.5)]
    infos = infos * 8
    data = list_of(infos).SerializeToString()
    starts, lengths = records.split_records(data)
    got = records.decode("B", data, [(3,), (2,)], 5)
    assert got.agent_id.tolist() == [1, 2, 3, 4] * 8
    assert got.reward.tolist() == [0.5, 0.0, 0.5, 0.5] * 8
    assert got.done.tolist() == [False, False, True, False] * 8


def test_records_longer_than_127_bytes_have_longer_headers():
    spec_shapes = [(40,), (2,)]
    infos = [agent_info(k, obs=[[float(k)] * (40 if k % 3 else 20), [1, 2]], reward=0.1 * (k % 2)) for k in range(1, 31)]
    data = list_of(infos).SerializeToString()
    starts, lengths = records.split_records(data)
    assert (lengths > 127).any() and (lengths < 128).any() and len(starts) == 30
    assert all(data[s - 2] == 0x0A or data[s - 3] == 0x0A for s in starts.tolist())
    # rows whose first observation has 20 floats do not match the spec: the per-agent parse decides
    assert records.decode("B", data, spec_shapes, 5) is None
    long_only = [info for k, info in enumerate(infos, 1) if k % 3]
    got = records.decode("B", list_of(long_only).SerializeToString(), spec_shapes, 5)
    assert got.obs[0][:, 0].tolist() == [float(k) for k in range(1, 31) if k % 3]
    assert np.allclose(got.reward, [0.1 * (k % 2) for k in range(1, 31) if k % 3])


# ------------------------------------------------------------------ actions (the stub's side)
def action_list(rows):
    from protos.communicator_objects import unity_input_pb2
    msg = unity_input_pb2.UnityInputProto()
    value = msg.rl_input.agent_actions["B"].value
    for deprecated, continuous, discrete in rows:
        a = value.add()
        a.vector_actions_deprecated.extend(deprecated)
        a.continuous_actions.extend(continuous)
        a.discrete_actions.extend(discrete)
    return unity_input_pb2.UnityInputProto.FromString(msg.SerializeToString()).rl_input.agent_actions["B"]


def test_actions_from_bytes_equal_the_fields_whatever_the_writer():
    rng = np.random.default_rng(3)
    n = 40
    cont = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
    disc = rng.integers(0, 3, (n, 2)).astype(np.int32)
    disc[5] = [200, 70000]  # multi-byte varints
    disc[6] = [-1, 0]  # a negative int32 is a 10-byte varint
    ours = action_list([((), c, d) for c, d in zip(cont.tolist(), disc.tolist())])
    mlagents_style = action_list([(c + [float(x) for x in d], c, d) for c, d in zip(cont.tolist(), disc.tolist())])
    for lst in (ours, mlagents_style):
        got = records.decode_actions("B", lst.SerializeToString(), 2, 2)
        assert got is not None
        np.testing.assert_array_equal(got[0], cont)
        np.testing.assert_array_equal(got[1], disc)
        assert got[0].dtype == np.float32 and got[1].dtype == np.int32
    only_continuous = action_list([((), c, ()) for c in cont.tolist()])
    got = records.decode_actions("B", only_continuous.SerializeToString(), 2, 0)
    np.testing.assert_array_equal(got[0], cont)
    assert got[1].shape == (n, 0)
    # widths other than the spec's: the per-agent path decides (and reports)
    assert records.decode_actions("B", only_continuous.SerializeToString(), 3, 0) is None
    assert records.decode_actions("B", ours.SerializeToString(), 2, 1) is None


def test_stub_applies_many_actions_from_bytes_like_one_by_one(monkeypatch):
    from unity_stub_env import make_task
    from unity_stub_env.academy import ActionCountError, Academy

    fast, slow = Academy(make_task("ball3d", num_areas=3, seed=0)), Academy(make_task("ball3d", num_areas=3, seed=0))
    rng = np.random.default_rng(0)
    cont = rng.uniform(-1, 1, (36, 2)).astype(np.float32)
    lst = action_list([((), c, ()) for c in cont.tolist()])
    taken = []
    real = records.decode_actions
    monkeypatch.setattr(records, "decode_actions", lambda *a: taken.append(real(*a)) or taken[-1])
    fast.apply_action_list(lst)
    assert taken and taken[0] is not None  # the bytes path really ran
    slow.apply_actions(lst.value)
    np.testing.assert_array_equal(fast.continuous, cont)
    np.testing.assert_array_equal(slow.continuous, cont)
    with pytest.raises(ActionCountError, match="35 actions"):
        fast.apply_action_list(action_list([((), c, ()) for c in cont[:35].tolist()]))
    with pytest.raises(ActionCountError, match="continuous actions of length"):
        fast.apply_action_list(action_list([((), c + [0.0], ()) for c in cont.tolist()]))
    fast.apply_action_list(None)
    assert not fast.continuous.any()


def _walk(data: bytes):
    """Reference cut of ``repeated bytes = 1`` records, one record at a time."""
    starts, lengths, pos = [], [], 0
    while pos < len(data):
        assert data[pos] == 0x0A
        size, shift, pos = 0, 0, pos + 1
        while True:
            byte = data[pos]
            pos += 1
            size |= (byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                break
        starts.append(pos)
        lengths.append(size)
        pos += size
    return starts, lengths


@pytest.mark.timeout(60)
def test_split_records_skips_runs_of_one_length_exactly_like_a_record_walk():
    rng = np.random.default_rng(7)
    for trial in range(300):
        # runs of equal lengths, lengths that repeat later, payloads full of 0x0A and length bytes
        sizes = []
        while len(sizes) < rng.integers(1, 60):
            sizes += [int(rng.choice([0, 1, 8, 10, 45, 72, 74, 127, 128, 300]))] * int(rng.integers(1, 12))
        data = b"".join(b"\x0a" + wire.varint(s) + bytes(rng.choice([0x0A, s % 256, 0x48], size=s).astype(np.uint8))
                        for s in sizes)
        got = records.split_records(data)
        starts, lengths = _walk(data)
        assert got is not None
        assert got[0].tolist() == starts and got[1].tolist() == lengths, sizes
        for cut in (1, 2, len(data) // 2):  # truncated messages are refused, never looped on
            if cut < len(data):
                assert records.split_records(data[:-cut]) is None or _walk_ok(data[:-cut])


def _walk_ok(data: bytes) -> bool:
    """True if ``data`` still happens to cut into whole records (a cut at a record boundary)."""
    try:
        starts, lengths = _walk(data)
    except (AssertionError, IndexError):
        return False
    return starts[-1] + lengths[-1] == len(data) if starts else True


# ------------------------------------------------------------------ whole messages
def _message(outputs: dict, params=(), side_channel: bytes = b"side") -> bytes:
    from protos.communicator_objects import unity_message_pb2
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 200
    message.unity_output.CopyFrom(output_with(outputs, params))
    message.unity_output.rl_output.side_channel = side_channel
    return message.SerializeToString()


def test_large_lists_are_taken_out_before_parsing_and_decoded_once(monkeypatch):
    big = varied_infos(70, 3)
    small = [agent_info(k, obs=[[1.0, 2.0]], reward=0.5) for k in range(1, 4)]
    params = [brain_params("B", 2, (3, 2)), brain_params("S", 1)]
    payload = _message({"B": big, "S": small}, params)
    split = records.split_agent_lists(payload, 64)
    assert split is not None and set(split[1]) == {"B"}  # only the list of >= 64 agents
    body, raw = split
    assert len(body) < len(payload) - len(raw["B"][0])
    monkeypatch.setattr(records, "MIN_ROWS", 64)
    from_bytes = []
    real = codec._list_fields
    monkeypatch.setattr(codec, "_list_fields", lambda name, *a: from_bytes.append(name) or real(name, *a))
    fast = codec.decode_message(payload, {}).result  # first message: specs from the raw list's first agent
    assert from_bytes == ["B"]
    monkeypatch.setattr(records, "split_agent_lists", lambda *a: pytest.fail("unused here"))
    from protos.communicator_objects import unity_message_pb2
    slow = codec.decode_rl_output(unity_message_pb2.UnityMessageProto.FromString(payload).unity_output, {})
    assert fast.specs == slow.specs and set(fast.specs) == {"B", "S"}
    assert fast.specs["B"].action_spec == ActionSpec(2, (3, 2))
    assert fast.side_channel == slow.side_channel == b"side"
    assert list(fast.steps) == list(slow.steps)
    for name in ("B", "S"):
        assert_same_steps(fast.steps[name], slow.steps[name])
    parsed = codec.steps_from_agent_infos("B", big, fast.specs["B"])  # and against the protos themselves
    assert_same_steps(fast.steps["B"], parsed)


def test_unusual_messages_are_parsed_whole():
    big = [agent_info(k, obs=[[1.0, 2.0, 3.0], [4.0, 5.0]]) for k in range(1, 80)]
    payload = _message({"B": big}, [brain_params("B", 2, (3, 2))])
    assert records.split_agent_lists(payload, 64) is not None
    assert records.split_agent_lists(payload, 100) is None  # no list that large
    assert records.split_agent_lists(payload + payload[:2], 64) is None  # a truncated extra field
    key = payload.index(b"\x0a\x01B\x12")  # the map entry's key "B", then its value
    assert records.split_agent_lists(payload[:key + 2] + b"\xff" + payload[key + 3:], 64) is None  # not UTF-8
    twice = payload + payload[payload.index(b"\x12", 2):]  # unity_output sent twice (protobuf merges)
    assert records.split_agent_lists(twice, 64) is None
    m1 = _message({}, [])  # no agents at all (e.g. the handshake's second message)
    assert records.split_agent_lists(m1, 1) is None


def test_a_garbled_large_list_is_a_protocol_error_not_a_crash(monkeypatch):
    good = [agent_info(k, obs=[[1.0, 2.0, 3.0], [4.0, 5.0]], reward=0.1) for k in range(1, 80)]
    payload = bytearray(_message({"B": good}, [brain_params("B", 2, (3, 2))]))
    body, raw = records.split_agent_lists(bytes(payload), 64)
    data, cut = raw["B"]
    starts, lengths, _ = cut
    garbled = bytearray(data)
    garbled[starts[5]:starts[5] + lengths[5]] = b"\xff" * int(lengths[5])  # a record that is no AgentInfoProto
    spec = BehaviorSpec((vec(3), vec(2)), ActionSpec(2, (3, 2)))
    with pytest.raises(ProtocolError, match="not valid AgentInfoProtos"):
        codec.decode_rl_output(
            __import__("protos.communicator_objects.unity_message_pb2", fromlist=["x"])
            .UnityMessageProto.FromString(body).unity_output,
            {"B": spec}, {"B": (bytes(garbled), records._cut(bytes(garbled)))})


def test_messages_too_small_for_a_large_list_are_not_walked(monkeypatch):
    """The codec looks for lists to cut out only in a message that can hold MIN_ROWS records of
    the known behavior with the fewest observation floats (and always before any is known)."""
    monkeypatch.setattr(records, "MIN_ROWS", 64)
    spec = BehaviorSpec((vec(3), vec(2)), ActionSpec(2, (3, 2)))
    assert codec._split_threshold({}) == 0
    assert codec._split_threshold({"B": spec}) == 64 * (2 + 4 * 5)
    looked = []
    real = records.split_agent_lists
    monkeypatch.setattr(records, "split_agent_lists", lambda *a: looked.append(len(a[0])) or real(*a))
    infos = [agent_info(k, obs=[[1.0, 2.0, 3.0], [4.0, 5.0]]) for k in range(1, 80)]
    small, large = (_message({"B": infos[:n]}, [brain_params("B", 2, (3, 2))]) for n in (20, 79))
    assert len(small) < 64 * 22 <= len(large)
    codec.decode_message(small, {"B": spec})
    assert looked == []
    first = codec.decode_message(small, {})  # nothing known yet: looked at (and nothing taken)
    assert looked == [len(small)] and len(first.result.steps["B"][0]) == 20
    result = codec.decode_message(large, {"B": spec}).result
    assert looked[-1] == len(large) and result.steps["B"][0].agent_id.tolist() == list(range(1, 80))


def test_a_message_that_is_not_one_and_a_closing_one():
    with pytest.raises(codec.NotAMessageError, match="not a valid UnityMessageProto"):
        codec.decode_message(b"\xff\xff\xff", {})
    from protos.communicator_objects import unity_message_pb2
    closing = unity_message_pb2.UnityMessageProto()
    closing.header.status = 400
    decoded = codec.decode_message(closing.SerializeToString(), {})
    assert decoded.message.header.status == 400 and decoded.result is None
