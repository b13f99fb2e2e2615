"""Float properties (both ways): named floats that Python and the scene can each set."""
from __future__ import annotations

import uuid

from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel
from protos.side_channels import FLOAT_PROPERTIES_CHANNEL_ID, decode_float_property, encode_float_property


class FloatPropertiesChannel(SideChannel):
    def __init__(self, channel_id: uuid.UUID | None = None) -> None:
        super().__init__(FLOAT_PROPERTIES_CHANNEL_ID if channel_id is None else channel_id)
        self._float_properties: dict[str, float] = {}

    def on_message_received(self, msg: IncomingMessage) -> None:
        key, value = decode_float_property(bytes(msg.buffer[msg.offset:]))
        self._float_properties[key] = value

    def set_property(self, key: str, value: float) -> None:
        """Set it here and queue it for the scene."""
        self._float_properties[key] = value
        msg = OutgoingMessage()
        msg.set_raw_bytes(encode_float_property(key, value))
        self.queue_message_to_send(msg)

    def get_property(self, key: str) -> float | None:
        return self._float_properties.get(key)

    def list_properties(self) -> list[str]:
        return list(self._float_properties)

    def get_property_dict_copy(self) -> dict[str, float]:
        return dict(self._float_properties)
