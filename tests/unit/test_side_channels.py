"""Side channel framing and payloads, checked against hand-written bytes from docs/protocol.md, "Known channels"."""
from __future__ import annotations

import logging
import uuid

import numpy as np
import pytest

from protos import side_channels as sc
from protos.errors import ProtocolError
from protos.types import StatsAggregationMethod

# --- the four observed wire examples of docs/protocol.md, "Known channels", byte for byte ---------------

GRAVITY_HEX = "07000000" + "gravity".encode().hex() + "00000000" + "c3f51c41"
SCALE_HEX = "05000000" + "scale".encode().hex() + "01000000" + "2b000000" + "00000000" + "0000003f" + "00004040"
MR_HEX = (
    "02000000" + "mr".encode().hex() + "01000000" + "2c000000" + "02000000" + "04000000"
    + "0000803f" + "00000040" + "0000a040" + "0000c040"
)
SCREEN_RESOLUTION_HEX = "00000000" + "54000000" + "54000000"


def test_env_float_wire_example():
    assert sc.encode_env_float("gravity", 9.81).hex() == GRAVITY_HEX


def test_uniform_sampler_wire_example():
    assert sc.encode_env_sampler("scale", "uniform", 43, (0.5, 3.0)).hex() == SCALE_HEX


def test_multirange_sampler_wire_example():
    payload = sc.encode_env_sampler("mr", "multirangeuniform", 44, [(1.0, 2.0), (5.0, 6.0)])
    assert payload.hex() == MR_HEX


def test_engine_config_wire_example_and_order():
    payloads = sc.encode_engine_config(84, 84, 5, 20.0, -1, 60)
    assert [p.hex() for p in payloads] == [
        SCREEN_RESOLUTION_HEX,
        "01000000" + "05000000",
        "02000000" + "0000a041",  # 20.0f
        "03000000" + "ffffffff",
        "04000000" + "3c000000",
    ]
    assert [sc.decode_engine_config(p) for p in payloads] == [
        ("screen_resolution", (84, 84)),
        ("quality_level", 5),
        ("time_scale", 20.0),
        ("target_frame_rate", -1),
        ("capture_frame_rate", 60),
    ]


def test_decode_env_parameters_from_wire_bytes():
    key, param = sc.decode_env_parameter(bytes.fromhex(GRAVITY_HEX))
    assert key == "gravity" and param.kind == "float" and param.seed is None
    assert param.values == (pytest.approx(9.81, abs=1e-6),)
    assert sc.decode_env_parameter(bytes.fromhex(SCALE_HEX)) == ("scale", sc.EnvParameter("uniform", 43, (0.5, 3.0)))
    assert sc.decode_env_parameter(bytes.fromhex(MR_HEX)) == (
        "mr", sc.EnvParameter("multirangeuniform", 44, (1.0, 2.0, 5.0, 6.0))
    )


def test_gaussian_sampler_bytes():
    payload = sc.encode_env_sampler("g", "gaussian", 7, (1.0, 0.5))
    assert payload.hex() == "01000000" + "67" + "01000000" + "07000000" + "01000000" + "0000803f" + "0000003f"


def test_uuid_constants():
    assert sc.STATS_CHANNEL_ID == uuid.uuid5(uuid.NAMESPACE_URL, "com.unity.ml-agents/StatsSideChannel")
    assert sc.TRAINING_ANALYTICS_CHANNEL_ID == uuid.uuid5(
        uuid.NAMESPACE_URL, "com.unity.ml-agents/TrainingAnalyticsSideChannel"
    )
    assert str(sc.ENGINE_CONFIG_CHANNEL_ID) == "e951342c-4f7e-11ea-b238-784f4387d1f7"
    assert str(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID) == "534c891e-810f-11ea-a9d0-822485860400"
    assert str(sc.FLOAT_PROPERTIES_CHANNEL_ID) == "60ccf7d0-4f7e-11ea-b238-784f4387d1f7"


# --- framing ----------------------------------------------------------------------------------

# .NET Guid byte order of the two channel ids (first three groups reversed), written by hand.
STATS_ID_LE_HEX = "b7f7d8a1" + "c8ce" + "f950" + "b78bd3e165a78520"
FLOAT_PROPS_ID_LE_HEX = "d0f7cc60" + "7e4f" + "ea11" + "b238784f4387d1f7"


