"""Runs INSIDE .venv-interop: the real ML-Agents 1.1.0 demonstration code on .demo files.

argv[1] is JSON: {"mode": "write", "path": P, "records": [...], "continuous": c, "branches": [...]}
writes P with mlagents.trainers.demo_loader.write_demo (metadata, brain parameters, one
AgentInfoActionPairProto per record: {"obs": [...], "reward": r, "done": d, "max_step": m,
"continuous": [...], "discrete": [...]}); {"mode": "read", "path": P} loads P (a file or a
folder) with demo_to_buffer and prints the spec and the buffer's columns as one JSON line."""
import json
import sys

import numpy as np
from mlagents.trainers.buffer import BufferKey
from mlagents.trainers.demo_loader import demo_to_buffer, write_demo
from mlagents.trainers.trajectory import ObsUtil
from mlagents_envs.communicator_objects.agent_action_pb2 import AgentActionProto
from mlagents_envs.communicator_objects.agent_info_action_pair_pb2 import AgentInfoActionPairProto
from mlagents_envs.communicator_objects.agent_info_pb2 import AgentInfoProto
from mlagents_envs.communicator_objects.brain_parameters_pb2 import ActionSpecProto, BrainParametersProto
from mlagents_envs.communicator_objects.demonstration_meta_pb2 import DemonstrationMetaProto
from mlagents_envs.communicator_objects.observation_pb2 import ObservationProto

options = json.loads(sys.argv[1])
if options["mode"] == "write":
    records = options["records"]
    pairs = []
    for r in records:
        obs = ObservationProto(shape=[len(r["obs"])], dimension_properties=[1])
        obs.float_data.data.extend(r["obs"])
        info = AgentInfoProto(reward=r["reward"], done=r["done"], max_step_reached=r["max_step"], id=7,
                              observations=[obs])
        action = AgentActionProto(continuous_actions=r["continuous"], discrete_actions=r["discrete"])
        pairs.append(AgentInfoActionPairProto(agent_info=info, action_info=action))
    meta = DemonstrationMetaProto(api_version=1, demonstration_name="ref", number_steps=len(records),
                                  number_episodes=sum(r["done"] for r in records), mean_reward=1.0)
    spec = ActionSpecProto(num_continuous_actions=options["continuous"], num_discrete_actions=len(options["branches"]),
                           discrete_branch_sizes=options["branches"])
    brain = BrainParametersProto(brain_name="Ref?team=0", is_training=False, action_spec=spec)
    write_demo(options["path"], meta, brain, pairs)
    print(json.dumps({"written": len(pairs)}))
else:
    spec, buffer = demo_to_buffer(options["path"], 1)
    out = {
        "observation_shapes": [list(o.shape) for o in spec.observation_specs],
        "continuous": spec.action_spec.continuous_size,
        "branches": list(spec.action_spec.discrete_branches),
        "obs": [np.asarray(buffer[ObsUtil.get_name_at(i)], np.float32).tolist()
                for i in range(len(spec.observation_specs))],
        "rewards": np.asarray(buffer[BufferKey.ENVIRONMENT_REWARDS], np.float32).tolist(),
        "done": np.asarray(buffer[BufferKey.DONE], bool).tolist(),
    }
    if spec.action_spec.continuous_size:
        out["continuous_actions"] = np.asarray(buffer[BufferKey.CONTINUOUS_ACTION], np.float32).tolist()
    if spec.action_spec.discrete_size:
        out["discrete_actions"] = np.asarray(buffer[BufferKey.DISCRETE_ACTION], np.int64).tolist()
    print(json.dumps(out))
