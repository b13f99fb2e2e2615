"""Pure translation between the wire protos and numpy batches (spec §1.6, §3).

Every Unity message is decoded exactly once, here, into the plain types of
``protos.types``; every answer is built here from ``ActionTuple`` batches. Nothing in
this module does I/O or keeps state.
"""
from __future__ import annotations

import functools
import math
import operator
import re
from typing import Mapping, Sequence

import numpy as np

from google.protobuf.message import DecodeError

from protos.communicator_objects import agent_info_pb2, command_pb2, observation_pb2
from protos.communicator_objects import unity_rl_input_pb2, unity_rl_output_pb2
from protos.errors import ProtocolError
from trainer.errors import UnityVersionError
from protos import records, wire
from protos.versions import COMMUNICATION_VERSION, PACKAGE_VERSION
from trainer.protocol.png import decode_png_observation
from protos.types import (
    ActionSpec,
    ActionTuple,
    BehaviorSpec,
    DecisionSteps,
    DimensionProperty,
    ObservationSpec,
    ObservationType,
    StepResult,
    TerminalSteps,
)

STEP = command_pb2.STEP
RESET = command_pb2.RESET

_P = DimensionProperty
SUPPORTED_DIMENSION_PROPERTIES = frozenset(
    {
        (_P.NONE,),
        (_P.UNSPECIFIED,),
        (_P.NONE, _P.TRANSLATIONAL_EQUIVARIANCE, _P.TRANSLATIONAL_EQUIVARIANCE),
        (_P.UNSPECIFIED,) * 3,
        (_P.VARIABLE_SIZE, _P.NONE),
    }
)
_VERSION_RE = re.compile(r"(\d+)\.(\d+)(?:\.(\d+))?(?:[ab]\d+)?")  # StrictVersion's grammar


# --------------------------------------------------------------------------- handshake helpers
def check_communication_version(unity_version: str) -> None:
    """Raise UnityVersionError unless Unity's communication API can talk to ours (spec §1.6).

    Unity major 0: major and minor must equal ours. Otherwise the majors must be equal.
    """
    advice = (
        f"This trainer speaks communication API {COMMUNICATION_VERSION} (ML-Agents Python "
        f"{PACKAGE_VERSION}); rebuild the environment with a Unity ML-Agents package whose "
        "communication API is 1.x (com.unity.ml-agents 3.0.x, ML-Agents Release 22)."
    )
    match = _VERSION_RE.fullmatch(unity_version)
    if match is None:
        raise UnityVersionError(
            f"The Unity environment reported a malformed communication version {unity_version!r}. "
            + advice
        )
    unity_major, unity_minor = int(match.group(1)), int(match.group(2))
    ours_major, ours_minor = (int(p) for p in COMMUNICATION_VERSION.split(".")[:2])
    compatible = unity_major == ours_major and (unity_major != 0 or unity_minor == ours_minor)
    if not compatible:
        raise UnityVersionError(
            f"The Unity environment speaks communication API {unity_version}, which is not "
            f"compatible with {COMMUNICATION_VERSION}. " + advice
        )


# --------------------------------------------------------------------------- behavior specs
def behavior_spec_from_proto(brain_params, agent_info) -> BehaviorSpec:
    """BrainParametersProto + the behavior's first AgentInfoProto → BehaviorSpec (spec §3.2)."""
    observation_specs = []
    for index, obs in enumerate(agent_info.observations):
        shape = tuple(obs.shape)
        props = tuple(_P(p) for p in obs.dimension_properties) or (_P.UNSPECIFIED,) * len(shape)
        if len(props) != len(shape) or props not in SUPPORTED_DIMENSION_PROPERTIES:
            raise ProtocolError(
                f"Unsupported sensor {obs.name!r} (observation {index}) of behavior "
                f"{brain_params.brain_name!r}: shape {shape} with dimension properties "
                f"{[p.name for p in props]}. Supported are vectors (rank 1), CHW images (rank 3) and "
                "variable-length entity lists (VARIABLE_SIZE, NONE); change the sensor in the scene."
            )
        observation_specs.append(
            ObservationSpec(shape, props, ObservationType(obs.observation_type), obs.name)
        )
    return BehaviorSpec(tuple(observation_specs), _action_spec_from_proto(brain_params))


