"""``.demo`` files: Unity's Demonstration Recorder format, read and written (docs/demonstrations.md).

A ``.demo`` file is length-delimited protobuf messages of the wire's own types:

    offset 0    varint length + DemonstrationMetaProto   (must fit in the first 32 bytes)
    offset 33   varint length + BrainParametersProto     (is_training false)
    then        varint length + AgentInfoActionPairProto, one per recorded decision

Unity writes the metadata first, rewrites it on close with the final counts, and then appends
the raw metadata bytes once more (undelimited) at the very end: readers therefore stop after
``number_steps`` records instead of reading to the end of the file. A folder of ``.demo`` files
reads as one demonstration, the records of each file after the previous file's, counted
cumulatively against the files' ``number_steps`` as the reference loader does.

The records of one file are one agent's consecutive decisions: record t holds the agent info
(observations, the reward since the previous decision, done) and the action taken at t; the
episode ends at a record with ``done`` set, and the next record starts the next episode.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import BinaryIO

from google.protobuf.internal.decoder import _DecodeVarint32  # the protobuf runtime's own varint codec
from google.protobuf.message import DecodeError

from protos import wire
from protos.communicator_objects.agent_action_pb2 import AgentActionProto
from protos.communicator_objects.agent_info_action_pair_pb2 import AgentInfoActionPairProto
from protos.communicator_objects.agent_info_pb2 import AgentInfoProto
from protos.communicator_objects.brain_parameters_pb2 import BrainParametersProto
from protos.communicator_objects.demonstration_meta_pb2 import DemonstrationMetaProto

API_VERSION = 1  # what Unity writes
SUPPORTED_API_VERSIONS = frozenset({0, 1})
META_DATA_BYTES = 32  # Unity's MetaDataBytes: room for the delimited metadata at the start
INITIAL_POS = META_DATA_BYTES + 1  # where the brain parameters start
SUFFIX = ".demo"


class DemoFileError(ValueError):
    """A demonstration path that cannot be read: the message names the file and what to do."""


@dataclass
class Demonstration:
    """What a ``.demo`` file (or a folder of them) holds."""

    brain_parameters: BrainParametersProto
    pairs: list[AgentInfoActionPairProto] = field(default_factory=list)
    metas: list[DemonstrationMetaProto] = field(default_factory=list)  # one per file read
    files: list[str] = field(default_factory=list)


def demo_files(path: str) -> list[str]:
    """The ``.demo`` files of ``path``: the file itself, or a folder's ``*.demo`` in name order."""
    if os.path.isfile(path):
        if not path.endswith(SUFFIX):
            raise DemoFileError(f"demonstration file {path!r} does not end in {SUFFIX}; give a .demo file "
                                "recorded by Unity's Demonstration Recorder (or unity-stub-env --record-demo) "
                                "or a folder of them")
        return [path]
    if os.path.isdir(path):
        found = sorted(os.path.join(path, name) for name in os.listdir(path) if name.endswith(SUFFIX))
        if not found:
            raise DemoFileError(f"the demonstration folder {path!r} holds no {SUFFIX} file; record one "
                                "into it or point demo_path at a .demo file")
        return found
    raise DemoFileError(f"the demonstration file or folder {path!r} does not exist; check demo_path "
                        "(a relative path is read from the folder mlagents-like-learn runs in)")


def _delimited(data: bytes, pos: int, where: str) -> tuple[bytes, int]:
    """The message bytes at ``pos`` (varint length first) and the position after them."""
    try:
        size, start = _DecodeVarint32(data, pos)
    except (IndexError, DecodeError):
        raise DemoFileError(f"{where}: truncated length prefix at byte {pos}; the file is damaged "
                            "(re-record it)") from None
    if start + size > len(data):
        raise DemoFileError(f"{where}: a record at byte {pos} declares {size} bytes but the file ends "
                            f"at {len(data)}; the file is truncated (re-record it)")
    return data[start:start + size], start + size


