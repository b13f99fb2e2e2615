"""``python -m unity_stub_env.gym``: the markdown table of the registered ids that
docs/python-api.md shows (tests/stub/test_stub_gym.py keeps the two equal)."""
from __future__ import annotations

from unity_stub_env.gym import ENV_IDS
from unity_stub_env.gym.spaces import action_space, observation_space
from unity_stub_env.tasks import make_task


def ids_table() -> str:
    lines = ["| id | task | agents per area | single-agent `make` | observation | action | decision period |",
             "|---|---|---|---|---|---|---|"]
    for task_name, env_id in ENV_IDS.items():
        task = make_task(task_name, seed=0)
        obs, act = observation_space(task.observation_specs), action_space(task.action_spec)
        single = "no (agents play together)" if task.agents_interact else "yes"
        lines.append(f"| `{env_id}` | {task_name} | {task.agents_per_area} | {single} | `{obs}` | `{act}` | "
                     f"{task.decision_period} |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(ids_table())
