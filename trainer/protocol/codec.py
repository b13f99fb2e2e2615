"""The trainer's codec: a simulator's message bytes -> numpy batches, actions -> answer bytes.

Every message from the simulator goes through ``decode_message`` exactly once, into the plain
types of ``protos.types``; every answer is written by ``encode_answer`` from ``ActionTuple``
batches. Nothing in this module does I/O or keeps state.

Two decode paths, no more (docs/protocol.md):

* **protobuf** — the message is parsed by the generated classes and each behavior's agents are
  read agent by agent (``steps_from_agent_infos``). It takes everything: PNG observations,
  unusual layouts, malformed values, and it words the precise errors.
* **records** — an agent info list of at least ``records.MIN_ROWS`` agents is cut out of the
  message bytes before parsing (``records.split_agent_lists``) and read as one byte matrix
  (``records.decode``); whatever that reader does not handle falls back to the protobuf path.

The records path wins for many agents and loses for few (its fixed cost is numpy's), hence
``records.MIN_ROWS`` = 64; the measurements: docs/performance.md, "The byte codec".
"""
from __future__ import annotations

import functools
import logging
import math
import operator
import re
from typing import Mapping, NamedTuple, Sequence

import numpy as np

from google.protobuf.message import DecodeError

from protos import records, wire
from protos.communicator_objects import agent_info_pb2, command_pb2, observation_pb2
from protos.communicator_objects import unity_message_pb2, unity_rl_output_pb2
from protos.errors import ProtocolError
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
from protos.versions import COMMUNICATION_VERSION, PACKAGE_VERSION
from trainer.errors import UnityVersionError
from trainer.protocol.png import decode_png_observation

logger = logging.getLogger(__name__)

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
_DIMENSION_PROPERTY_VALUES = frozenset(int(p) for p in _P)
_VERSION_RE = re.compile(r"(\d+)\.(\d+)(?:\.(\d+))?(?:[ab]\d+)?")  # StrictVersion's grammar


