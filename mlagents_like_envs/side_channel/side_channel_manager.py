"""Routes one exchange's side channel bytes to the registered channels, and packs theirs."""
from __future__ import annotations

import logging
import uuid

from mlagents_like_envs.exception import UnityEnvironmentException
from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel
from protos.errors import ProtocolError
from protos.side_channels import pack_messages, unpack_messages

logger = logging.getLogger(__name__)


class SideChannelManager:
    def __init__(self, side_channels: list[SideChannel] | None) -> None:
        self._side_channels_dict = self._get_side_channels_dict(side_channels)
        self._warned: set[uuid.UUID] = set()

    def process_side_channel_message(self, data: bytes) -> None:
        """Hand each message of ``data`` to its channel; unknown channel ids are warned about once."""
        try:
            messages = unpack_messages(data)
        except ProtocolError as error:
            raise UnityEnvironmentException(f"Could not read the side channel data: {error}") from None
        for channel_id, payload in messages:
            channel = self._side_channels_dict.get(channel_id)
            if channel is not None:
                channel.on_message_received(IncomingMessage(payload))
            elif channel_id not in self._warned:
                self._warned.add(channel_id)
                logger.warning("Unknown side channel data received. Channel type: %s.", channel_id)

    def generate_side_channel_messages(self) -> bytearray:
        """Every channel's queued messages, framed, in channel then queue order; the queues empty."""
        messages = []
        for channel_id, channel in self._side_channels_dict.items():
            messages += [(channel_id, bytes(message)) for message in channel.message_queue]
            channel.message_queue = []
        return bytearray(pack_messages(messages))

    @staticmethod
    def _get_side_channels_dict(side_channels: list[SideChannel] | None) -> dict[uuid.UUID, SideChannel]:
        found: dict[uuid.UUID, SideChannel] = {}
        for channel in side_channels or []:
            if channel.channel_id in found:
                raise UnityEnvironmentException(
                    f"There cannot be two side channels with the same channel id {channel.channel_id}.")
            found[channel.channel_id] = channel
        return found
