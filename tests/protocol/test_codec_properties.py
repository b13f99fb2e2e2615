"""Property tests: on random messages of every shape, the fast paths and protobuf agree.

* decoding (``codec.decode_message``): messages built with protobuf's classes, several
  behaviors, vector (1-D), entity (2-D) and image (3-D, float or PNG) observations, action
  masks of several branches (right or wrong width, a branch all masked: both paths refuse
  those of deciding agents), done / interrupted agents, group ids and
  rewards, empty lists, 0..70 agents (around the records path's threshold, which is also drawn
  lower so small lists take it) -> every DecisionSteps / TerminalSteps field equals what
  ``reference.read_agents`` reads attribute by attribute;
* the trainer's answers (``codec.encode_answer``): continuous / discrete / hybrid actions, any
  int32, counts around the byte-matrix writer's threshold, STEP and RESET, side channels ->
  the bytes protobuf serializes (``reference.answer``);
* the stub's agent infos (``unity_stub_env.agents.encode_agent_infos``) -> the bytes protobuf
  serializes for the AgentInfoProtos built field by field the way Unity's C# fills them.
"""
from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image

from protos import records, wire
from protos.communicator_objects import (
    brain_parameters_pb2,
    observation_pb2,
    unity_message_pb2,
    unity_rl_output_pb2,
)
from protos.errors import ProtocolError
from protos.types import ActionSpec, ActionTuple, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from tests.protocol import reference
from trainer.protocol import codec
from unity_stub_env.agents import encode_agent_infos

P = DimensionProperty
PROPERTY = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.data_too_large])
FLOATS = st.floats(width=32, allow_nan=False, allow_infinity=False)
INT32 = st.integers(-(2**31), 2**31 - 1)
# agent counts: the edges of both thresholds (8 for the action writer, 64 for the records path)
COUNTS = st.one_of(st.sampled_from([0, 1, 2, 7, 8, 9, 63, 64, 65]), st.integers(0, 70))
NAMES = st.text(alphabet="abcXYZ?=0_", min_size=1, max_size=8)


@contextlib.contextmanager
def patched(module, name: str, value):
    old = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, old)


# ------------------------------------------------------------------ strategies
@st.composite
def observation_specs(draw, png_allowed: bool = True):
    kind = draw(st.sampled_from(["vector", "entities", "image", "png"] if png_allowed else ["vector", "entities", "image"]))
    name = draw(st.text(alphabet="abcdef", max_size=6))
    obs_type = draw(st.sampled_from(list(ObservationType)))
    if kind == "vector":
        props = draw(st.sampled_from([(P.NONE,), (P.UNSPECIFIED,)]))
        spec = ObservationSpec((draw(st.integers(1, 12)),), props, obs_type, name)
    elif kind == "entities":
        spec = ObservationSpec((draw(st.integers(1, 4)), draw(st.integers(1, 4))), (P.VARIABLE_SIZE, P.NONE),
                               obs_type, name)
    else:
        channels = draw(st.sampled_from([1, 3])) if kind == "png" else draw(st.integers(1, 3))
        props = draw(st.sampled_from([(P.NONE, P.TRANSLATIONAL_EQUIVARIANCE, P.TRANSLATIONAL_EQUIVARIANCE),
                                      (P.UNSPECIFIED,) * 3]))
        spec = ObservationSpec((channels, draw(st.integers(1, 4)), draw(st.integers(1, 4))), props, obs_type, name)
    return spec, kind == "png"


action_specs = st.builds(ActionSpec, st.integers(0, 3), st.lists(st.integers(1, 5), max_size=3).map(tuple))


def png_of(pixels: np.ndarray) -> bytes:
    """uint8 [C, H, W] (C = 1 or 3) -> one PNG file (L or RGB)."""
    image = Image.fromarray(pixels[0] if len(pixels) == 1 else np.moveaxis(pixels, 0, -1))
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