def _action_spec_from_proto(brain_params) -> ActionSpec:
    spec = brain_params.action_spec
    if spec.num_continuous_actions == 0 and spec.num_discrete_actions == 0:
        # communication API < 1.3 only fills the deprecated fields
        sizes = tuple(brain_params.vector_action_size_deprecated)
        if brain_params.vector_action_space_type_deprecated == 1:  # continuous
            return ActionSpec(sizes[0] if sizes else 0, ())
        return ActionSpec(0, sizes)
    return ActionSpec(spec.num_continuous_actions, tuple(spec.discrete_branch_sizes))


# --------------------------------------------------------------------------- Unity → trainer
def decode_rl_output(output, known_specs: Mapping[str, BehaviorSpec],
                     raw_lists: Mapping[str, tuple] | None = None) -> StepResult:
    """Decode one UnityOutputProto into DecisionSteps/TerminalSteps per behavior.

    ``known_specs`` is not modified: specs registered by this message's ``brain_parameters`` are
    returned in ``StepResult.specs`` (the caller merges them). Every behavior with a spec gets an
    entry in ``StepResult.steps`` (empty steps when the message does not mention it).
    ``raw_lists``: agent info lists taken out of the message before it was parsed
    (``records.split_agent_lists``: {behavior: (serialized ListAgentInfoProto, its cut)}).
    """
    agent_infos = output.rl_output.agentInfos
    raw_lists = raw_lists or {}
    new_specs: dict[str, BehaviorSpec] = {}
    for brain_params in output.rl_initialization_output.brain_parameters:
        name = brain_params.brain_name
        if name in raw_lists:
            data, (starts, lengths, _) = raw_lists[name]
            first = _parse(name, agent_info_pb2.AgentInfoProto, data[starts[0]:starts[0] + lengths[0]])
            new_specs[name] = behavior_spec_from_proto(brain_params, first)
        elif name in agent_infos and len(agent_infos[name].value) > 0:
            new_specs[name] = behavior_spec_from_proto(brain_params, agent_infos[name].value[0])
    specs = {**known_specs, **new_specs}
    for name in [*agent_infos, *raw_lists]:
        if name not in specs and (name in raw_lists or len(agent_infos[name].value) > 0):
            raise ProtocolError(
                f"The simulator sent agents of behavior {name!r} without ever sending its "
                "brain_parameters; it does not follow the ML-Agents protocol."
            )
    steps = {}
    for name, spec in specs.items():
        if name in raw_lists:
            steps[name] = _steps_from_list_bytes(name, *raw_lists[name], spec)
        elif name in agent_infos:
            steps[name] = steps_from_agent_infos(name, agent_infos[name].value, spec, agent_infos[name])
        else:
            steps[name] = (DecisionSteps.empty(spec), TerminalSteps.empty(spec))
    return StepResult(specs=new_specs, steps=steps, side_channel=output.rl_output.side_channel)


def _steps_from_list_bytes(behavior_name: str, data: bytes, cut: tuple, spec: BehaviorSpec):
    """``steps_from_agent_infos`` for a serialized ListAgentInfoProto that was never parsed:
    read from its bytes, or, if that path does not apply, parsed now and read agent by agent."""
    fields = _from_bytes(behavior_name, data, spec, cut)
    if fields is None:
        infos = _parse(behavior_name, unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto, data).value
        fields = _agent_by_agent(behavior_name, infos, spec)
    return _split_steps(fields, spec)


def _parse(behavior_name: str, message_type, data: bytes):
    try:
        return message_type.FromString(data)
    except DecodeError as error:
        raise ProtocolError(
            f"The simulator sent agent infos of behavior {behavior_name!r} that are not valid "
            f"AgentInfoProtos ({error}); is it an ML-Agents environment speaking communication "
            "API 1.x? Rebuild it with the ML-Agents package of Release 22."
        ) from None


