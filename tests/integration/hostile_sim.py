"""A misbehaving simulator for tests/integration/test_hostile_simulators.py, launched by the
trainer as its --env player (a tiny shell script runs ``python tests/integration/hostile_sim.py``).

It speaks the real protocol over the stub's own HTTP/2 client (M1, M2, then steps of one
behavior ``H?team=0`` with one vector observation of 2 floats and 2 continuous actions) and
misbehaves the way ``HOSTILE_CASE`` says. ``HOSTILE_AFTER`` good steps come first (default 0).
"""
from __future__ import annotations

import io
import math
import os
import sys
import time

from protos.communicator_objects import agent_info_pb2, brain_parameters_pb2, observation_pb2, unity_message_pb2
from protos.versions import COMMUNICATION_VERSION, all_true_capabilities
from unity_stub_env.http2_client import CallError, Http2Channel

PATH = b"/communicator_objects.UnityToExternalProto/Exchange"
NAME = "H?team=0"


def port_from(argv: list[str]) -> int:
    return int(argv[argv.index("--mlagents-port") + 1])


def message() -> unity_message_pb2.UnityMessageProto:
    msg = unity_message_pb2.UnityMessageProto()
    msg.header.status = 200
    return msg


def m1(version: str = COMMUNICATION_VERSION) -> bytes:
    msg = message()
    init = msg.unity_output.rl_initialization_output
    init.name, init.communication_version, init.package_version = "AcademySingleton", version, "3.0.0"
    init.capabilities.CopyFrom(all_true_capabilities())
    return msg.SerializeToString()


def params(continuous: int = 2, branches=(), name: str = NAME):
    bp = brain_parameters_pb2.BrainParametersProto(brain_name=name, is_training=True)
    bp.action_spec.num_continuous_actions = continuous
    bp.action_spec.num_discrete_actions = len(branches)
    bp.action_spec.discrete_branch_sizes.extend(branches)
    return bp


def agent(agent_id: int = 1, obs=(0.5, -0.5), reward: float = 0.1, done: bool = False, mask=()):
    info = agent_info_pb2.AgentInfoProto(id=agent_id, reward=reward, done=done)
    info.action_mask.extend(mask)
    if obs is not None:
        o = info.observations.add()
        o.shape.append(len(obs))
        o.float_data.data.extend(obs)
    return info


def png_obs(info, data: bytes, shape=(3, 8, 8)):
    o = info.observations.add()
    o.shape.extend(shape)
    o.compression_type = observation_pb2.PNG
    o.compressed_data = data
    return info


def step(infos, brain=None, name: str = NAME) -> bytes:
    msg = message()
    msg.unity_output.rl_output.agentInfos[name].value.extend(infos)
    if brain is not None:
        msg.unity_output.rl_initialization_output.brain_parameters.append(brain)
    return msg.SerializeToString()


def big_png() -> bytes:
    """A 20000 x 20000 RGB PNG of about 60 KB, written by hand (zlib of zero rows)."""
    import struct
    import zlib

    width = height = 20000

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    compressor = zlib.compressobj(9)
    row = b"\x00" * (1 + 3 * width)
    body = b"".join(compressor.compress(row) for _ in range(height)) + compressor.flush()
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", body) + chunk(b"IEND", b""))


def first_step(case: str) -> bytes:
    """The hostile first message carrying the behavior's brain parameters."""
    nan = float("nan")
    if case == "huge_continuous":
        return step([agent()], params(continuous=10**8))
    if case == "huge_branches":
        return step([agent()], params(continuous=0, branches=[2] * 10**6))
    if case == "zero_branch":
        return step([agent()], params(continuous=0, branches=[3, 0]))
    if case == "branch_count_mismatch":  # 3 branches claimed, 2 sizes listed
        bp = params(continuous=0, branches=[3, 2])
        bp.action_spec.num_discrete_actions = 3
        return step([agent()], bp)
    if case == "no_observations":
        return step([agent(obs=None)], params())
    if case == "no_brain_parameters":
        return step([agent()])
    if case == "missing_observation":
        return step([agent(1), agent(2, obs=None)], params())
    if case == "wrong_sized_observation":
        return step([agent(1), agent(2, obs=(1.0, 2.0, 3.0))], params())
    if case == "nan_reward":
        return step([agent(reward=nan)], params())
    if case == "inf_observation":
        return step([agent(obs=(math.inf, 0.0))], params())
    if case == "mask_wrong_length":
        return step([agent(mask=[False, True])], params(continuous=0, branches=[3]))
    if case == "mask_everything":
        return step([agent(mask=[True, True, True])], params(continuous=0, branches=[3]))
    if case in ("corrupt_png", "png_bomb"):
        info = agent()
        if case == "corrupt_png":
            from PIL import Image

            out = io.BytesIO()
            Image.new("RGB", (8, 8)).save(out, format="PNG")
            data = bytearray(out.getvalue())
            data[40:60] = b"\xff" * 20  # inside IDAT: a zlib stream that does not inflate
            png_obs(info, bytes(data))
        else:
            png_obs(info, big_png(), shape=(3, 8, 8))
        return step([info], params())
    return step([agent()], params())


def main() -> int:
    case = os.environ["HOSTILE_CASE"]
    good_steps = int(os.environ.get("HOSTILE_AFTER", "0"))
    channel = Http2Channel("127.0.0.1", port_from(sys.argv), PATH)
    deadline = time.monotonic() + 30
    while not channel.connect(1.0):
        if time.monotonic() > deadline:
            return 3
        time.sleep(0.1)
    if case == "never_sends":
        time.sleep(120)
        return 0
    try:
        channel.call(m1("0.9.0" if case == "wrong_version" else COMMUNICATION_VERSION), timeout=30)
        if case == "handshake_twice":
            channel.call(m1(), timeout=30)  # a second M1 where M2 belongs
        channel.call(message().SerializeToString(), timeout=30)  # M2; its answer is RESET
        hostile = first_step(case)
        if good_steps:
            channel.call(step([agent()], params()), timeout=30)
            for k in range(good_steps):
                channel.call(step([agent(1, obs=(k / good_steps, 0.0))]), timeout=30)
            if case == "spec_change":
                hostile = step([agent(obs=(0.5, 0.5, 0.5))], params(continuous=3))
            else:
                hostile = step([agent()]) if case in ("disconnect_mid_exchange",) else hostile
        if case == "disconnect_mid_exchange":
            channel.sock.sendall(b"\x00\x00\x20\x01\x04\x00\x00\x00\x7f")  # half a HEADERS frame
            os._exit(5)  # gone mid-call, as a crashing player
        if case in ("handshake_twice", "normal", "nan_every_step"):
            for k in range(100000):
                infos = [agent(1, obs=(0.1, k % 7 / 7))]
                if case == "nan_every_step":  # beside it, agents whose reward or observation is not finite
                    infos += [agent(2, reward=float("nan")), agent(3, obs=(math.inf, 0.0)),
                              agent(4, obs=(0.0, -math.inf), done=True)]
                channel.call(step(infos, params() if k == 0 else None), timeout=30)
        channel.call(hostile, timeout=30)
        channel.call(step([agent()]), timeout=30)  # the trainer should have stopped before this
    except CallError:
        return 0  # the trainer closed the session
    return 0


if __name__ == "__main__":
    sys.exit(main())
