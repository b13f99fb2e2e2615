"""Engine configuration (Python → Unity): screen size, quality level, time scale, frame rates."""
from __future__ import annotations

from typing import NamedTuple

from mlagents_like_envs.exception import UnityCommunicationException, UnitySideChannelException
from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel
from protos.side_channels import ENGINE_CONFIG_CHANNEL_ID, EngineConfigType


class EngineConfig(NamedTuple):
    width: int | None
    height: int | None
    quality_level: int | None
    time_scale: float | None
    target_frame_rate: int | None
    capture_frame_rate: int | None

    @staticmethod
    def default_config() -> "EngineConfig":
        """What mlagents-learn sends by default (80x80, quality 1, time scale 20, no target
        frame rate, capture at 60)."""
        return EngineConfig(80, 80, 1, 20.0, -1, 60)


class EngineConfigurationChannel(SideChannel):
    ConfigurationType = EngineConfigType

    def __init__(self) -> None:
        super().__init__(ENGINE_CONFIG_CHANNEL_ID)

    def on_message_received(self, msg: IncomingMessage) -> None:
        raise UnityCommunicationException(
            "The EngineConfigurationChannel received a message from Unity; it only sends.")

    def set_configuration_parameters(self, width: int | None = None, height: int | None = None,
                                     quality_level: int | None = None, time_scale: float | None = None,
                                     target_frame_rate: int | None = None,
                                     capture_frame_rate: int | None = None) -> None:
        """Queue one message per setting given (None: leave it as it is); width and height go together."""
        if (width is None) != (height is None):
            raise UnitySideChannelException(
                "Set the screen resolution's width and height together (one of them is None).")
        kind = EngineConfigType
        if width is not None:
            self._queue(kind.SCREEN_RESOLUTION, ("int", width), ("int", height))
        if quality_level is not None:
            self._queue(kind.QUALITY_LEVEL, ("int", quality_level))
        if time_scale is not None:
            self._queue(kind.TIME_SCALE, ("float", time_scale))
        if target_frame_rate is not None:
            self._queue(kind.TARGET_FRAME_RATE, ("int", target_frame_rate))
        if capture_frame_rate is not None:
            self._queue(kind.CAPTURE_FRAME_RATE, ("int", capture_frame_rate))

    def set_configuration(self, config: EngineConfig) -> None:
        self.set_configuration_parameters(**config._asdict())

    def _queue(self, kind: EngineConfigType, *values: tuple[str, float]) -> None:
        msg = OutgoingMessage()
        msg.write_int32(kind)
        for type_, value in values:
            (msg.write_int32 if type_ == "int" else msg.write_float32)(value)
        self.queue_message_to_send(msg)