def _from_bytes(behavior_name: str, data: bytes, spec: BehaviorSpec, cut=None) -> records.Decoded | None:
    """Every agent's fields read from the serialized list (``records.decode``) and checked for
    NaN/Inf; None if the byte path does not apply."""
    fields = records.decode(behavior_name, data, [tuple(o.shape) for o in spec.observation_specs],
                            int(sum(spec.action_spec.discrete_branches)), cut)
    if fields is not None:
        _require_finite_rewards(behavior_name, fields.reward, fields.group_reward, fields.agent_id)
        for index, (stacked, obs_spec) in enumerate(zip(fields.obs, spec.observation_specs)):
            _require_finite(stacked, behavior_name, f"observation {index} ({obs_spec.name})", fields.agent_id)
    return fields


# C-level field access for the per-agent loops (no Python frame per agent)
_SCALAR_FIELDS = operator.attrgetter("reward", "group_reward", "id", "group_id", "done", "max_step_reached")
_OBSERVATIONS = operator.attrgetter("observations")
_FLOAT_DATA = operator.attrgetter("float_data")
_ACTION_MASK = operator.attrgetter("action_mask")
_SERIALIZE = operator.methodcaller("SerializeToString")


def steps_from_agent_infos(
    behavior_name: str, agent_infos: Sequence, spec: BehaviorSpec, agent_info_list=None
) -> tuple[DecisionSteps, TerminalSteps]:
    """Split n AgentInfoProtos into DecisionSteps (done=false) and TerminalSteps (done=true).

    Relative order is kept. Shapes as in ``protos.types``. Three decoders give the same
    fields: plain Python for a few deciding agents; for many, their serialized bytes at once
    (``records``, needs ``agent_info_list``, the ListAgentInfoProto holding ``agent_infos``);
    agent by agent for everything else, which also words the errors.
    """
    n = len(agent_infos)
    fields = _few_deciding_agents(agent_infos, spec) if n < _FEW_AGENTS else None
    if fields is None and agent_info_list is not None and n >= records.MIN_ROWS:
        fields = _from_bytes(behavior_name, agent_info_list.SerializeToString(), spec)
    if fields is None:
        fields = _agent_by_agent(behavior_name, agent_infos, spec)
    return _split_steps(fields, spec)


def _agent_by_agent(behavior_name: str, agent_infos: Sequence, spec: BehaviorSpec) -> records.Decoded:
    """The fields of every agent, read through the protobuf objects; raises ProtocolError."""
    n = len(agent_infos)
    # one pass over the protos; float64 holds float32 rewards and int32 ids exactly
    scalars = np.array(list(map(_SCALAR_FIELDS, agent_infos)), dtype=np.float64).reshape(n, 6)
    floats = scalars[:, :2].astype(np.float32)
    agent_id = scalars[:, 2].astype(np.int64)
    _require_finite_rewards(behavior_name, floats[:, 0], floats[:, 1], agent_id)
    all_obs = list(map(_OBSERVATIONS, agent_infos))
    return records.Decoded(
        reward=floats[:, 0], group_reward=floats[:, 1], agent_id=agent_id,
        group_id=scalars[:, 3].astype(np.int32), done=scalars[:, 4] != 0, max_step=scalars[:, 5] != 0,
        obs=[_stack_observation(behavior_name, index, obs_spec, all_obs, agent_id)
             for index, obs_spec in enumerate(spec.observation_specs)],
        mask=_mask_matrix(agent_infos, int(sum(spec.action_spec.discrete_branches))),
    )