def test_two_messages_in_one_buffer():
    data = sc.pack_messages([(sc.STATS_CHANNEL_ID, b"\x01\x02\x03"), (sc.FLOAT_PROPERTIES_CHANNEL_ID, b"")])
    assert data.hex() == STATS_ID_LE_HEX + "03000000" + "010203" + FLOAT_PROPS_ID_LE_HEX + "00000000"
    assert sc.unpack_messages(data) == [(sc.STATS_CHANNEL_ID, b"\x01\x02\x03"), (sc.FLOAT_PROPERTIES_CHANNEL_ID, b"")]


def test_empty_buffer_has_no_messages():
    assert sc.pack_messages([]) == b""
    assert sc.unpack_messages(b"") == []


@pytest.mark.parametrize(
    "hex_data, fragment",
    [
        (STATS_ID_LE_HEX[:20], "offset 0"),  # header cut inside the uuid
        (STATS_ID_LE_HEX + "0500", "offset 0"),  # header cut inside the length
        (STATS_ID_LE_HEX + "05000000" + "0102", "offset 20"),  # payload shorter than its length
        (STATS_ID_LE_HEX + "ffffffff", "negative"),  # length -1
        (STATS_ID_LE_HEX + "00000000" + "00", "offset 20"),  # a trailing stray byte
    ],
)
def test_truncated_or_garbled_buffers_raise(hex_data, fragment):
    with pytest.raises(ProtocolError, match=fragment):
        sc.unpack_messages(bytes.fromhex(hex_data))


def test_short_payloads_raise_protocol_error():
    with pytest.raises(ProtocolError, match="too short"):
        sc.decode_stat(bytes.fromhex("05000000") + b"ab")  # string of 5 bytes, only 2 present
    with pytest.raises(ProtocolError, match="too short"):
        sc.decode_float_property(bytes.fromhex("01000000") + b"k" + b"\x00\x00")
    with pytest.raises(ProtocolError, match="too short"):
        sc.PayloadReader(bytes.fromhex("03000000" + "0000803f")).read_float_list()


def test_non_ascii_string_rejected_with_its_name():
    with pytest.raises(ValueError, match="grävity"):
        sc.PayloadWriter().write_string("grävity")


def test_payload_primitives_bytes():
    data = (
        sc.PayloadWriter().write_int32(-2).write_float32(1.5)
        .write_string("ab").write_float_list([0.25]).getvalue()
    )
    assert data.hex() == "feffffff" + "0000c03f" + "02000000" + "6162" + "01000000" + "0000803e"
    reader = sc.PayloadReader(data)
    assert (reader.read_int32(), reader.read_float32(), reader.read_string(),
            reader.read_float_list()) == (-2, 1.5, "ab", [0.25])
    assert reader.remaining == 0


# --- stats and float properties ----------------------------------------------------------------

def test_stats_bytes_and_round_trip():
    payload = sc.encode_stat("Env/Score", 2.5, StatsAggregationMethod.SUM)
    assert payload.hex() == "09000000" + b"Env/Score".hex() + "00002040" + "02000000"
    for method in StatsAggregationMethod:
        assert sc.decode_stat(sc.encode_stat("k", -0.75, method)) == ("k", -0.75, method)


def test_unknown_aggregation_is_protocol_error():
    with pytest.raises(ProtocolError, match="aggregation"):
        sc.decode_stat(bytes.fromhex("01000000" + "6b" + "00000000" + "07000000"))


def test_float_property_round_trip():
    payload = sc.encode_float_property("speed", 0.5)
    assert payload.hex() == "05000000" + b"speed".hex() + "0000003f"
    assert sc.decode_float_property(payload) == ("speed", 0.5)


# --- samplers (Unity side) ---------------------------------------------------------------------

def test_seeded_uniform_sampler_reproduces_itself_and_stays_in_range():
    param = sc.EnvParameter("uniform", 43, (0.5, 3.0))
    first, second = param.sampler(), param.sampler()
    draws = [first() for _ in range(200)]
    assert draws == [second() for _ in range(200)]
    assert min(draws) >= 0.5 and max(draws) <= 3.0
    assert len(set(draws)) == 200  # a fresh value on every read
    other_seed = sc.EnvParameter("uniform", 44, (0.5, 3.0)).sampler()
    assert [other_seed() for _ in range(5)] != draws[:5]


def test_float_parameter_is_constant():
    draw = sc.EnvParameter("float", None, (9.5,)).sampler()
    assert [draw(), draw()] == [9.5, 9.5]


