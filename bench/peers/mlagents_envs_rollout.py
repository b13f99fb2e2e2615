"""Runs INSIDE .venv-interop (the real mlagents_envs 1.1.0); never imports project code.

Times ``UnityEnvironment`` stepping an executable with random actions, the way a user's Python
loop would: get_steps, random_action for the deciding agents, set_actions, step.

Usage: python mlagents_envs_rollout.py '{"file_name": ..., "base_port": ..., "num_areas": 16,
        "warmup": 200, "exchanges": 2000}'
Prints one JSON line: {"exchanges", "seconds", "agent_steps"}.
"""
import json
import sys
import time

from mlagents_envs.environment import UnityEnvironment


def main():
    options = json.loads(sys.argv[1])
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