def _split_steps(fields: records.Decoded, spec: BehaviorSpec) -> tuple[DecisionSteps, TerminalSteps]:
    branches = spec.action_spec.discrete_branches
    done = fields.done
    if not done.any():  # the common message: nobody finished, no boolean indexing needed
        decision = DecisionSteps(
            obs=fields.obs,
            reward=fields.reward.copy(),
            agent_id=fields.agent_id,
            action_mask=_split_branches(fields.mask, branches),
            group_id=fields.group_id,
            group_reward=fields.group_reward.copy(),
        )
        return decision, _empty_terminal(spec)
    deciding = ~done
    decision = DecisionSteps(
        obs=[o[deciding] for o in fields.obs],
        reward=fields.reward[deciding],
        agent_id=fields.agent_id[deciding],
        action_mask=_split_branches(fields.mask[deciding], branches),
        group_id=fields.group_id[deciding],
        group_reward=fields.group_reward[deciding],
    )
    terminal = TerminalSteps(
        obs=[o[done] for o in fields.obs],
        reward=fields.reward[done],
        interrupted=fields.max_step[done],
        agent_id=fields.agent_id[done],
        group_id=fields.group_id[done],
        group_reward=fields.group_reward[done],
    )
    return decision, terminal


_FEW_AGENTS = 8  # below this, per-agent Python beats numpy's per-call cost (measured)


def _few_deciding_agents(agent_infos: Sequence, spec: BehaviorSpec) -> records.Decoded | None:
    """The fields of a handful of agents that all ask for a decision, with rank-1 float
    observations: plain Python checks instead of a dozen numpy reductions (one basic agent:
    ~100 -> ~45 us). None when anything else holds (a finished agent, a non-finite value,
    another shape): the other decoders then take the message, and report."""
    rows = list(map(_SCALAR_FIELDS, agent_infos))
    for reward, group_reward, _, _, done, _ in rows:
        if done or not (math.isfinite(reward) and math.isfinite(group_reward)):
            return None
    n = len(rows)
    obs = []
    for index, obs_spec in enumerate(spec.observation_specs):
        if len(obs_spec.shape) != 1:
            return None
        try:
            values = [_FLOAT_DATA(a.observations[index]).data for a in agent_infos]
        except IndexError:
            return None
        if any(len(v) != obs_spec.shape[0] for v in values):
            return None
        stacked = np.array(values, dtype=np.float32).reshape(n, obs_spec.shape[0])
        if not math.isfinite(float(stacked.sum(dtype=np.float64))):  # NaN/Inf propagate into the sum
            return None
        obs.append(stacked)
    columns = list(zip(*rows))
    return records.Decoded(
        reward=np.array(columns[0], dtype=np.float32), group_reward=np.array(columns[1], dtype=np.float32),
        agent_id=np.array(columns[2], dtype=np.int64), group_id=np.array(columns[3], dtype=np.int32),
        done=np.zeros(n, dtype=bool), max_step=np.zeros(n, dtype=bool), obs=obs,
        mask=_mask_matrix(agent_infos, int(sum(spec.action_spec.discrete_branches))),
    )


def _require_finite_rewards(behavior: str, reward: np.ndarray, group_reward: np.ndarray,
                            agent_id: np.ndarray) -> None:
    if not (np.isfinite(reward).all() and np.isfinite(group_reward).all()):
        _require_finite(reward, behavior, "reward", agent_id)
        _require_finite(group_reward, behavior, "group_reward", agent_id)


@functools.lru_cache(maxsize=64)
def _empty_terminal(spec: BehaviorSpec) -> TerminalSteps:
    """Shared by every message without terminal agents (zero-row arrays are never written)."""
    return TerminalSteps.empty(spec)


def _require_finite(values: np.ndarray, behavior: str, field: str, agent_id: np.ndarray) -> None:
    """ProtocolError naming the first agent whose ``values`` row holds NaN or Inf."""
    if np.isfinite(values).all():
        return
    finite = np.isfinite(values.reshape(len(values), -1)).all(axis=1)
    if not finite.all():
        bad = int(np.argmin(finite))
        raise ProtocolError(
            f"Behavior {behavior!r} sent a NaN or infinite {field} for agent id {int(agent_id[bad])}; "
            "fix the reward/observation code of that agent in the Unity project."
        )


