"""Environment parameters (Python → Unity): constants and samplers a scene reads through
``Academy.Instance.EnvironmentParameters``."""
from __future__ import annotations

import enum

from mlagents_like_envs.exception import UnityCommunicationException
from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.outgoing_message import OutgoingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel
from protos.side_channels import ENVIRONMENT_PARAMETERS_CHANNEL_ID, SAMPLER_TYPES, encode_env_float, encode_env_sampler


class EnvironmentParametersChannel(SideChannel):
    class EnvironmentDataTypes(enum.IntEnum):
        FLOAT = 0
        SAMPLER = 1

    SamplerTypes = enum.IntEnum("SamplerTypes", {name.upper(): code for name, code in SAMPLER_TYPES.items()})

    def __init__(self) -> None:
        super().__init__(ENVIRONMENT_PARAMETERS_CHANNEL_ID)

    def on_message_received(self, msg: IncomingMessage) -> None:
        raise UnityCommunicationException(
            "The EnvironmentParametersChannel received a message from Unity; it only sends.")

    def set_float_parameter(self, key: str, value: float) -> None:
        self._send(encode_env_float(key, value))

    def set_uniform_sampler_parameters(self, key: str, min_value: float, max_value: float, seed: int) -> None:
        """Unity draws the parameter uniformly from [min_value, max_value) at each read."""
        self._send(encode_env_sampler(key, "uniform", seed, (min_value, max_value)))

    def set_gaussian_sampler_parameters(self, key: str, mean: float, st_dev: float, seed: int) -> None:
        self._send(encode_env_sampler(key, "gaussian", seed, (mean, st_dev)))

    def set_multirangeuniform_sampler_parameters(self, key: str, intervals: list[tuple[float, float]],
                                                 seed: int) -> None:
        """Unity picks one of the (min, max) intervals (in proportion to its length), then a value in it."""
        self._send(encode_env_sampler(key, "multirangeuniform", seed, intervals))

    def _send(self, payload: bytes) -> None:
        msg = OutgoingMessage()
        msg.set_raw_bytes(payload)
        self.queue_message_to_send(msg)
