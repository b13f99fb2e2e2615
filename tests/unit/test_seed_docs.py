"""The counts README.md and docs/ state about the seed tasks are the ones bench/seed_counts.py
generates from the code (task specs, the dodge evaluation's throws, the runner's HMM files, the
mimic model, the dodge thesis' 0.x file), and the throws said to come from the dodge thesis are
the ones its text describes (docs/stub-tasks.md, "Seed projects")."""
from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _seed_counts():
    spec = importlib.util.spec_from_file_location("seed_counts", REPO / "bench" / "seed_counts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_generated_count_is_what_the_docs_say():
    module = _seed_counts()
    pairs = module.claims()
    assert len(pairs) >= 15
    assert module.missing(pairs) == []


def test_a_changed_count_is_caught():
    module = _seed_counts()
    path, phrase = next(pair for pair in module.claims() if pair[0] == "docs/configuration.md")
    assert module.missing([(path, phrase.replace("28,000", "28,001"))]) == [(path, phrase.replace("28,000", "28,001"))]


def test_the_throws_from_the_dodge_thesis_are_its_throws_1_and_17():
    from unity_stub_env.tasks.dodge import SCRIPTED_THROWS
    from unity_stub_env.tasks.dodge.evaluation import FROM_THE_SEED

    # its text: throw 1 from the front at the left shoulder, throw 17 from the left at the
    # lower-middle torso; the other 15 are reconstructed
    assert [SCRIPTED_THROWS[i] for i in FROM_THE_SEED] == [("front", "left shoulder"), ("left", "lower torso")]
    assert FROM_THE_SEED == (0, len(SCRIPTED_THROWS) - 1) and len(SCRIPTED_THROWS) == 17