# --------------------------------------------------------------------------- handshake helpers
def check_communication_version(unity_version: str) -> None:
    """Raise UnityVersionError unless Unity's communication API can talk to ours (docs/protocol.md, "Version checks").

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
# Bounds on what a simulator may declare, checked before anything is allocated for it
# (docs/protocol.md, "Behavior spec", "Limits"). Real games declare tens of actions and observations of at
# most a few hundred thousand floats; these leave a wide margin and keep the trainer's memory
# for one behavior within a budget: the policy's output layer is at most
# (MAX_CONTINUOUS_ACTIONS + MAX_DISCRETE_OPTIONS) x hidden_units floats (36 MiB at 512 units),
# one agent's action mask MAX_DISCRETE_OPTIONS bools, and one decoded observation
# MAX_OBSERVATION_FLOATS floats (64 MiB).
MAX_CONTINUOUS_ACTIONS = 2048
MAX_DISCRETE_BRANCHES = 1024
MAX_DISCRETE_OPTIONS = 16384  # the sum of the branch sizes
MAX_OBSERVATION_FLOATS = 1 << 24
# decoded PNG observations of one message, before the images are decoded (a PNG of a few bytes
# can declare any size: it is checked against this and the sensor shape first)
MAX_DECODED_IMAGE_BYTES = 1 << 30


def behavior_spec_from_proto(brain_params, agent_info) -> BehaviorSpec:
    """BrainParametersProto + the behavior's first AgentInfoProto → BehaviorSpec (docs/protocol.md, "Behavior spec").

    Raises ProtocolError for a spec the trainer cannot train, or one beyond the limits above."""
    name = brain_params.brain_name
    if not agent_info.observations:
        raise ProtocolError(
            f"Behavior {name!r} sent an agent without any observation; a policy needs at least one "
            "sensor. Add a sensor (or vector observations) to its agents in the Unity scene."
        )
    observation_specs = []
    for index, obs in enumerate(agent_info.observations):
        shape = tuple(obs.shape)
        known = all(p in _DIMENSION_PROPERTY_VALUES for p in obs.dimension_properties)
        props = tuple(_P(p) if known else p for p in obs.dimension_properties) or (_P.UNSPECIFIED,) * len(shape)
        if len(props) != len(shape) or props not in SUPPORTED_DIMENSION_PROPERTIES:
            raise ProtocolError(
                f"Unsupported sensor {obs.name!r} (observation {index}) of behavior "
                f"{brain_params.brain_name!r}: shape {shape} with dimension properties "
                f"{[getattr(p, 'name', p) for p in props]}. Supported are vectors (rank 1), CHW images (rank 3) and "
                "variable-length entity lists (VARIABLE_SIZE, NONE); change the sensor in the scene."
            )
        if any(d <= 0 for d in shape) or math.prod(shape) > MAX_OBSERVATION_FLOATS:
            raise ProtocolError(
                f"Sensor {obs.name!r} (observation {index}) of behavior {name!r} declares shape "
                f"{shape}; each dimension must be positive and an observation at most "
                f"{MAX_OBSERVATION_FLOATS} floats. Check the sensor's size in the Unity scene."
            )
        try:
            observation_type = ObservationType(obs.observation_type)
        except ValueError:
            raise ProtocolError(
                f"Sensor {obs.name!r} (observation {index}) of behavior {name!r} has the unknown "
                f"observation type {obs.observation_type}; rebuild the environment with the "
                "ML-Agents package of Release 22."
            ) from None
        observation_specs.append(ObservationSpec(shape, props, observation_type, obs.name))
    return BehaviorSpec(tuple(observation_specs), _checked_action_spec(name, _action_spec_from_proto(brain_params)))


def _checked_action_spec(name: str, spec: ActionSpec) -> ActionSpec:
    """``spec`` if the trainer can build a policy for it, else ProtocolError (limits above)."""
    branches = spec.discrete_branches
    fault = None
    if spec.continuous_size < 0 or spec.continuous_size > MAX_CONTINUOUS_ACTIONS:
        fault = f"{spec.continuous_size} continuous actions (at most {MAX_CONTINUOUS_ACTIONS})"
    elif len(branches) > MAX_DISCRETE_BRANCHES:
        fault = f"{len(branches)} discrete branches (at most {MAX_DISCRETE_BRANCHES})"
    elif any(size <= 0 for size in branches):
        fault = f"discrete branch sizes {_brief(branches)}: every branch needs at least one option"
    elif sum(branches) > MAX_DISCRETE_OPTIONS:
        fault = f"{sum(branches)} discrete options over all branches (at most {MAX_DISCRETE_OPTIONS})"
    if fault is not None:
        raise ProtocolError(
            f"Behavior {name!r} declares {fault}; the trainer cannot build a policy for it. Fix the "
            "Behavior Parameters (action specification) of its agents in the Unity scene."
        )
    return spec


def _brief(values: Sequence[int]) -> str:
    shown = ", ".join(map(str, values[:8]))
    return f"[{shown}{', ...' if len(values) > 8 else ''}]"


def _action_spec_from_proto(brain_params) -> ActionSpec:
    spec = brain_params.action_spec
    if spec.num_discrete_actions != len(spec.discrete_branch_sizes):  # ML-Agents fills both from one list
        raise ProtocolError(
            f"Behavior {brain_params.brain_name!r} declares {spec.num_discrete_actions} discrete branches "
            f"but lists {len(spec.discrete_branch_sizes)} branch sizes "
            f"{_brief(spec.discrete_branch_sizes)}: its action specification contradicts itself, so "
            "the trainer cannot tell which actions it expects. The simulator does not fill its brain "
            "parameters as ML-Agents does; fix how it builds them.")
    if spec.num_continuous_actions == 0 and spec.num_discrete_actions == 0:
        # communication API < 1.3 only fills the deprecated fields
        sizes = tuple(brain_params.vector_action_size_deprecated)
        if brain_params.vector_action_space_type_deprecated == 1:  # continuous
            return ActionSpec(sizes[0] if sizes else 0, ())
        return ActionSpec(0, sizes)
    return ActionSpec(spec.num_continuous_actions, tuple(spec.discrete_branch_sizes))


# --------------------------------------------------------------------------- Unity → trainer
NON_FINITE_STAT = "Environment/Non-finite Agent Steps Dropped"  # summed per summary period
_WARNED_NON_FINITE: set[str] = set()  # behaviors whose first dropped step was logged


class Dropped(NamedTuple):
    """Agents of one behavior left out of a message for NaN/Inf (``_drop_non_finite``)."""

    count: int  # deciding and finished agents left out
    deciding: int  # deciding agents the simulator sent: it is owed one action row for each
    kept: np.ndarray  # int positions, among those, of the rows DecisionSteps holds
    ended: np.ndarray  # int64 agent (episode) ids of finished agents left out: their episodes end unseen


class NotAMessageError(ProtocolError):
    """The payload is not a UnityMessageProto at all (the server then fails the call itself)."""


class DecodedMessage(NamedTuple):
    message: unity_message_pb2.UnityMessageProto  # parsed, without the agent lists read from bytes
    result: StepResult | None  # None when the status is not 200 (the simulator is closing)


def decode_message(payload: bytes, known_specs: Mapping[str, BehaviorSpec]) -> DecodedMessage:
    """A serialized UnityMessageProto from the simulator → the parsed message and its steps.

    Agent info lists of at least ``records.MIN_ROWS`` agents are taken out of the bytes before
    parsing and read by the records path; everything else is parsed by protobuf (module doc).
    ``known_specs`` is not modified (see ``decode_rl_output``). Raises NotAMessageError for
    bytes that are not a UnityMessageProto, ProtocolError for agent data the protocol does not
    allow (naming the first bad agent).
    """
    body, lists = payload, {}
    if len(payload) >= _split_threshold(known_specs):
        split = records.split_agent_lists(payload, records.MIN_ROWS)
        if split is not None:
            body, lists = split
    try:
        message = unity_message_pb2.UnityMessageProto.FromString(body)
    except DecodeError as error:
        raise NotAMessageError(f"not a valid UnityMessageProto ({error})") from None
    if message.header.status != 200:
        return DecodedMessage(message, None)
    return DecodedMessage(message, decode_rl_output(message.unity_output, known_specs, lists))


def _split_threshold(known_specs: Mapping[str, BehaviorSpec]) -> int:
    """The smallest message that can hold a list the records path would take: ``MIN_ROWS``
    records of the known behavior with the fewest observation floats (4 bytes each, plus the
    record's 2-byte header); 0 before any behavior is known. Smaller messages skip looking
    (the walk costs ~11 us, a fifth of a 12-agent decode); a list that is missed is still
    decoded, by protobuf."""
    return records.MIN_ROWS * min(map(_record_floor, known_specs.values()), default=0)


@functools.lru_cache(maxsize=64)
def _record_floor(spec: BehaviorSpec) -> int:
    return 2 + 4 * sum(math.prod(o.shape) for o in spec.observation_specs)


def decode_rl_output(output, known_specs: Mapping[str, BehaviorSpec],
                     lists: Mapping[str, tuple] | None = None) -> StepResult:
    """Decode one UnityOutputProto into DecisionSteps/TerminalSteps per behavior.

    ``known_specs`` is not modified: specs registered by this message's ``brain_parameters`` are
    returned in ``StepResult.specs`` (the caller merges them). Every behavior with a spec gets an
    entry in ``StepResult.steps`` (empty steps when the message does not mention it).
    ``lists``: agent info lists taken out of the message before it was parsed
    (``records.split_agent_lists``: {behavior: (serialized ListAgentInfoProto, its cut)}).
    """
    agent_infos = output.rl_output.agentInfos
    lists = lists or {}
    new_specs: dict[str, BehaviorSpec] = {}
    compressions: dict[str, tuple[str, ...]] = {}
    for brain_params in output.rl_initialization_output.brain_parameters:
        name = brain_params.brain_name
        if name in lists:
            data, (starts, lengths, _) = lists[name]
            first = _parse(name, agent_info_pb2.AgentInfoProto, data[starts[0]:starts[0] + lengths[0]])
        elif name in agent_infos and len(agent_infos[name].value) > 0:
            first = agent_infos[name].value[0]
        else:
            continue
        new_specs[name] = behavior_spec_from_proto(brain_params, first)
        compressions[name] = tuple("png" if o.compression_type == observation_pb2.PNG else "none"
                                   for o in first.observations)
    for name, spec in new_specs.items():
        known = known_specs.get(name)
        if known is not None and _network_shape(known) != _network_shape(spec):
            raise ProtocolError(
                f"Behavior {name!r} changed its specification mid-run, from {_describe_spec(known)} "
                f"to {_describe_spec(spec)}; the trainer's networks are built for the first one. "
                "Keep each behavior's sensors and actions fixed during a run, or give the new "
                "setup its own behavior name."
            )
    specs = {**known_specs, **new_specs}
    for name in [*agent_infos, *lists]:
        if name not in specs and (name in lists or len(agent_infos[name].value) > 0):
            raise ProtocolError(
                f"The simulator sent agents of behavior {name!r} without ever sending its "
                "brain_parameters; it does not follow the ML-Agents protocol."
            )
    steps, dropped = {}, {}
    for name, spec in specs.items():
        if name in lists:
            fields = _list_fields(name, *lists[name], spec)
        elif name in agent_infos:
            fields = _agent_by_agent(name, agent_infos[name].value, spec)
        else:
            steps[name] = (DecisionSteps.empty(spec), TerminalSteps.empty(spec))
            continue
        fields, dropped_here = _drop_non_finite(name, fields)
        if dropped_here is not None:
            dropped[name] = dropped_here
        steps[name] = _split_steps(fields, spec)
    return StepResult(specs=new_specs, steps=steps, side_channel=output.rl_output.side_channel,
                      compressions=compressions, dropped=dropped)


def _drop_non_finite(behavior: str, fields: records.Decoded) -> tuple[records.Decoded, Dropped | None]:
    """``fields`` without the agents whose reward, group reward or any observation holds NaN or
    Inf (docs/protocol.md, "Simulator → trainer"): they never reach the networks. Also what was dropped,
    or None."""
    # the common message: NaN and Inf propagate into a Python sum of the rewards (0.3 us for 12
    # agents, where two numpy checks cost 2 us), then one pass over each observation array
    if (math.isfinite(sum(fields.reward.tolist()) + sum(fields.group_reward.tolist()))
            and all(np.isfinite(o).all() for o in fields.obs)):
        return fields, None
    finite = [np.isfinite(fields.reward), np.isfinite(fields.group_reward)] + [np.isfinite(o) for o in fields.obs]
    n = len(fields.reward)
    ok = np.logical_and.reduce([f.reshape(n, -1).all(axis=1) for f in finite])
    if ok.all():  # the rewards' sum overflowed, nothing else
        return fields, None
    deciding = ~fields.done
    bad = int(np.argmin(ok))
    if behavior not in _WARNED_NON_FINITE:
        _WARNED_NON_FINITE.add(behavior)
        logger.warning(
            "Behavior %r sent a NaN or infinite reward or observation (first: agent id %d); such agent "
            "steps are dropped and counted in TensorBoard as %r. Fix the reward/observation code of "
            "that agent in the Unity project.", behavior, int(fields.agent_id[bad]), NON_FINITE_STAT)
    kept = records.Decoded(
        reward=fields.reward[ok], group_reward=fields.group_reward[ok], agent_id=fields.agent_id[ok],
        group_id=fields.group_id[ok], done=fields.done[ok], max_step=fields.max_step[ok],
        obs=[o[ok] for o in fields.obs], mask=fields.mask[ok])
    return kept, Dropped(int(n - ok.sum()), int(deciding.sum()), np.flatnonzero(ok[deciding]),
                         fields.agent_id[~ok & fields.done].astype(np.int64))


def _network_shape(spec: BehaviorSpec) -> tuple:
    """What the trainer's networks are built from: sensor names may change, and the supported
    dimension properties of one rank are all read the same way."""
    return (tuple((o.shape, o.observation_type) for o in spec.observation_specs),
            spec.action_spec)


def _describe_spec(spec: BehaviorSpec) -> str:
    shapes = ", ".join(str(o.shape) for o in spec.observation_specs)
    action = spec.action_spec
    return (f"observations {shapes} with {action.continuous_size} continuous actions and discrete "
            f"branches {_brief(action.discrete_branches)}")


def decode_agent_list(behavior_name: str, data: bytes, cut, spec: BehaviorSpec):
    """A serialized ListAgentInfoProto → (DecisionSteps, TerminalSteps): read by the records
    path, or, where that does not apply, parsed and read agent by agent. ``cut``: its
    ``records`` cut if known (else None). Agents with NaN/Inf are left out (``decode_rl_output``
    says which)."""
    fields, _ = _drop_non_finite(behavior_name, _list_fields(behavior_name, data, cut, spec))
    return _split_steps(fields, spec)


def _list_fields(behavior_name: str, data: bytes, cut, spec: BehaviorSpec) -> records.Decoded:
    fields = records.decode(behavior_name, data, [tuple(o.shape) for o in spec.observation_specs],
                            int(sum(spec.action_spec.discrete_branches)), cut)
    if fields is None:
        infos = _parse(behavior_name, unity_rl_output_pb2.UnityRLOutputProto.ListAgentInfoProto, data).value
        fields = _agent_by_agent(behavior_name, infos, spec)
    return fields


def steps_from_agent_infos(
    behavior_name: str, agent_infos: Sequence, spec: BehaviorSpec
) -> tuple[DecisionSteps, TerminalSteps]:
    """The protobuf path: n AgentInfoProtos → DecisionSteps (done=false) and TerminalSteps
    (done=true), relative order kept, shapes as in ``protos.types``; raises ProtocolError.
    Agents with NaN/Inf are left out (``decode_rl_output`` says which)."""
    fields, _ = _drop_non_finite(behavior_name, _agent_by_agent(behavior_name, agent_infos, spec))
    return _split_steps(fields, spec)


def agent_fields(behavior_name: str, agent_infos: Sequence, spec: BehaviorSpec) -> records.Decoded:
    """The fields of n AgentInfoProtos in their own order (obs [n, ...] per sensor, reward, done,
    max_step, ...), nothing dropped: a demonstration's records (trainer/demonstrations.py)."""
    return _agent_by_agent(behavior_name, agent_infos, spec)


def _parse(behavior_name: str, message_type, data: bytes):
    try:
        return message_type.FromString(data)
    except DecodeError as error:
        raise ProtocolError(
            f"The simulator sent agent infos of behavior {behavior_name!r} that are not valid "
            f"AgentInfoProtos ({error}); is it an ML-Agents environment speaking communication "
            "API 1.x? Rebuild it with the ML-Agents package of Release 22."
        ) from None


# C-level field access for the per-agent loops (no Python frame per agent)
_SCALAR_FIELDS = operator.attrgetter("reward", "group_reward", "id", "group_id", "done", "max_step_reached")
_OBSERVATIONS = operator.attrgetter("observations")
_FLOAT_DATA = operator.attrgetter("float_data")
_ACTION_MASK = operator.attrgetter("action_mask")
_SERIALIZE = operator.methodcaller("SerializeToString")


def _agent_by_agent(behavior_name: str, agent_infos: Sequence, spec: BehaviorSpec) -> records.Decoded:
    """The fields of every agent, read through the protobuf objects; raises ProtocolError."""
    n = len(agent_infos)
    if n == 0:
        return _no_agents(spec)
    reward, group_reward, agent_id, group_id, done, max_step = zip(*map(_SCALAR_FIELDS, agent_infos))
    ids = np.array(agent_id, dtype=np.int64)
    rewards = np.array(reward, dtype=np.float32)
    group_rewards = np.array(group_reward, dtype=np.float32)
    all_obs = list(map(_OBSERVATIONS, agent_infos))
    return records.Decoded(
        reward=rewards, group_reward=group_rewards, agent_id=ids,
        group_id=np.array(group_id, dtype=np.int32), done=np.array(done, dtype=bool),
        max_step=np.array(max_step, dtype=bool),
        obs=[_stack_observation(behavior_name, index, obs_spec, all_obs, ids)
             for index, obs_spec in enumerate(spec.observation_specs)],
        mask=_mask_matrix(behavior_name, agent_infos, int(sum(spec.action_spec.discrete_branches)), ids, done),
    )


def _no_agents(spec: BehaviorSpec) -> records.Decoded:
    return records.Decoded(
        reward=np.zeros(0, np.float32), group_reward=np.zeros(0, np.float32),
        agent_id=np.zeros(0, np.int64), group_id=np.zeros(0, np.int32),
        done=np.zeros(0, bool), max_step=np.zeros(0, bool),
        obs=[np.zeros((0, *o.shape), np.float32) for o in spec.observation_specs],
        mask=np.zeros((0, int(sum(spec.action_spec.discrete_branches))), bool),
    )


def _split_steps(fields: records.Decoded, spec: BehaviorSpec) -> tuple[DecisionSteps, TerminalSteps]:
    branches = spec.action_spec.discrete_branches
    done = fields.done
    if branches and fields.mask.any():
        _require_an_option_per_branch(fields, branches)
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


@functools.lru_cache(maxsize=64)
def _empty_terminal(spec: BehaviorSpec) -> TerminalSteps:
    """Shared by every message without terminal agents (zero-row arrays are never written)."""
    return TerminalSteps.empty(spec)


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
        stacked = _stack_visual(behavior, index, obs_spec.shape, sensor_obs, agent_id)
    else:
        stacked = _stack_float_data(behavior, index, obs_spec.shape, sensor_obs, agent_id)
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
    if any(len(part) != row_bytes for part in parts):
        row = next(r for r, part in enumerate(parts) if len(part) != row_bytes)
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
    if 4 * len(sensor_obs) * math.prod(shape) > MAX_DECODED_IMAGE_BYTES:
        raise ProtocolError(
            f"Behavior {behavior!r} sent {len(sensor_obs)} image observations of shape {shape} in one "
            f"message, more than the trainer decodes at once ({MAX_DECODED_IMAGE_BYTES >> 20} MiB as "
            "floats); lower the camera resolution or the number of agents per simulator."
        )
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


def _mask_matrix(behavior: str, agent_infos: Sequence, total: int, agent_id: np.ndarray,
                 done: Sequence[bool]) -> np.ndarray:
    """bool [n, total], True = masked. An empty mask masks nothing; a deciding agent's mask of
    any other length than ``total`` (the sum of the branch sizes) is a ProtocolError naming the
    agent (a finished agent's mask is never used: it masks nothing). Without discrete actions
    there is nothing to mask: masks are not read."""
    if total == 0:
        return np.zeros((len(agent_infos), 0), dtype=bool)
    masks = list(map(_ACTION_MASK, agent_infos))
    if not any(map(len, masks)):  # the common case: nobody masks anything
        return np.zeros((len(masks), total), dtype=bool)
    nothing = [False] * total
    rows = []
    for row, mask in enumerate(masks):
        if len(mask) == total:
            rows.append(list(mask))
        elif not mask or done[row]:
            rows.append(nothing)
        else:
            _bad_mask_length(behavior, agent_id[row], len(mask), total)
    return np.array(rows, dtype=bool).reshape(len(rows), total)


def _bad_mask_length(behavior: str, agent_id, length: int, total: int) -> None:
    raise ProtocolError(
        f"Agent id {int(agent_id)} of behavior {behavior!r} sent an action mask of {length} entries; "
        f"its discrete branches have {total} options in all. Mask through the ML-Agents "
        "WriteDiscreteActionMask API, one entry per option of each branch."
    )


def _require_an_option_per_branch(fields: records.Decoded, branches: tuple[int, ...]) -> None:
    """ProtocolError if a deciding agent masks every option of a branch (nothing to choose)."""
    deciding = ~fields.done
    for branch, (start, end) in enumerate(_branch_bounds(branches)):
        all_masked = fields.mask[:, start:end].all(axis=1) & deciding
        if all_masked.any():
            agent = int(fields.agent_id[int(np.argmax(all_masked))])
            raise ProtocolError(
                f"Agent id {agent} masked every action of discrete branch {branch} (size "
                f"{end - start}); at least one option per branch must stay allowed. Fix the agent's "
                "WriteDiscreteActionMask code in the Unity project."
            )


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
def encode_answer(actions: Mapping[str, ActionTuple], side_channel: bytes, command: int = STEP) -> bytes:
    """The serialized UnityMessageProto answering a simulator's call with status 200, written
    directly (no message objects): header, then unity_input (3) = rl_input (1) {one
    agent_actions (1) map entry per behavior with at least one row, in ``actions`` order:
    key (1), ListAgentActionProto (2); command (4) unless STEP, the proto3 default;
    side_channel (5) unless empty}. RESET carries no actions. Protobuf writes the same bytes
    for the same message (tests/protocol/test_codec_properties.py).

    Per agent (AgentActionProto): ``vector_actions_deprecated`` (continuous then discrete, as
    floats), ``continuous_actions`` (float32), ``discrete_actions`` (int32), each packed;
    ``actions[behavior]`` holds continuous float32 [n, c] and discrete int32 [n, b].
    """
    entries = []
    if command != RESET:
        for behavior_name, action in actions.items():
            continuous, discrete = as_action_matrices(action)
            if len(continuous) == 0:
                continue
            entries.append(wire.map_entry(1, behavior_name, agent_actions_bytes(continuous, discrete)))
    if command != STEP:
        entries += [wire.tag(4, wire.VARINT), wire.varint(command)]
    if side_channel:
        entries.append(wire.field(5, bytes(side_channel)))
    return wire.HEADER_OK_FIELD + wire.field(3, wire.field(1, b"".join(entries)))


def agent_actions_bytes(continuous: np.ndarray, discrete: np.ndarray) -> bytes:
    """The serialized ListAgentActionProto of n agents (float32 [n, c], int32 [n, b]).

    Two writers of the same bytes, because each loses badly where the other wins: rows of one byte
    matrix (``wire.repeated_rows``) pay numpy's fixed cost, which a plain loop does not for one
    agent; the loop pays per agent, which the matrix does not for many (docs/performance.md, "The
    byte codec", has the numbers). So the matrix from ``wire.MIN_MATRIX_ROWS`` agents on, as long
    as every discrete action is one varint byte.
    """
    n, b = len(discrete), discrete.shape[1]
    if n >= wire.MIN_MATRIX_ROWS and (b == 0 or (discrete.min() >= 0 and discrete.max() < 0x80)):
        return _agent_actions_matrix(continuous, discrete)
    return _agent_actions_loop(continuous, discrete)


def _agent_actions_matrix(continuous: np.ndarray, discrete: np.ndarray) -> bytes:
    n, c = continuous.shape
    b = discrete.shape[1]
    parts: list = []
    if c + b:
        deprecated = np.concatenate([continuous, discrete.astype(np.float32)], axis=1)
        parts += [wire.len_prefix(1, 4 * (c + b)), wire.float_columns(deprecated, n)]
    if c:
        parts += [wire.len_prefix(6, 4 * c), wire.float_columns(continuous, n)]
    if b:
        parts += [wire.len_prefix(7, b), discrete.astype(np.uint8)]
    return wire.repeated_rows(1, parts, n)


def _agent_actions_loop(continuous: np.ndarray, discrete: np.ndarray) -> bytes:
    n, c = continuous.shape
    b = discrete.shape[1]
    floats = continuous.astype("<f4").tobytes()
    as_floats = discrete.astype("<f4").tobytes()
    deprecated = wire.len_prefix(1, 4 * (c + b)) if c + b else b""
    continuous_prefix = wire.len_prefix(6, 4 * c) if c else b""
    out = []
    for row, actions in enumerate(discrete.tolist()):
        own = floats[4 * c * row:4 * c * (row + 1)]
        parts = [deprecated, own, as_floats[4 * b * row:4 * b * (row + 1)]] if c + b else []
        if c:
            parts += [continuous_prefix, own]
        if b:
            varints = b"".join(map(wire.varint, actions))
            parts += [wire.len_prefix(7, len(varints)), varints]
        out.append(wire.field(1, b"".join(parts)))
    return b"".join(out)


def as_action_matrices(action: ActionTuple) -> tuple[np.ndarray, np.ndarray]:
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
