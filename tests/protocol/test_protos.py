"""The wire contract: generated code is current, descriptors match docs/protocol.md ("Message schema") and the real
ML-Agents."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from google.protobuf import descriptor_pb2

from protos.communicator_objects import (
    agent_action_pb2,
    agent_info_pb2,
    brain_parameters_pb2,
    command_pb2,
    observation_pb2,
    space_type_pb2,
    unity_message_pb2,
    unity_rl_initialization_output_pb2,
    unity_rl_input_pb2,
    unity_rl_output_pb2,
    unity_to_external_pb2,
)
from tests.interop_venv import INTEROP_PYTHON

ROOT = Path(__file__).resolve().parents[2]

# FieldDescriptorProto type / label numbers
FLOAT, INT32, BOOL, STRING, MESSAGE, BYTES, ENUM = 2, 5, 8, 9, 11, 12, 14
OPTIONAL, REPEATED = 1, 3


def test_generated_code_matches_the_proto_files():
    done = subprocess.run(
        [sys.executable, "-m", "protos.regenerate", "--check"], cwd=ROOT, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr


def descriptor_proto(message_cls) -> descriptor_pb2.DescriptorProto:
    proto = descriptor_pb2.DescriptorProto()
    message_cls.DESCRIPTOR.CopyToProto(proto)
    return proto


def fields(message_cls) -> dict[int, tuple]:
    return {f.number: (f.name, f.type, f.label, f.type_name.rsplit(".", 1)[-1]) for f in descriptor_proto(message_cls).field}


def reserved(message_cls) -> set[int]:
    return {n for r in descriptor_proto(message_cls).reserved_range for n in range(r.start, r.end)}


def test_agent_info_fields_and_reserved_numbers():
    assert fields(agent_info_pb2.AgentInfoProto) == {
        7: ("reward", FLOAT, OPTIONAL, ""),
        8: ("done", BOOL, OPTIONAL, ""),
        9: ("max_step_reached", BOOL, OPTIONAL, ""),
        10: ("id", INT32, OPTIONAL, ""),
        11: ("action_mask", BOOL, REPEATED, ""),
        13: ("observations", MESSAGE, REPEATED, "ObservationProto"),
        14: ("group_id", INT32, OPTIONAL, ""),
        15: ("group_reward", FLOAT, OPTIONAL, ""),
    }
    assert reserved(agent_info_pb2.AgentInfoProto) == {1, 2, 3, 4, 5, 6, 12}


def test_action_and_brain_parameter_messages():
    assert fields(agent_action_pb2.AgentActionProto) == {
        1: ("vector_actions_deprecated", FLOAT, REPEATED, ""),
        4: ("value", FLOAT, OPTIONAL, ""),
        6: ("continuous_actions", FLOAT, REPEATED, ""),
        7: ("discrete_actions", INT32, REPEATED, ""),
    }
    assert reserved(agent_action_pb2.AgentActionProto) == {2, 3, 5}
    assert fields(brain_parameters_pb2.BrainParametersProto) == {
        3: ("vector_action_size_deprecated", INT32, REPEATED, ""),
        5: ("vector_action_descriptions_deprecated", STRING, REPEATED, ""),
        6: ("vector_action_space_type_deprecated", ENUM, OPTIONAL, "SpaceTypeProto"),
        7: ("brain_name", STRING, OPTIONAL, ""),
        8: ("is_training", BOOL, OPTIONAL, ""),
        9: ("action_spec", MESSAGE, OPTIONAL, "ActionSpecProto"),
    }
    assert reserved(brain_parameters_pb2.BrainParametersProto) == {1, 2, 4}
    assert reserved(unity_rl_initialization_output_pb2.UnityRLInitializationOutputProto) == {6}


def test_maps_are_map_entries_with_camel_case_agent_infos():
    out = descriptor_proto(unity_rl_output_pb2.UnityRLOutputProto)
    assert fields(unity_rl_output_pb2.UnityRLOutputProto) == {
        2: ("agentInfos", MESSAGE, REPEATED, "AgentInfosEntry"),
        3: ("side_channel", BYTES, OPTIONAL, ""),
    }
    assert reserved(unity_rl_output_pb2.UnityRLOutputProto) == {1}
    entry = next(n for n in out.nested_type if n.name == "AgentInfosEntry")
    assert entry.options.map_entry
    assert [(f.name, f.number, f.type) for f in entry.field] == [("key", 1, STRING), ("value", 2, MESSAGE)]
    assert entry.field[1].type_name.endswith("UnityRLOutputProto.ListAgentInfoProto")

    rl_in = descriptor_proto(unity_rl_input_pb2.UnityRLInputProto)
    assert fields(unity_rl_input_pb2.UnityRLInputProto) == {
        1: ("agent_actions", MESSAGE, REPEATED, "AgentActionsEntry"),
        4: ("command", ENUM, OPTIONAL, "CommandProto"),
        5: ("side_channel", BYTES, OPTIONAL, ""),
    }
    assert reserved(unity_rl_input_pb2.UnityRLInputProto) == {2, 3}
    assert next(n for n in rl_in.nested_type if n.name == "AgentActionsEntry").options.map_entry


def test_observation_oneof_and_enums():
    obs = observation_pb2.ObservationProto.DESCRIPTOR
    assert [o.name for o in obs.oneofs] == ["observation_data"]
    assert sorted(f.name for f in obs.oneofs[0].fields) == ["compressed_data", "float_data"]
    assert (obs.fields_by_name["compressed_data"].number, obs.fields_by_name["float_data"].number) == (3, 4)
    assert dict(observation_pb2.CompressionTypeProto.items()) == {"NONE": 0, "PNG": 1}
    assert dict(observation_pb2.ObservationTypeProto.items()) == {"DEFAULT": 0, "GOAL_SIGNAL": 1}
    assert dict(command_pb2.CommandProto.items()) == {"STEP": 0, "RESET": 1, "QUIT": 2}
    assert dict(space_type_pb2.SpaceTypeProto.items()) == {"discrete": 0, "continuous": 1}


def test_service_path():
    service = unity_to_external_pb2.DESCRIPTOR.services_by_name["UnityToExternalProto"]
    assert service.full_name == "communicator_objects.UnityToExternalProto"
    exchange = service.methods_by_name["Exchange"]
    assert f"/{service.full_name}/{exchange.name}" == "/communicator_objects.UnityToExternalProto/Exchange"
    assert exchange.input_type.full_name == exchange.output_type.full_name == "communicator_objects.UnityMessageProto"
    assert [m.name for m in service.methods] == ["Exchange"]


# ------------------------------------------------------------------ hand-built wire bytes
def test_agent_info_wire_bytes():
    info = agent_info_pb2.AgentInfoProto(reward=1.0, done=True, id=7, action_mask=[False, True])
    assert info.SerializeToString() == bytes.fromhex(
        "3d 0000803f"  # field 7, wire type 5 (fixed32): 1.0f
        "40 01"  # field 8, varint: true
        "50 07"  # field 10, varint: 7
        "5a 02 00 01"  # field 11, wire type 2 (packed): [false, true]
    )


def test_unity_rl_input_wire_bytes():
    rl_input = unity_rl_input_pb2.UnityRLInputProto(side_channel=b"sc")
    rl_input.agent_actions["B"].value.add(continuous_actions=[0.5], discrete_actions=[1])
    assert rl_input.SerializeToString() == bytes.fromhex(
        "0a 10"  # field 1 (map entry), 16 bytes
        "0a 01 42"  # key = "B"
        "12 0b"  # value: ListAgentActionProto, 11 bytes
        "0a 09"  # value[0]: AgentActionProto, 9 bytes
        "32 04 0000003f"  # continuous_actions packed [0.5]
        "3a 01 01"  # discrete_actions packed [1]
        "2a 02 7363"  # side_channel = b"sc"; command STEP (0) is the default, so absent
    )
    assert unity_rl_input_pb2.UnityRLInputProto(command=command_pb2.RESET).SerializeToString() == b"\x20\x01"


def test_closing_header_wire_bytes():
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 400
    assert message.SerializeToString() == b"\x0a\x03\x08\x90\x03"  # 400 = varint 90 03
    assert struct.pack("<f", 0.5) == bytes.fromhex("0000003f")


# ------------------------------------------------------------------ against the real ML-Agents 1.1.0
DUMPER = r'''
import importlib, json, pkgutil, sys
from google.protobuf import descriptor_pb2, text_format
pkg = importlib.import_module(sys.argv[1])
out = {}
def numbers(ranges, inclusive):
    return sorted(n for r in ranges for n in range(r.start, r.end + (1 if inclusive else 0)))
def message(m, prefix):
    name = prefix + m.name
    out["message " + name] = {
        "fields": sorted(
            [f.name, f.number, f.type, f.label, f.type_name,
             m.oneof_decl[f.oneof_index].name if f.HasField("oneof_index") else None]
            for f in m.field),
        "reserved": numbers(m.reserved_range, False),
        "reserved_names": sorted(m.reserved_name),
        "map_entry": m.options.map_entry,
    }
    for n in m.nested_type:
        message(n, name + ".")
    for e in m.enum_type:
        enum(e, name + ".")
def enum(e, prefix):
    out["enum " + prefix + e.name] = {
        "values": sorted([v.name, v.number] for v in e.value),
        "reserved": numbers(e.reserved_range, True),
    }
for info in pkgutil.iter_modules(pkg.__path__):
    if not info.name.endswith("_pb2"):
        continue
    module = importlib.import_module(pkg.__name__ + "." + info.name)
    fdp = descriptor_pb2.FileDescriptorProto()
    module.DESCRIPTOR.CopyToProto(fdp)
    out["file " + fdp.name.rsplit("/", 1)[-1]] = {
        "package": fdp.package, "syntax": fdp.syntax, "csharp_namespace": fdp.options.csharp_namespace,
        "imports": sorted(d.rsplit("/", 1)[-1] for d in fdp.dependency)}
    prefix = "." + fdp.package + "."
    for m in fdp.message_type:
        message(m, prefix)
    for e in fdp.enum_type:
        enum(e, prefix)
    for s in fdp.service:
        out["service " + prefix + s.name] = sorted(
            [x.name, x.input_type, x.output_type, x.client_streaming, x.server_streaming] for x in s.method)
unity_message = importlib.import_module(pkg.__name__ + ".unity_message_pb2").UnityMessageProto
sample = text_format.Parse(sys.stdin.read(), unity_message())
out["sample bytes"] = sample.SerializeToString(deterministic=True).hex()
print(json.dumps(out, sort_keys=True))
'''

SAMPLE = """
header { status: 200 }
unity_output {
  rl_output {
    agentInfos { key: "Ball?team=0" value { value {
      reward: 0.25 done: true max_step_reached: true id: 12 action_mask: [true, false]
      group_id: 3 group_reward: -1.5
      observations { shape: [2] float_data { data: [1.5, -2] } name: "vec" observation_type: GOAL_SIGNAL }
      observations { shape: [3, 4, 4] compression_type: PNG compressed_data: "\\x89PNG"
                     compressed_channel_mapping: [0, 1, 2] dimension_properties: [1, 2, 2] }
    } } }
    side_channel: "\\x01\\x02"
  }
  rl_initialization_output {
    name: "AcademySingleton" communication_version: "1.5.0" package_version: "3.0.0" log_path: "x"
    capabilities { baseRLCapabilities: true multiAgentGroups: true }
    brain_parameters {
      brain_name: "Ball?team=0" is_training: true vector_action_size_deprecated: [2]
      vector_action_space_type_deprecated: continuous vector_action_descriptions_deprecated: "d"
      action_spec { num_continuous_actions: 2 num_discrete_actions: 1 discrete_branch_sizes: [3]
                    action_descriptions: "a" }
    }
  }
}
unity_input {
  rl_input {
    agent_actions { key: "Ball?team=0" value { value {
      vector_actions_deprecated: [0.5, 1] value: 0.5 continuous_actions: [0.5] discrete_actions: [1] } } }
    command: RESET side_channel: "\\x03"
  }
  rl_initialization_input {
    seed: 7 communication_version: "1.5.0" package_version: "1.1.0" num_areas: 2
    capabilities { hybridActions: true }
  }
}
"""


def dump_descriptors(python: str, package: str, tmp_path: Path) -> dict:
    script = tmp_path / "dump_descriptors.py"
    script.write_text(DUMPER)
    done = subprocess.run(
        [python, str(script), package], input=SAMPLE, cwd=ROOT if package.startswith("protos") else tmp_path,
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.interop
def test_descriptors_and_bytes_match_the_real_mlagents(tmp_path):
    if not INTEROP_PYTHON.exists():
        pytest.skip(f"{INTEROP_PYTHON} is missing: the real mlagents 1.1.0 venv is needed for this cross-check")
    ours = dump_descriptors(sys.executable, "protos.communicator_objects", tmp_path)
    real = dump_descriptors(str(INTEROP_PYTHON), "mlagents_envs.communicator_objects", tmp_path)
    assert len(real) > 40  # every file, message and enum of the real package was dumped
    differences = {k: (ours.get(k), real.get(k)) for k in sorted(set(ours) | set(real)) if ours.get(k) != real.get(k)}
    assert differences == {}
