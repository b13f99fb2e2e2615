"""Helpers for protocol tests: proto builders and a scripted "Unity" gRPC client in a thread."""
from __future__ import annotations

import io
import socket
import threading
from typing import Callable, Sequence, Union

import grpc
import numpy as np
import pytest
from PIL import Image

from protos.communicator_objects import (
    agent_info_pb2,
    brain_parameters_pb2,
    unity_message_pb2,
    unity_to_external_pb2_grpc,
)

BIG = 256 * 1024 * 1024
Message = unity_message_pb2.UnityMessageProto


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def png_bytes(pixels: np.ndarray, **save_kwargs) -> bytes:
    """uint8 [H, W, 3] or [H, W] → one PNG file."""
    buf = io.BytesIO()
    Image.fromarray(np.asarray(pixels, dtype=np.uint8)).save(buf, format="PNG", **save_kwargs)
    return buf.getvalue()


def brain_params(name: str, continuous: int = 0, branches: Sequence[int] = ()):
    bp = brain_parameters_pb2.BrainParametersProto(brain_name=name, is_training=True)
    bp.action_spec.num_continuous_actions = continuous
    bp.action_spec.num_discrete_actions = len(branches)
    bp.action_spec.discrete_branch_sizes.extend(branches)
    return bp


def agent_info(
    agent_id: int,
    obs: Sequence[Sequence[float]] = (),
    reward: float = 0.0,
    done: bool = False,
    max_step: bool = False,
    mask: Sequence[bool] = (),
    group_id: int = 0,
    group_reward: float = 0.0,
):
    """An AgentInfoProto with one rank-1 float observation per entry of ``obs``."""
    info = agent_info_pb2.AgentInfoProto(
        id=agent_id, reward=reward, done=done, max_step_reached=max_step,
        group_id=group_id, group_reward=group_reward,
    )
    info.action_mask.extend(mask)
    for values in obs:
        o = info.observations.add()
        o.shape.append(len(values))
        o.float_data.data.extend(values)
    return info


def m1(version: str = "1.5.0", base_caps: bool = True) -> Message:
    msg = Message()
    msg.header.status = 200
    init = msg.unity_output.rl_initialization_output
    init.name = "AcademySingleton"
    init.communication_version = version
    init.package_version = "3.0.0"
    caps = init.capabilities
    for field in caps.DESCRIPTOR.fields:
        setattr(caps, field.name, True)
    caps.baseRLCapabilities = base_caps
    return msg


def m2() -> Message:
    msg = Message()
    msg.header.status = 200
    return msg


def rl_message(infos: dict[str, list], params: Sequence = (), side_channel: bytes = b"") -> Message:
    msg = Message()
    msg.header.status = 200
    out = msg.unity_output
    for name, agent_infos in infos.items():
        out.rl_output.agentInfos[name].value.extend(agent_infos)
    out.rl_output.side_channel = side_channel
    out.rl_initialization_output.brain_parameters.extend(params)
    return msg


Step = Union[Message, Callable[[Message], Message]]


class ScriptedUnity(threading.Thread):
    """A fake simulator: sends each scripted message as an Exchange call, in order.

    A script entry is a message or a function of the previous response returning the next
    message. ``responses`` collects what the trainer answered; ``error`` holds an RpcError.
    """

    def __init__(self, port: int, script: Sequence[Step], host: str = "127.0.0.1") -> None:
        super().__init__(daemon=True)
        self.script = list(script)
        self.responses: list[Message] = []
        self.error: grpc.RpcError | None = None
        self.channel = grpc.insecure_channel(
            f"{host}:{port}",
            options=[("grpc.max_receive_message_length", BIG), ("grpc.max_send_message_length", BIG)],
        )
        self.stub = unity_to_external_pb2_grpc.UnityToExternalProtoStub(self.channel)

    def run(self) -> None:
        previous = None
        try:
            for step in self.script:
                request = step(previous) if callable(step) else step
                previous = self.stub.Exchange(request, wait_for_ready=True, timeout=30)
                self.responses.append(previous)
        except grpc.RpcError as err:
            self.error = err
        finally:
            self.channel.close()

    def finish(self, timeout: float = 10.0) -> None:
        self.join(timeout)
        assert not self.is_alive(), "scripted Unity client did not finish"


@pytest.fixture
def port() -> int:
    return free_port()
