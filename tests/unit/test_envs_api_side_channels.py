"""mlagents_like_envs.side_channel: message bytes written out by hand (little-endian), and routing."""
from __future__ import annotations

import logging
import struct
import uuid

import pytest

from mlagents_like_envs.exception import (
    UnityCommunicationException,
    UnityEnvironmentException,
    UnitySideChannelException,
)
from mlagents_like_envs.side_channel import IncomingMessage, OutgoingMessage, SideChannel
from mlagents_like_envs.side_channel.engine_configuration_channel import EngineConfig, EngineConfigurationChannel
from mlagents_like_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel
from mlagents_like_envs.side_channel.float_properties_channel import FloatPropertiesChannel
from mlagents_like_envs.side_channel.raw_bytes_channel import RawBytesChannel
from mlagents_like_envs.side_channel.side_channel_manager import SideChannelManager
from mlagents_like_envs.side_channel.stats_side_channel import StatsAggregationMethod, StatsSideChannel

ONE_F = b"\x00\x00\x80\x3f"  # 1.0 as float32
TWO_F = b"\x00\x00\x00\x40"  # 2.0


def i32(value: int) -> bytes:
    return struct.pack("<i", value)


def test_outgoing_message_bytes():
    msg = OutgoingMessage()
    msg.write_bool(True)
    msg.write_int32(1)
    msg.write_float32(1.0)
    msg.write_string("ab")
    msg.write_float32_list([1.0, 2.0])
    assert bytes(msg.buffer) == b"\x01" + b"\x01\x00\x00\x00" + ONE_F + b"\x02\x00\x00\x00ab" + i32(2) + ONE_F + TWO_F
    with pytest.raises(ValueError, match="ASCII"):
        msg.write_string("é")
    msg.set_raw_bytes(b"xyz")
    assert msg.buffer == bytearray(b"xyz")


def test_incoming_message_reads_in_order_then_defaults():
    msg = IncomingMessage(b"\x01" + i32(-5) + TWO_F + i32(3) + b"key" + i32(2) + ONE_F + TWO_F)
    assert msg.read_bool() is True
    assert msg.read_int32() == -5
    assert msg.read_float32() == 2.0
    assert msg.read_string() == "key"
    assert msg.read_float32_list() == [1.0, 2.0]
    assert (msg.read_bool(True), msg.read_int32(9), msg.read_float32(0.5), msg.read_string("d"),
            msg.read_float32_list([4.0])) == (True, 9, 0.5, "d", [4.0])
    assert msg.get_raw_bytes()[:1] == bytearray(b"\x01")


def test_engine_configuration_messages():
    channel = EngineConfigurationChannel()
    assert channel.channel_id == uuid.UUID("e951342c-4f7e-11ea-b238-784f4387d1f7")
    channel.set_configuration_parameters(width=80, height=60, time_scale=2.0)
    assert [bytes(m) for m in channel.message_queue] == [i32(0) + i32(80) + i32(60), i32(2) + TWO_F]
    channel.message_queue = []
    channel.set_configuration(EngineConfig.default_config())
    assert [struct.unpack_from("<i", m)[0] for m in channel.message_queue] == [0, 1, 2, 3, 4]
    with pytest.raises(UnitySideChannelException, match="width and height"):
        channel.set_configuration_parameters(width=10)
    with pytest.raises(UnityCommunicationException):
        channel.on_message_received(IncomingMessage(b""))


def test_environment_parameter_messages():
    channel = EnvironmentParametersChannel()
    assert channel.channel_id == uuid.UUID("534c891e-810f-11ea-a9d0-822485860400")
    channel.set_float_parameter("k", 2.0)
    channel.set_uniform_sampler_parameters("k", 1.0, 2.0, 7)
    channel.set_gaussian_sampler_parameters("k", 2.0, 1.0, 7)
    channel.set_multirangeuniform_sampler_parameters("k", [(1.0, 2.0)], 7)
    key = i32(1) + b"k"
    assert [bytes(m) for m in channel.message_queue] == [
        key + i32(0) + TWO_F,
        key + i32(1) + i32(7) + i32(0) + ONE_F + TWO_F,
        key + i32(1) + i32(7) + i32(1) + TWO_F + ONE_F,
        key + i32(1) + i32(7) + i32(2) + i32(2) + ONE_F + TWO_F,
    ]
    assert int(channel.SamplerTypes.MULTIRANGEUNIFORM) == 2 and int(channel.EnvironmentDataTypes.SAMPLER) == 1


def test_stats_float_properties_and_raw_bytes_channels():
    stats = StatsSideChannel()
    stats.on_message_received(IncomingMessage(i32(1) + b"s" + TWO_F + i32(1)))
    stats.on_message_received(IncomingMessage(i32(1) + b"s" + ONE_F + i32(3)))
    assert stats.get_and_reset_stats() == {"s": [(2.0, StatsAggregationMethod.MOST_RECENT),
                                                 (1.0, StatsAggregationMethod.HISTOGRAM)]}
    assert stats.get_and_reset_stats() == {}

    props = FloatPropertiesChannel()
    props.on_message_received(IncomingMessage(i32(1) + b"p" + ONE_F))
    props.set_property("q", 2.0)
    assert props.get_property("p") == 1.0 and props.get_property("missing") is None
    assert props.list_properties() == ["p", "q"] and props.get_property_dict_copy() == {"p": 1.0, "q": 2.0}
    assert bytes(props.message_queue[0]) == i32(1) + b"q" + TWO_F

    raw = RawBytesChannel(uuid.UUID(int=5))
    raw.on_message_received(IncomingMessage(b"\x00\xff"))
    raw.send_raw_data(bytearray(b"hi"))
    assert raw.get_and_clear_received_messages() == [bytearray(b"\x00\xff")]
    assert raw.get_and_clear_received_messages() == [] and raw.message_queue == [bytearray(b"hi")]


class Recorder(SideChannel):
    """A user-defined channel: what it receives, read with IncomingMessage."""

    def __init__(self, channel_id: uuid.UUID) -> None:
        super().__init__(channel_id)
        self.received: list[str] = []

    def on_message_received(self, msg: IncomingMessage) -> None:
        self.received.append(msg.read_string())


def test_manager_packs_and_routes(caplog):
    first, second = Recorder(uuid.UUID(int=1)), Recorder(uuid.UUID(int=2))
    manager = SideChannelManager([first, second])
    for channel, text in ((second, "b"), (first, "a1"), (first, "a2")):
        msg = OutgoingMessage()
        msg.write_string(text)
        channel.queue_message_to_send(msg)
    packed = manager.generate_side_channel_messages()
    frame = lambda cid, payload: uuid.UUID(int=cid).bytes_le + i32(len(payload)) + payload  # noqa: E731
    # channel order (as registered), then queue order; the queues are emptied
    assert bytes(packed) == (frame(1, i32(2) + b"a1") + frame(1, i32(2) + b"a2") + frame(2, i32(1) + b"b"))
    assert first.message_queue == [] and manager.generate_side_channel_messages() == bytearray()

    unknown = frame(9, b"zz")
    with caplog.at_level(logging.WARNING):
        manager.process_side_channel_message(packed + unknown + unknown)
    assert first.received == ["a1", "a2"] and second.received == ["b"]
    assert sum("Unknown side channel" in r.message for r in caplog.records) == 1
    with pytest.raises(UnityEnvironmentException, match="side channel"):
        manager.process_side_channel_message(packed[:-3])
    with pytest.raises(UnityEnvironmentException, match="same channel id"):
        SideChannelManager([Recorder(uuid.UUID(int=1)), Recorder(uuid.UUID(int=1))])