@st.composite
def behaviors(draw):
    """(BehaviorSpec, PNG flags per observation, AgentInfoProtos)."""
    drawn = draw(st.lists(observation_specs(), min_size=1, max_size=3))
    spec = BehaviorSpec(tuple(s for s, _ in drawn), draw(action_specs))
    pngs = [png for _, png in drawn]
    n = draw(st.integers(0, 6) if any(pngs) else COUNTS)  # PNGs are slow to make: few such agents
    width = sum(spec.action_spec.discrete_branches)
    infos = []
    for _ in range(n):
        info = unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto().value.add()
        info.reward, info.group_reward = draw(FLOATS), draw(FLOATS)
        info.id, info.group_id = draw(INT32), draw(st.one_of(st.just(0), INT32))
        info.done = draw(st.booleans())
        info.max_step_reached = info.done and draw(st.booleans())
        mask_width = draw(st.sampled_from([width, width, width, 0, width + 1])) if width else 0
        mask = draw(st.lists(st.booleans(), min_size=mask_width, max_size=mask_width))
        if mask_width == width and draw(st.sampled_from([True, True, True, False])):
            start = 0  # usually one option of each branch stays allowed (else the message is refused)
            for size in spec.action_spec.discrete_branches:
                mask[start + draw(st.integers(0, size - 1))] = False
                start += size
        info.action_mask.extend(mask)
        for obs_spec, png in zip(spec.observation_specs, pngs):
            obs = info.observations.add()
            obs.shape.extend(obs_spec.shape)
            obs.dimension_properties.extend(int(p) for p in obs_spec.dimension_property)
            obs.observation_type = int(obs_spec.observation_type)
            obs.name = obs_spec.name
            if png:
                pixels = draw(arrays(np.uint8, obs_spec.shape))
                obs.compression_type = observation_pb2.PNG
                obs.compressed_data = png_of(pixels)
            else:
                obs.float_data.data.extend(draw(arrays(np.float32, obs_spec.shape, elements=FLOATS)).ravel().tolist())
        infos.append(info)
    return spec, infos


def brain_parameters(name: str, action_spec: ActionSpec):
    params = brain_parameters_pb2.BrainParametersProto(brain_name=name, is_training=True)
    params.action_spec.num_continuous_actions = action_spec.continuous_size
    params.action_spec.num_discrete_actions = len(action_spec.discrete_branches)
    params.action_spec.discrete_branch_sizes.extend(action_spec.discrete_branches)
    return params


# ------------------------------------------------------------------ decoding
@PROPERTY
@given(scene=st.dictionaries(NAMES, behaviors(), min_size=1, max_size=3),
       side_channel=st.binary(max_size=40), min_rows=st.sampled_from([64, 64, 1, 8]))
def test_decoding_equals_protobufs_fields(scene, side_channel, min_rows):
    message = unity_message_pb2.UnityMessageProto()
    message.header.status = 200
    rl_output = message.unity_output.rl_output
    rl_output.side_channel = side_channel
    for name, (spec, infos) in scene.items():
        rl_output.agentInfos[name].value.extend(infos)
        message.unity_output.rl_initialization_output.brain_parameters.append(brain_parameters(name, spec.action_spec))
    payload = message.SerializeToString()
    specs = {name: spec for name, (spec, _) in scene.items()}
    if any(reference.mask_fault(infos, spec.action_spec.discrete_branches) for spec, infos in scene.values()):
        with patched(records, "MIN_ROWS", min_rows):  # both paths refuse it
            for known in ({}, specs):
                with pytest.raises(ProtocolError, match="action mask of|masked every action"):
                    codec.decode_message(payload, known)
        return
    with patched(records, "MIN_ROWS", min_rows):
        first = codec.decode_message(payload, {}).result  # specs from brain_parameters + first agents
        later = codec.decode_message(payload, specs).result  # every behavior known
    assert first.specs == {name: spec for name, (spec, infos) in scene.items() if infos}
    assert first.side_channel == later.side_channel == side_channel
    assert set(later.steps) == set(scene)
    for name, (spec, infos) in scene.items():
        expected = reference.read_agents(infos, spec.action_spec.discrete_branches)
        reference.assert_steps_equal(*later.steps[name], expected)
        if infos:
            reference.assert_steps_equal(*first.steps[name], expected)
        for steps in later.steps[name]:
            assert [o.shape[1:] for o in steps.obs] == [o.shape for o in spec.observation_specs]


