"""The independent reference for the codec: protobuf's own generated classes, used field by field.

Nothing here imports the codec or the ``protos`` wire helpers: ``answer`` builds the trainer's
answer as message objects and lets protobuf serialize it; ``read_agents`` reads agent infos
attribute by attribute into plain Python/numpy values (PNG observations through Pillow).
"""
from __future__ import annotations

import io
from typing import Mapping, Sequence

import numpy as np
from PIL import Image

from protos.communicator_objects import command_pb2, observation_pb2, unity_message_pb2


def answer(actions: Mapping[str, tuple], side_channel: bytes = b"", command: int = command_pb2.STEP) -> bytes:
    """The serialized UnityMessageProto (status 200) protobuf writes for ``actions``
    ({behavior: (continuous [n, c], discrete [n, b])}); behaviors with no rows are left out,
    RESET carries no actions. Map entries in key order (deterministic serialization)."""
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 200
    rl_input = message.unity_input.rl_input
    rl_input.command = command
    rl_input.side_channel = bytes(side_channel)
    if command == command_pb2.RESET:
        return message.SerializeToString(deterministic=True)
    for name, (continuous, discrete) in actions.items():
        continuous = np.asarray(continuous, dtype=np.float32).tolist()
        discrete = np.asarray(discrete, dtype=np.int64).tolist()
        if not continuous:
            continue
        agents = rl_input.agent_actions[name].value
        for cont_row, disc_row in zip(continuous, discrete):
            agent = agents.add()
            agent.vector_actions_deprecated.extend(cont_row + [float(d) for d in disc_row])
            agent.continuous_actions.extend(cont_row)
            agent.discrete_actions.extend(disc_row)
    return message.SerializeToString(deterministic=True)


def observation_value(obs: observation_pb2.ObservationProto) -> np.ndarray:
    """One ObservationProto → float32 array of its shape (one PNG: L = 1 channel, RGB = 3)."""
    shape = tuple(obs.shape)
    if obs.compression_type == observation_pb2.PNG:
        pixels = np.asarray(Image.open(io.BytesIO(obs.compressed_data)), dtype=np.float32) / 255.0
        chw = pixels[None] if pixels.ndim == 2 else np.moveaxis(pixels, -1, 0)
        return chw.reshape(shape)
    return np.array(list(obs.float_data.data), dtype=np.float32).reshape(shape)


def mask_fault(infos: Sequence, branches: Sequence[int]) -> bool:
    """True if a deciding agent's action mask is refused: neither empty nor one entry per
    option, or masking every option of a branch (docs/protocol.md, "Simulator → trainer")."""
    total = sum(branches)
    bounds = np.cumsum([0, *branches])
    for info in infos if total else ():  # without discrete actions masks are not read
        if info.done or not len(info.action_mask):
            continue
        if len(info.action_mask) != total:
            return True
        if any(all(info.action_mask[bounds[i]:bounds[i + 1]]) for i in range(len(branches))):
            return True
    return False


def read_agents(infos: Sequence, branches: Sequence[int]) -> dict:
    """Agent infos → {"decision": [...], "terminal": [...]}: one dict per agent, in message order,
    with the fields DecisionSteps / TerminalSteps carry (an empty mask masks nothing; a finished
    agent's mask is not read; ``mask_fault`` says which messages are refused)."""
    total = sum(branches)
    out: dict = {"decision": [], "terminal": []}
    for info in infos:
        agent = {
            "obs": [observation_value(o) for o in info.observations],
            "reward": np.float32(info.reward), "agent_id": int(info.id), "group_id": int(info.group_id),
            "group_reward": np.float32(info.group_reward),
        }
        if info.done:
            agent["interrupted"] = bool(info.max_step_reached)
            out["terminal"].append(agent)
        else:
            mask = list(info.action_mask) if len(info.action_mask) == total else [False] * total
            bounds = np.cumsum([0, *branches])
            agent["action_mask"] = [mask[bounds[i]:bounds[i + 1]] for i in range(len(branches))]
            out["decision"].append(agent)
    return out


def assert_steps_equal(decision, terminal, expected: dict) -> None:
    """DecisionSteps/TerminalSteps against ``read_agents``, value for value and dtype for dtype."""
    for steps, agents, kind in ((decision, expected["decision"], "decision"),
                                (terminal, expected["terminal"], "terminal")):
        assert len(steps) == len(agents), kind
        assert steps.agent_id.dtype == np.int64 and steps.agent_id.tolist() == [a["agent_id"] for a in agents]
        assert steps.reward.dtype == np.float32
        np.testing.assert_array_equal(steps.reward, np.array([a["reward"] for a in agents], np.float32))
        assert steps.group_id.dtype == np.int32 and steps.group_id.tolist() == [a["group_id"] for a in agents]
        np.testing.assert_array_equal(steps.group_reward, np.array([a["group_reward"] for a in agents], np.float32))
        for index, stacked in enumerate(steps.obs):
            assert stacked.dtype == np.float32
            want = np.array([a["obs"][index] for a in agents], np.float32).reshape(stacked.shape)
            np.testing.assert_array_equal(stacked, want)
        if kind == "terminal":
            assert steps.interrupted.dtype == bool
            assert steps.interrupted.tolist() == [a["interrupted"] for a in agents]
        elif steps.action_mask is not None:
            for branch, matrix in enumerate(steps.action_mask):
                assert matrix.dtype == bool
                assert matrix.tolist() == [a["action_mask"][branch] for a in agents]