def _stack_observation(
    behavior: str, index: int, obs_spec: ObservationSpec, all_obs: list, agent_id: np.ndarray
) -> np.ndarray:
    """Observation ``index`` of every agent → float32 [n, *obs_spec.shape]."""
    try:
        sensor_obs = list(map(operator.itemgetter(index), all_obs))
    except IndexError:
        raise ProtocolError(
            f"An agent of behavior {behavior!r} sent fewer observations than its first agent "
            f"(observation {index} is missing); all agents of a behavior need the same sensors."
        ) from None
    if len(obs_spec.shape) == 3:
        return _stack_visual(behavior, index, obs_spec.shape, sensor_obs, agent_id)
    stacked = _stack_float_data(behavior, index, obs_spec.shape, sensor_obs, agent_id)
    _require_finite(stacked, behavior, f"observation {index} ({obs_spec.name})", agent_id)
    return stacked


def _stack_float_data(
    behavior: str, index: int, shape: tuple[int, ...], sensor_obs: list, agent_id: np.ndarray
) -> np.ndarray:
    """Uncompressed observations → float32 [n, *shape] without touching each float in Python.

    ``FloatData`` serializes to one tag byte, a varint byte length and the packed little-endian
    float32 payload, so n serialized messages of equal length form an [n, header + 4*size]
    byte matrix whose payload columns are the observations.
    """
    n, size = len(sensor_obs), math.prod(shape)
    if size == 0:
        return np.zeros((n, *shape), dtype=np.float32)
    header = _float_data_header(4 * size)
    row_bytes = len(header) + 4 * size
    parts = list(map(_SERIALIZE, map(_FLOAT_DATA, sensor_obs)))
    lengths = np.fromiter(map(len, parts), dtype=np.int64, count=n)
    wrong = np.nonzero(lengths != row_bytes)[0]
    if len(wrong):
        row = int(wrong[0])
        raise ProtocolError(
            f"Observation {index} of agent id {int(agent_id[row])} (behavior {behavior!r}) has "
            f"{max(len(parts[row]) - len(header), 0) // 4} floats but its sensor shape {shape} needs "
            f"{size}; all agents of a behavior need the same sensor shapes."
        )
    matrix = np.frombuffer(b"".join(parts), dtype=np.uint8).reshape(n, row_bytes)
    payload = np.ascontiguousarray(matrix[:, len(header):])
    return payload.view("<f4").astype(np.float32, copy=False).reshape(n, *shape)


@functools.lru_cache(maxsize=256)
def _float_data_header(byte_length: int) -> bytes:
    return wire.len_prefix(1, byte_length)


def _stack_visual(
    behavior: str, index: int, shape: tuple[int, ...], sensor_obs: list, agent_id: np.ndarray
) -> np.ndarray:
    """Rank-3 observations (PNG or float) → float32 [n, C, H, W]."""
    out = np.empty((len(sensor_obs), *shape), dtype=np.float32)
    for row, obs in enumerate(sensor_obs):
        if tuple(obs.shape) != shape:
            raise ProtocolError(
                f"Observation {index} of agent id {int(agent_id[row])} (behavior {behavior!r}) has "
                f"shape {tuple(obs.shape)} but the sensor declared {shape}."
            )
        if obs.compression_type == observation_pb2.PNG:
            out[row] = decode_png_observation(
                obs.compressed_data, shape, list(obs.compressed_channel_mapping)
            )
        else:
            out[row] = _stack_float_data(behavior, index, shape, [obs], agent_id[row : row + 1])[0]
    return out


def _mask_matrix(agent_infos: Sequence, total: int) -> np.ndarray:
    """bool [n, total], True = masked. A mask whose length is not ``total`` (the sum of the
    branch sizes) is ignored: nothing masked for that agent."""
    if total == 0:
        return np.zeros((len(agent_infos), 0), dtype=bool)
    nothing = [False] * total
    rows = [list(mask) if len(mask) == total else nothing for mask in map(_ACTION_MASK, agent_infos)]
    return np.array(rows, dtype=bool).reshape(len(rows), total)


