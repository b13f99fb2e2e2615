"""Times ``UnityEnvironment`` stepping an executable with random actions, the way a user's Python
loop would: get_steps, random_action for the deciding agents, set_actions, step.

Runs under the package named by ``"package"``: the real ``mlagents_envs`` 1.1.0 (the default; in
.venv-interop, with no project code on its path) or ``mlagents_like_envs`` (the project's venv),
imported by the same module path, so both are timed with the very same loop.

Usage: python mlagents_envs_rollout.py '{"file_name": ..., "base_port": ..., "num_areas": 16,
        "warmup": 200, "exchanges": 2000, "package": "mlagents_envs"}'
Prints one JSON line: {"exchanges", "seconds", "agent_steps"}.
"""
import importlib
import json
import sys
import time


def main():
    options = json.loads(sys.argv[1])
    UnityEnvironment = importlib.import_module(options.get("package", "mlagents_envs") + ".environment").UnityEnvironment
    env = UnityEnvironment(file_name=options["file_name"], base_port=options["base_port"],
                           no_graphics=True, seed=1, timeout_wait=60,
                           num_areas=options.get("num_areas", 1))
    try:
        env.reset()
        names = list(env.behavior_specs.keys())

        def one_exchange():
            deciding = 0
            for name in names:
                decision, _ = env.get_steps(name)
                deciding += len(decision)
                if len(decision) > 0:
                    env.set_actions(name, env.behavior_specs[name].action_spec.random_action(len(decision)))
            env.step()
            return deciding

        for _ in range(options["warmup"]):
            one_exchange()
        agent_steps = 0
        started = time.perf_counter()
        for _ in range(options["exchanges"]):
            agent_steps += one_exchange()
        seconds = time.perf_counter() - started
    finally:
        env.close()
    print(json.dumps({"exchanges": options["exchanges"], "seconds": seconds, "agent_steps": agent_steps}))


if __name__ == "__main__":
    main()