def _parse(message_type, payload: bytes, where: str):
    try:
        return message_type.FromString(payload)
    except DecodeError:
        raise DemoFileError(f"{where}: not a valid {message_type.__name__}; this is not a .demo file "
                            "or it is damaged") from None


def read_demo(path: str) -> Demonstration:
    """Every record of the ``.demo`` file or folder ``path`` (DemoFileError if unreadable)."""
    files = demo_files(path)
    demo: Demonstration | None = None
    expected = 0
    for name in files:
        with open(name, "rb") as f:
            data = f.read()
        meta = _parse(DemonstrationMetaProto, _delimited(data, 0, name)[0], f"{name} (metadata)")
        if meta.api_version not in SUPPORTED_API_VERSIONS:
            raise DemoFileError(f"{name}: demonstration api_version {meta.api_version} is not supported "
                                f"(only {sorted(SUPPORTED_API_VERSIONS)}); record it again with this "
                                "ML-Agents version")
        brain, pos = _delimited(data, INITIAL_POS, f"{name} (brain parameters)")
        brain_parameters = _parse(BrainParametersProto, brain, f"{name} (brain parameters)")
        if demo is None:
            demo = Demonstration(brain_parameters)
        demo.metas.append(meta)
        demo.files.append(name)
        expected += meta.number_steps
        while len(demo.pairs) < expected and pos < len(data):
            record, pos = _delimited(data, pos, name)
            demo.pairs.append(_parse(AgentInfoActionPairProto, record, f"{name} (record {len(demo.pairs)})"))
    if demo is None or not demo.pairs:
        raise DemoFileError(f"the demonstration {path!r} holds no recorded step; record a longer one")
    return demo


def _meta_bytes(name: str, steps: int, episodes: int, mean_reward: float) -> bytes:
    """The delimited metadata, its name shortened until it fits in META_DATA_BYTES."""
    for cut in range(len(name), -1, -1):
        meta = DemonstrationMetaProto(api_version=API_VERSION, demonstration_name=name[:cut],
                                      number_steps=steps, number_episodes=episodes, mean_reward=mean_reward)
        payload = meta.SerializeToString()
        delimited = wire.varint(len(payload)) + payload
        if len(delimited) <= META_DATA_BYTES:
            return delimited
    raise AssertionError("unreachable: the metadata without a name fits")  # pragma: no cover


class DemoWriter:
    """Writes one agent's decisions as Unity's recorder does: metadata, brain parameters at 33,
    one record per ``record`` call; ``close`` rewrites the metadata with the final counts and
    appends its raw bytes at the end of the file, as Unity does."""

    def __init__(self, path: str, name: str, brain_parameters: BrainParametersProto) -> None:
        self.path = path
        self.name = name
        self.steps = self.episodes = 0
        self.total_reward = 0.0
        self._file: BinaryIO = open(path, "wb")
        self._file.write(_meta_bytes(name, 0, 0, 0.0))
        self._file.seek(INITIAL_POS)
        brain = BrainParametersProto()
        brain.CopyFrom(brain_parameters)
        brain.is_training = False
        self._write(brain)

    def _write(self, message) -> None:
        payload = message.SerializeToString()
        self._file.write(wire.varint(len(payload)) + payload)

    def record(self, agent_info: AgentInfoProto, action: AgentActionProto) -> None:
        self._write(AgentInfoActionPairProto(agent_info=agent_info, action_info=action))
        self.steps += 1
        self.total_reward += agent_info.reward
        if agent_info.done:
            self.episodes += 1

    def close(self) -> None:
        if self._file.closed:
            return
        mean = self.total_reward / self.episodes if self.episodes else 0.0
        meta = _meta_bytes(self.name, self.steps, self.episodes, mean)
        self._file.seek(0, os.SEEK_END)
        self._file.write(meta[1:])  # the raw metadata, undelimited (its length prefix is one byte)
        self._file.seek(0)
        self._file.write(meta)
        self._file.close()

    def __enter__(self) -> "DemoWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
