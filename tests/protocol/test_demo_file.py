"""protos.demo_file against hand-built messages: the byte layout of Unity's .demo format
(docs/demonstrations.md), reading a file and a folder, and one clear error per kind of bad path."""
from __future__ import annotations

import os

import pytest

from protos import demo_file
from protos.communicator_objects.agent_action_pb2 import AgentActionProto
from protos.communicator_objects.agent_info_pb2 import AgentInfoProto
from protos.communicator_objects.brain_parameters_pb2 import BrainParametersProto
from protos.communicator_objects.demonstration_meta_pb2 import DemonstrationMetaProto
from protos.communicator_objects.observation_pb2 import ObservationProto


def _brain() -> BrainParametersProto:
    brain = BrainParametersProto(brain_name="Basic?team=0", is_training=True)
    brain.action_spec.num_discrete_actions = 1
    brain.action_spec.discrete_branch_sizes.append(3)
    return brain


def _info(value: float, reward: float, done: bool = False, agent_id: int = 1) -> AgentInfoProto:
    obs = ObservationProto(shape=[2])
    obs.float_data.data.extend([value, -value])
    return AgentInfoProto(reward=reward, done=done, id=agent_id, observations=[obs])


def _write(path, name="expert", records=((0.0, 0.0, False), (1.0, 0.5, False), (2.0, 1.0, True))):
    with demo_file.DemoWriter(str(path), name, _brain()) as writer:
        for index, (value, reward, done) in enumerate(records):
            writer.record(_info(value, reward, done), AgentActionProto(discrete_actions=[index % 3]))
    return path


def _delimited(message) -> bytes:
    payload = message.SerializeToString()
    assert len(payload) < 128
    return bytes([len(payload)]) + payload


def test_layout_is_unitys_metadata_brain_at_33_records_then_raw_metadata(tmp_path):
    path = _write(tmp_path / "a.demo")
    data = path.read_bytes()
    meta = DemonstrationMetaProto(api_version=1, demonstration_name="expert", number_steps=3,
                                  number_episodes=1, mean_reward=1.5)  # (0 + 0.5 + 1.0) / 1 episode
    head = _delimited(meta)
    assert data[:len(head)] == head
    assert data[len(head):33] == bytes(33 - len(head))  # the reserved room is zeros
    brain = _brain()
    brain.is_training = False  # recorded demonstrations say so
    body = _delimited(brain) + b"".join(
        _delimited(demo_file.AgentInfoActionPairProto(agent_info=_info(v, r, d),
                                                      action_info=AgentActionProto(discrete_actions=[i])))
        for i, (v, r, d) in enumerate([(0.0, 0.0, False), (1.0, 0.5, False), (2.0, 1.0, True)]))
    assert data[33:33 + len(body)] == body
    assert data[33 + len(body):] == meta.SerializeToString()  # Unity's trailing undelimited copy


def test_read_stops_after_number_steps_and_returns_the_messages(tmp_path):
    demo = demo_file.read_demo(str(_write(tmp_path / "a.demo")))
    assert [p.agent_info.reward for p in demo.pairs] == [0.0, 0.5, 1.0]
    assert [list(p.agent_info.observations[0].float_data.data) for p in demo.pairs] == [[0, 0], [1, -1], [2, -2]]
    assert [list(p.action_info.discrete_actions) for p in demo.pairs] == [[0], [1], [2]]
    assert [p.agent_info.done for p in demo.pairs] == [False, False, True]
    assert demo.brain_parameters.brain_name == "Basic?team=0"
    assert list(demo.brain_parameters.action_spec.discrete_branch_sizes) == [3]
    assert demo.metas[0].number_steps == 3


def test_a_folder_reads_its_files_in_name_order_counting_steps_cumulatively(tmp_path):
    _write(tmp_path / "b.demo", records=[(5.0, 0.0, False), (6.0, 1.0, True)])
    _write(tmp_path / "a.demo")
    (tmp_path / "notes.txt").write_text("not a demo")
    demo = demo_file.read_demo(str(tmp_path))
    assert [p.agent_info.observations[0].float_data.data[0] for p in demo.pairs] == [0, 1, 2, 5, 6]
    assert [os.path.basename(f) for f in demo.files] == ["a.demo", "b.demo"]


def test_a_long_name_is_shortened_to_fit_the_32_reserved_bytes(tmp_path):
    path = _write(tmp_path / "a.demo", name="x" * 100)
    demo = demo_file.read_demo(str(path))
    name = demo.metas[0].demonstration_name
    assert 0 < len(name) < 100 and set(name) == {"x"}
    assert path.read_bytes()[0] + 1 <= 32


def test_an_unfinished_file_of_unity_reads_as_far_as_its_records_go(tmp_path):
    """A recorder killed before close leaves number_steps 0 ... and its records: the reference
    reads nothing of it (0 expected); so do we, and say the demonstration is empty."""
    path = tmp_path / "a.demo"
    writer = demo_file.DemoWriter(str(path), "x", _brain())
    writer.record(_info(0, 0), AgentActionProto(discrete_actions=[1]))
    writer._file.close()
    with pytest.raises(demo_file.DemoFileError, match="holds no recorded step"):
        demo_file.read_demo(str(path))


@pytest.mark.parametrize("make, match", [
    (lambda d: str(d / "missing.demo"), "does not exist"),
    (lambda d: str(d), "holds no .demo file"),
    (lambda d: (d / "a.txt").write_text("x") and str(d / "a.txt"), "does not end in .demo"),
    (lambda d: (d / "a.demo").write_bytes(b"\x05ab") and str(d / "a.demo"), "truncated"),
    (lambda d: (d / "a.demo").write_bytes(
        _delimited(DemonstrationMetaProto(api_version=7, number_steps=1))) and str(d / "a.demo"),
     "api_version 7 is not supported"),
])
def test_bad_paths_raise_one_clear_error(tmp_path, make, match):
    with pytest.raises(demo_file.DemoFileError, match=match):
        demo_file.read_demo(make(tmp_path))


def test_a_truncated_record_is_reported_with_its_position(tmp_path):
    path = _write(tmp_path / "a.demo")
    data = path.read_bytes()
    path.write_bytes(data[:60])
    with pytest.raises(demo_file.DemoFileError, match="truncated"):
        demo_file.read_demo(str(path))