# ------------------------------------------------------------------ the trainer's answers
def protobuf_map_order(keys) -> list[str]:
    """The order in which protobuf's deterministic serialization writes these map keys."""
    from protos.communicator_objects import unity_rl_input_pb2

    probe = unity_rl_input_pb2.UnityRLInputProto()
    for key in keys:
        probe.agent_actions[key].value.add()
    data = probe.SerializeToString(deterministic=True)
    return sorted(keys, key=lambda key: data.index(wire.map_entry(1, key, b"\x0a\x00")))


@st.composite
def actions(draw):
    spec = draw(action_specs)
    n = draw(COUNTS)
    continuous = draw(arrays(np.float32, (n, spec.continuous_size), elements=FLOATS))
    discrete = draw(arrays(np.int32, (n, len(spec.discrete_branches)),
                           elements=st.one_of(st.integers(0, 5), st.integers(0, 300), INT32)))
    return continuous, discrete


@PROPERTY
@given(answer=st.dictionaries(NAMES, actions(), max_size=3), side_channel=st.binary(max_size=300),
       command=st.sampled_from([codec.STEP, codec.STEP, codec.RESET]), none_for_empty=st.booleans())
def test_answers_are_protobufs_bytes(answer, side_channel, command, none_for_empty):
    answer = {name: answer[name] for name in protobuf_map_order(answer)}  # ours writes the given order
    tuples = {name: ActionTuple(None if none_for_empty and c.size == 0 and d.size else c,
                                None if none_for_empty and d.size == 0 and c.size else d)
              for name, (c, d) in answer.items()}
    assert codec.encode_answer(tuples, side_channel, command) == reference.answer(answer, side_channel, command)


# ------------------------------------------------------------------ the stub's agent infos
@st.composite
def stub_infos(draw):
    obs_specs = [s for s, _ in draw(st.lists(observation_specs(png_allowed=False), min_size=1, max_size=3))]
    n = draw(COUNTS)
    observations = [draw(arrays(np.float32, (n, *s.shape), elements=FLOATS)) for s in obs_specs]
    rewards = draw(arrays(np.float32, n, elements=st.one_of(st.just(0.0), FLOATS)))
    ids = draw(arrays(np.int64, n, elements=st.one_of(st.integers(0, 200), st.integers(0, 2**31 - 1))))
    done = draw(st.booleans())
    interrupted = draw(arrays(bool, n)) if done and draw(st.booleans()) else None
    width = draw(st.integers(0, 6))
    mask = draw(arrays(bool, (n, width))) if not done and draw(st.booleans()) else None
    return obs_specs, observations, rewards, ids, done, interrupted, mask


@PROPERTY
@given(drawn=stub_infos())
def test_stub_agent_infos_are_protobufs_bytes(drawn):
    obs_specs, observations, rewards, ids, done, interrupted, mask = drawn
    written = encode_agent_infos(obs_specs, observations, rewards, ids, done, interrupted, mask)
    expected = unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto()
    for row in range(len(ids)):
        info = expected.value.add()
        if rewards[row] != 0:  # Unity's C# leaves a zero reward out, -0.0 included
            info.reward = float(rewards[row])
        info.done = done
        info.max_step_reached = bool(done and interrupted is not None and interrupted[row])
        info.id = int(ids[row])
        if mask is not None:
            info.action_mask.extend(mask[row].tolist())
        for spec, values in zip(obs_specs, observations):
            obs = info.observations.add()
            obs.shape.extend(spec.shape)
            obs.float_data.data.extend(values[row].ravel().tolist())
            obs.dimension_properties.extend(int(p) for p in spec.dimension_property)
            obs.observation_type = int(spec.observation_type)
            obs.name = spec.name
    assert written.count == len(ids)
    assert written.data == expected.SerializeToString()


def test_the_thresholds_the_counts_straddle():
    """The strategies above draw counts around these; if they move, move the counts too."""
    assert records.MIN_ROWS == 64 and wire.MIN_MATRIX_ROWS == 8
