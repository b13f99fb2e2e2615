"""Runs INSIDE .venv-interop: the real mlagents_envs 1.1.0 UnityEnvironment (Editor mode) meets a
stub started with argv[1]'s "stub" command; prints one JSON line with the BehaviorSpecs it read
and what one step of each behavior looked like (tests/interop/test_mirror_interop.py)."""
import json
import subprocess
import sys

import numpy as np
from mlagents_envs.environment import UnityEnvironment

options = json.loads(sys.argv[1])
port = options["port"]
stub = subprocess.Popen(options["stub"] + ["--mlagents-port", str(port)], cwd=options["cwd"])
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=60)
try:
    env.reset()
except BaseException:
    stub.kill()
    env.close()
    raise
out = {"specs": {}, "steps": {}}
for name, spec in sorted(env.behavior_specs.items()):
    out["specs"][name] = {
        "observations": [{"shape": list(o.shape), "dimension_property": [int(p.value) for p in o.dimension_property],
                          "observation_type": int(o.observation_type.value), "name": o.name}
                         for o in spec.observation_specs],
        "continuous": spec.action_spec.continuous_size,
        "discrete_branches": list(spec.action_spec.discrete_branches),
    }
for _ in range(2):
    for name, spec in env.behavior_specs.items():
        decision, _ = env.get_steps(name)
        env.set_actions(name, spec.action_spec.random_action(len(decision)))
    env.step()
for name in sorted(env.behavior_specs):
    decision, _ = env.get_steps(name)
    out["steps"][name] = {"agents": len(decision), "group_ids": sorted({int(g) for g in decision.group_id}),
                          "obs_range": [[float(o.min()), float(o.max())] for o in decision.obs]}
env.close()
out["stub_exit"] = stub.wait(timeout=30)
print(json.dumps(out))
