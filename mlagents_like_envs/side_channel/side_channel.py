"""The base class of every side channel: a channel id, a queue of outgoing messages, and what
to do with an incoming one."""
from __future__ import annotations

import uuid
from abc import ABC, abstractmethod

from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage


class SideChannel(ABC):
    """Subclass it with the channel id your C# side channel uses; pass instances to
    ``UnityEnvironment(side_channels=[...])``. Queued messages leave with the next reset or step."""

    def __init__(self, channel_id: uuid.UUID) -> None:
        self._channel_id = channel_id
        self.message_queue: list[bytearray] = []

    def queue_message_to_send(self, msg: OutgoingMessage) -> None:
        self.message_queue.append(msg.buffer)

    @abstractmethod
    def on_message_received(self, msg: IncomingMessage) -> None:
        """Called once per message the environment sent on this channel (several per step possible)."""

    @property
    def channel_id(self) -> uuid.UUID:
        return self._channel_id