def _split_branches(matrix: np.ndarray, branches: tuple[int, ...]) -> list[np.ndarray] | None:
    """Per branch bool [n, branch_size]; None without discrete branches."""
    if not branches:
        return None
    return [matrix[:, start:end] for start, end in _branch_bounds(branches)]


@functools.lru_cache(maxsize=64)
def _branch_bounds(branches: tuple[int, ...]) -> tuple[tuple[int, int], ...]:
    ends = np.cumsum(branches).tolist()
    return tuple(zip([0] + ends[:-1], ends))


# --------------------------------------------------------------------------- trainer → Unity
def encode_rl_input(
    actions: Mapping[str, ActionTuple], side_channel: bytes, command: int = STEP
) -> unity_rl_input_pb2.UnityRLInputProto:
    """Build a UnityRLInputProto (spec §3.4). RESET carries no actions."""
    rl_input = unity_rl_input_pb2.UnityRLInputProto()
    fill_rl_input(rl_input, actions, side_channel, command)
    return rl_input


def fill_rl_input(
    rl_input, actions: Mapping[str, ActionTuple], side_channel: bytes, command: int = STEP
) -> None:
    """Fill an empty UnityRLInputProto in place (lets the server avoid a copy).

    Per behavior: one AgentActionProto per row of the ActionTuple (continuous float32 [n, c],
    discrete int32 [n, b]); ``vector_actions_deprecated`` = continuous then discrete as floats.
    Behaviors with zero rows are left out.
    """
    rl_input.command = command
    rl_input.side_channel = bytes(side_channel)
    if command == RESET:
        return
    for behavior_name, action in actions.items():
        continuous, discrete = _as_action_matrices(action)
        if len(continuous) == 0:
            continue
        encoded = encode_agent_actions(continuous, discrete) if len(continuous) >= wire.MIN_MATRIX_ROWS else None
        if encoded is not None:
            rl_input.agent_actions[behavior_name].MergeFromString(encoded)
        else:
            _fill_agent_actions(rl_input.agent_actions[behavior_name].value, continuous, discrete)


def encode_agent_actions(continuous: np.ndarray, discrete: np.ndarray) -> bytes | None:
    """Serialized ListAgentActionProto for n agents, built as one byte matrix.

    Per agent: ``vector_actions_deprecated`` (continuous then discrete, as floats),
    ``continuous_actions``, ``discrete_actions``, each packed. None when a discrete action is
    outside [0, 128) (its varint would not be one byte): the caller then fills messages one by one.
    """
    n, c = continuous.shape
    b = discrete.shape[1]
    if b and (discrete.min() < 0 or discrete.max() >= 128):
        return None
    parts: list = []
    if c + b:
        deprecated = np.concatenate([continuous, discrete.astype(np.float32)], axis=1)
        parts += [wire.len_prefix(1, 4 * (c + b)), wire.float_columns(deprecated, n)]
    if c:
        parts += [wire.len_prefix(6, 4 * c), wire.float_columns(continuous, n)]
    if b:
        parts += [wire.len_prefix(7, b), discrete.astype(np.uint8)]
    return wire.repeated_rows(1, parts, n)


