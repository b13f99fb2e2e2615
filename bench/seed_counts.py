"""The counts that README.md and docs/ state about the seed tasks (dodge, mimic, creature, runner),
generated from the code and the shipped files instead of typed:

    .venv/bin/python bench/seed_counts.py           # every count, with the sentence it appears in
    .venv/bin/python bench/seed_counts.py --check   # exit 1 if a doc no longer says what the code gives

Each claim is a file and a phrase of it whose numbers come from here (task specs, the dodge
evaluation's throws, the runner's HMM files, the mimic model, the generated creatures, the dodge
thesis' 0.x file). tests/unit/test_seed_docs.py runs the check. When a number changes, the check
names the file and the phrase to rewrite; bench/creature_counts.py gives every creature's counts.
Whitespace (line breaks) in the docs does not matter.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]


def _thousands(n: int) -> str:
    return f"{n:,}"


def claims() -> list[tuple[str, str]]:
    """(path relative to the repository, phrase) for every generated count."""
    from unity_stub_env.creatures import generate
    from unity_stub_env.tasks import make_task
    from unity_stub_env.tasks.creature import observation_size
    from unity_stub_env.tasks.dodge import SCRIPTED_THROWS
    from unity_stub_env.tasks.dodge.evaluation import FROM_THE_SEED

    out: list[tuple[str, str]] = []
    tasks = {name: make_task(name, seed=0) for name in ("dodge", "mimic", "creature", "runner")}

    def spec(name):
        task = tasks[name]
        (obs,) = [s.shape[0] for s in task.observation_specs]
        return task, obs, task.action_spec.continuous_size

    # README's task table, the seed tasks' rows.
    for name, behavior in (("dodge", "Dodge"), ("mimic", "Mimic"), ("runner", "Runner")):
        task, obs, act = spec(name)
        out.append(("README.md", f"| `{name}` | `{behavior}` | {task.agents_per_area} | vector {obs} "
                                 f"(`VectorSensor_size{obs}`) | {act} continuous"))
    dodge, _, _ = spec("dodge")
    out.append(("README.md", f"max {dodge.max_step} steps |"))
    mimic, _, _ = spec("mimic")
    out.append(("README.md", f"{mimic.decision_hz:g} decisions/s (`decision_hz` 250: the mimic thesis' rate), "
                             f"{mimic.max_step / mimic.decision_hz:g} s episodes"))
    creature, obs, act = spec("creature")
    skeleton = generate("quadruped", 0)
    assert obs == observation_size(skeleton) == 14 + 10 * len(skeleton.bones) + skeleton.num_hinges()
    out.append(("README.md", f"| `creature` | `Creature` | {creature.agents_per_area} | vector 14 + 10 × bones + "
                             f"hinges ({obs} for the default quadruped) | one continuous per hinge ({act})"))
    runner, _, _ = spec("runner")
    out.append(("README.md", f"max {runner.max_step} steps |"))

    # The dodge thesis' budget in both units (its 0.x file: environment steps of all its agents).
    legacy = yaml.safe_load((REPO / "configs" / "dodge_legacy.yaml").read_text())
    seed_env_steps = int(float(legacy["Dodge"]["max_steps"]))
    agents = dodge.agents_per_area
    modern = yaml.safe_load((REPO / "configs" / "dodge.yaml").read_text())
    our_agent_steps = int(modern["behaviors"]["Dodge"]["max_steps"])
    out += [
        ("docs/configuration.md", f"`max_steps: 2000` on `stub:dodge` ({agents} agents) trains "
                                  f"{_thousands(2000 * agents)} agent steps"),
        ("docs/configuration.md", f"seed 000's `max_steps: {seed_env_steps / 1e6:g}e6` on {agents} agents was "
                                  f"{_thousands(seed_env_steps * agents)} agent decisions"),
        ("docs/performance.md", f"A {our_agent_steps // 10**6} M agent-step dodge run "
                                f"({round(our_agent_steps / agents / 1000)}k environment steps × {agents} agents)"),
        ("docs/performance.md", f"That is 1/{seed_env_steps * agents // our_agent_steps} of the dodge thesis' "
                                "experience"),
        ("docs/performance.md", f"≈ {seed_env_steps * agents // 10**6} M agent decisions"),
    ]

    # The dodge evaluation's scripted throws: how many the seed's text fixes, how many are ours.
    n, fixed = len(SCRIPTED_THROWS), len(FROM_THE_SEED)
    out += [
        ("docs/stub-tasks.md", f"runs the {n} scripted throws"),
        ("docs/stub-tasks.md", f"the seed's text fixes throws {' and '.join(str(i + 1) for i in FROM_THE_SEED)}, "
                               f"the other {n - fixed} are our reconstruction"),
        ("docs/performance.md", f"of the {n} scripted throws ({fixed} as the dodge thesis' text gives them, "
                                f"{n - fixed} reconstructed"),
    ]

    # The evaluations' defaults and the creature's arena.
    from unity_stub_env.evaluate import _evaluations as evaluations
    from unity_stub_env.tasks.creature.task import ARENA_HALF, MAX_OBSTACLES
    from unity_stub_env.tasks.mimic.evaluation import EVAL_SECONDS
    out += [
        ("docs/stub-tasks.md", f"and {evaluations()['dodge'][2]} seeded random throws"),
        ("docs/stub-tasks.md", f"plays every motion for {EVAL_SECONDS:g} s"),
        ("docs/stub-tasks.md", f"each area is a {2 * ARENA_HALF:g} m arena"),
        ("docs/stub-tasks.md", f"`obstacles` 0..{MAX_OBSTACLES}"),
    ]

    # mimic's ragdoll.
    masses = mimic.model.body_mass.sum() / mimic.agents_per_area
    out.append(("docs/stub-tasks.md", f"a {masses:.0f} kg ragdoll with human mass fractions whose "
                                      f"{mimic.action_spec.continuous_size} joint axes"))

    # The runner's HMM generators: states × labels of the shipped models.
    sizes = {}
    for path in sorted((REPO / "unity_stub_env" / "tasks" / "runner" / "data").glob("*.json")):
        model = json.loads(path.read_text())
        sizes[path.stem] = (len(model["transition"]), len(model["labels"]))
    platforms = {sizes[f"{zone}_platforms"][0] for zone in ("urban", "rural", "desert")}
    assert len(platforms) == 1
    largest = max((sizes[f"{zone}_props"], zone) for zone in ("urban", "rural", "desert"))
    (states, labels), zone = largest
    from unity_stub_env.tasks.runner.task import LANES
    out.append(("docs/hmm.md", f"three prop corpora ({len(LANES)} spawn points per platform"))
    out += [
        ("docs/stub-tasks.md", f"{platforms.pop()}-state platform models"),
        ("docs/stub-tasks.md", f"its largest, {states} states × {labels} labels, is {zone}'s here"),
        ("docs/hmm.md", f"its largest generator has {states} states and {labels} labels, as {zone}'s here "
                        f"(rural {sizes['rural_props'][0]} states × {sizes['rural_props'][1]} labels, "
                        f"desert {sizes['desert_props'][0]} × {sizes['desert_props'][1]})"),
    ]
    return out


def _flat(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def missing(pairs: list[tuple[str, str]]) -> list[tuple[str, str]]:
    texts: dict[str, str] = {}
    for path, _ in pairs:
        texts.setdefault(path, _flat((REPO / path).read_text(encoding="utf-8")))
    return [(path, phrase) for path, phrase in pairs if _flat(phrase) not in texts[path]]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a doc does not contain a generated phrase")
    args = parser.parse_args()
    pairs = claims()
    absent = missing(pairs)
    for path, phrase in pairs:
        print(f"{'MISSING ' if (path, phrase) in absent else ''}{path}: {phrase}")
    if args.check and absent:
        print(f"{len(absent)} phrase(s) not found: rewrite them from the lines above", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
