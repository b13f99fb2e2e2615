"""Raw bytes both ways on a channel id of your choice."""
from __future__ import annotations

import uuid

from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel


class RawBytesChannel(SideChannel):
    def __init__(self, channel_id: uuid.UUID) -> None:
        super().__init__(channel_id)
        self._received_messages: list[bytearray] = []

    def on_message_received(self, msg: IncomingMessage) -> None:
        self._received_messages.append(msg.get_raw_bytes())

    def get_and_clear_received_messages(self) -> list[bytearray]:
        received, self._received_messages = self._received_messages, []
        return received

    def send_raw_data(self, data: bytes | bytearray) -> None:
        msg = OutgoingMessage()
        msg.set_raw_bytes(data)
        self.queue_message_to_send(msg)