def _encode_few_agent_actions(continuous: np.ndarray, discrete: np.ndarray) -> bytes | None:
    """``encode_agent_actions`` for fewer than ``wire.MIN_MATRIX_ROWS`` agents, joined in a plain
    loop (numpy's per-call cost loses there). None for a negative discrete action (its varint
    would need ten bytes: the protobuf objects then write it)."""
    n, c = continuous.shape
    b = discrete.shape[1]
    rows = discrete.tolist()
    if b and min(map(min, rows)) < 0:
        return None
    floats = continuous.tobytes()  # float32 [n, c], as _as_action_matrices made it
    as_floats = discrete.astype("<f4").tobytes()
    deprecated = wire.len_prefix(1, 4 * (c + b)) if c + b else b""
    continuous_prefix = wire.len_prefix(6, 4 * c) if c else b""
    records = []
    for row, actions in enumerate(rows):
        own = floats[4 * c * row:4 * c * (row + 1)]
        parts = [deprecated, own, as_floats[4 * b * row:4 * b * (row + 1)]] if c + b else []
        if c:
            parts += [continuous_prefix, own]
        if b:
            varints = b"".join(map(wire.varint, actions))
            parts += [wire.len_prefix(7, len(varints)), varints]
        content = b"".join(parts)
        records.append(wire.len_prefix(1, len(content)) + content)
    return b"".join(records)


def step_message_bytes(actions: Mapping[str, ActionTuple], side_channel: bytes) -> bytes | None:
    """The serialized UnityMessageProto answering a call with STEP and status 200, written
    directly: what ``fill_rl_input`` + ``SerializeToString`` give (the same bytes for one
    behavior; several behaviors' map entries in ``actions`` order), without building message
    objects on every step. None when some action needs the protobuf objects (a negative or
    too large discrete action)."""
    entries = []
    for behavior_name, action in actions.items():
        continuous, discrete = _as_action_matrices(action)
        if len(continuous) == 0:
            continue
        if len(continuous) >= wire.MIN_MATRIX_ROWS:
            value = encode_agent_actions(continuous, discrete)
        else:
            value = _encode_few_agent_actions(continuous, discrete)
        if value is None:
            return None
        key = behavior_name.encode()
        entry = wire.len_prefix(1, len(key)) + key + wire.len_prefix(2, len(value)) + value
        entries.append(wire.len_prefix(1, len(entry)) + entry)
    if side_channel:  # command STEP is 0, the proto3 default: not written
        entries += [wire.len_prefix(5, len(side_channel)), bytes(side_channel)]
    rl_input = b"".join(entries)
    unity_input = wire.len_prefix(1, len(rl_input)) + rl_input
    return wire.HEADER_OK_FIELD + wire.len_prefix(3, len(unity_input)) + unity_input


def _fill_agent_actions(value, continuous: np.ndarray, discrete: np.ndarray) -> None:
    """The same messages as ``encode_agent_actions``, one AgentActionProto at a time."""
    deprecated = np.concatenate([continuous, discrete.astype(np.float32)], axis=1)
    for cont_row, disc_row, dep_row in zip(continuous.tolist(), discrete.tolist(), deprecated.tolist()):
        agent_action = value.add()
        agent_action.vector_actions_deprecated.extend(dep_row)
        agent_action.continuous_actions.extend(cont_row)
        agent_action.discrete_actions.extend(disc_row)


def _as_action_matrices(action: ActionTuple) -> tuple[np.ndarray, np.ndarray]:
    """ActionTuple → (float32 [n, c], int32 [n, b]); a None or empty part becomes [n, 0]."""
    continuous, discrete = parts = (action.continuous, action.discrete)
    if (type(continuous) is np.ndarray and type(discrete) is np.ndarray  # what the policy gives
            and continuous.dtype == np.float32 and discrete.dtype == np.int32
            and continuous.ndim == discrete.ndim == 2 and len(continuous) == len(discrete)):
        return continuous, discrete
    rows = {len(p) for p in parts if p is not None and np.size(p) > 0}
    if len(rows) > 1:
        raise ValueError(f"continuous and discrete actions have different agent counts {rows}")
    n = rows.pop() if rows else max((len(p) for p in parts if p is not None and np.ndim(p)), default=0)
    return _as_matrix(parts[0], n, np.float32), _as_matrix(parts[1], n, np.int32)


def _as_matrix(part, n: int, dtype) -> np.ndarray:
    if part is None or np.size(part) == 0:
        return np.zeros((n, 0), dtype=dtype)
    return np.asarray(part, dtype=dtype).reshape(n, -1)