def test_gaussian_sampler_mean_and_spread():
    draw = sc.EnvParameter("gaussian", 3, (10.0, 2.0)).sampler()
    draws = np.array([draw() for _ in range(4000)])
    # standard error of the mean is 2/sqrt(4000) ~ 0.032; allow 6 of them
    assert abs(draws.mean() - 10.0) < 0.2
    assert 1.8 < draws.std() < 2.2


def test_multirange_picks_intervals_in_proportion_to_length():
    # lengths 1 and 3: expect 25% / 75%; binomial sd with n=4000 is ~0.7%, bounds are 5 sd.
    draw = sc.EnvParameter("multirangeuniform", 11, (0.0, 1.0, 10.0, 13.0)).sampler()
    draws = np.array([draw() for _ in range(4000)])
    in_first = (draws >= 0.0) & (draws <= 1.0)
    in_second = (draws >= 10.0) & (draws <= 13.0)
    assert np.all(in_first | in_second)
    assert 0.215 < in_first.mean() < 0.285
    # uniform inside the chosen interval: mean of the second interval's draws near 11.5
    assert abs(draws[in_second].mean() - 11.5) < 0.1


# --- router ------------------------------------------------------------------------------------

def test_router_drain_keeps_queue_order_then_clears():
    router = sc.SideChannelRouter()
    router.queue(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, b"\xaa")
    router.queue(sc.ENGINE_CONFIG_CHANNEL_ID, b"\xbb\xcc")
    data = router.drain()
    env_le = sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID.bytes_le.hex()
    engine_le = sc.ENGINE_CONFIG_CHANNEL_ID.bytes_le.hex()
    assert data.hex() == env_le + "01000000" + "aa" + engine_le + "02000000" + "bbcc"
    assert env_le == "1e894c530f81ea11a9d0822485860400"  # .NET order written by hand
    assert router.drain() == b""


def test_router_dispatch_stats_and_properties_and_skips_other_channels():
    other_id = uuid.UUID("12345678-1234-5678-1234-567812345678")
    router = sc.SideChannelRouter()
    data = sc.pack_messages([
        (sc.STATS_CHANNEL_ID, sc.encode_stat("a", 1.0, StatsAggregationMethod.AVERAGE)),
        (sc.FLOAT_PROPERTIES_CHANNEL_ID, sc.encode_float_property("p", 2.0)),
        (other_id, b"hello"),
        (sc.STATS_CHANNEL_ID, sc.encode_stat("b", 3.0, StatsAggregationMethod.MOST_RECENT)),
        (sc.FLOAT_PROPERTIES_CHANNEL_ID, sc.encode_float_property("p", 4.0)),
    ])
    incoming = router.dispatch(data)
    assert incoming.stats == [("a", 1.0, StatsAggregationMethod.AVERAGE), ("b", 3.0, StatsAggregationMethod.MOST_RECENT)]
    assert incoming.float_properties == {"p": 4.0}


def test_unknown_channel_warned_once_per_id(caplog):
    unknown_a = uuid.UUID("00000000-0000-0000-0000-0000000000aa")
    unknown_b = uuid.UUID("00000000-0000-0000-0000-0000000000bb")
    router = sc.SideChannelRouter()
    data = sc.pack_messages([
        (unknown_a, b"x"), (unknown_a, b"y"),
        (sc.STATS_CHANNEL_ID, sc.encode_stat("s", 1.0, StatsAggregationMethod.SUM)),
        (unknown_b, b""),
    ])
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        first = router.dispatch(data)
        router.dispatch(data)
    warnings = [r for r in caplog.records if r.name == "mlagents_like" and r.levelno == logging.WARNING]
    assert len(warnings) == 2
    assert str(unknown_a) in warnings[0].getMessage() and str(unknown_b) in warnings[1].getMessage()
    assert first.stats == [("s", 1.0, StatsAggregationMethod.SUM)]


def test_a_runs_simulators_warn_about_an_unknown_channel_once_between_them(caplog):
    from trainer.side_channel_payloads import make_routers

    unknown = uuid.UUID("00000000-0000-0000-0000-0000000000cc")
    data = sc.pack_messages([(unknown, b"x")])
    routers = make_routers(3)
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        for router in routers * 2:
            assert router.dispatch(data) == sc.IncomingSideChannelData()
    assert [r.getMessage().count(str(unknown)) for r in caplog.records] == [1]
