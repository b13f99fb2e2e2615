"""README.md is the users' page: at most 200 lines, and the first thing it shows is ./run.sh and ./test.sh.
Designs go to docs/, dated measurements to bench/RESULTS.md."""
from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"
MAX_LINES = 200


def test_the_readme_has_at_most_200_lines():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_LINES, f"README.md has {len(lines)} lines; move detail to docs/ (at most {MAX_LINES})"


def test_the_readme_opens_with_run_sh_and_test_sh():
    text = README.read_text(encoding="utf-8")
    first_block = re.search(r"```bash\n(.*?)```", text, re.S)
    assert first_block and text.index("```bash") < text.index("\n## ")
    commands = [line.split("#")[0].strip() for line in first_block.group(1).splitlines()]
    assert [c for c in commands if c][:2] == ["./run.sh", "./test.sh"]


def test_the_readmes_links_to_docs_exist():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(((?:docs|bench)/[^)#\s]+)", text):
        assert (README.parent / target).exists(), target


def test_the_stub_task_table_gives_each_tasks_agents_and_sizes():
    """README's table of stub tasks against the tasks' specs (what `unity-stub-env --list` prints): every
    task has a row, and its agents per area, observation sizes and action sizes are the specs' numbers
    (bench/seed_counts.py checks the seed tasks' rows phrase by phrase)."""
    from unity_stub_env.tasks import TASKS, make_task

    text = README.read_text(encoding="utf-8")
    rows = {m.group(1): [c.strip() for c in m.group(0).strip().strip("|").split("|")]
            for m in re.finditer(r"^\| `(\w+)` \|.*\|$", text, re.M)}
    for name in TASKS:
        if name == "mirror":
            continue
        assert name in rows, f"README's stub-task table has no row for {name}"
        _, _, agents, observations, actions, _ = rows[name]
        task = make_task(name, seed=0)
        numbers = lambda cell: [int(n) for n in re.findall(r"\d+", cell)]  # noqa: E731
        assert numbers(agents)[0] == task.agents_per_area, (name, agents)
        stated = {int(n) for n in re.findall(r"(?:vector |_size|\()(\d+)\b(?! \+)", observations)}
        assert stated == {spec.shape[-1] for spec in task.observation_specs}, (name, observations)
        spec = task.action_spec
        expected = ([spec.continuous_size] if spec.continuous_size else []) + list(spec.discrete_branches)
        assert set(expected) <= set(numbers(actions)) | ({1} if "one" in actions else set()), (name, actions)
