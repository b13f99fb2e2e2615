"""Side channels: messages beside the agents' data, in both directions (mlagents_envs' modules).

``SideChannel`` subclasses get ``IncomingMessage``s from the environment and queue
``OutgoingMessage``s; the environment packs them into each exchange (``side_channel_manager``).
Framing and payload primitives are the project's one wire format, ``protos.side_channel_wire``.
"""
from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel

__all__ = ["IncomingMessage", "OutgoingMessage", "SideChannel"]
