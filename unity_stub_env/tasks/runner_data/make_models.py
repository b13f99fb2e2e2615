"""Write the runner's corpora and train its six HMMs (the files beside this script).

    python -m unity_stub_env.tasks.runner_data.make_models          # rewrites *.txt and *.json

The corpora are written from hand-made phrases, one list per zone (below): a line of a corpus
is a random chain of that zone's phrases (seeded, so the files are reproducible). Each model is
then trained exactly as ``unity-stub-env hmm train CORPUS -o MODEL --states N --restarts 5
--method fast --seed 0`` would, and tests/stub/test_stub_runner.py checks that the shipped models
are what this script produces.

Platform corpora (labels Left, Right, Straight; 5 states each, as in the runner
thesis, docs/stub-tasks.md, "Seed projects"):
  urban  - city blocks: a few straights, then one right-angle turn; never two turns in a row.
  rural  - a winding road: S-bends (a turn one way, maybe a straight, the other way back).
  desert - long straights with a rare single turn.
Prop corpora: three labels per platform, its spawn points filled left to right (clockwise seen
from above, starting at the left edge); ``-`` is the epsilon label, an empty spawn point.
Obstacles (the zone's scenery) cost the agent when it drives into them; ``coin`` rewards it.
The phrases never block all three lanes of a platform. The largest prop model has 8 states.
"""
from __future__ import annotations

import os

import numpy as np

from unity_stub_env.hmm import parse_corpus, train

HERE = os.path.dirname(os.path.abspath(__file__))
ZONES = ("urban", "rural", "desert")

PLATFORM_PHRASES = {
    "urban": ["Straight Straight Left", "Straight Straight Right", "Straight Straight Straight Left",
              "Straight Straight Straight Right", "Straight Straight"],
    "rural": ["Left Right", "Right Left", "Left Straight Right", "Right Straight Left", "Left Left Right Right",
              "Straight"],
    "desert": ["Straight Straight Straight Straight", "Straight Straight Straight", "Straight Left Straight",
               "Straight Right Straight"],
}
# one phrase = the spawn points of one or two platforms (3 labels each)
PROP_PHRASES = {
    "urban": ["- - -", "- - -", "car - -", "- - car", "- hydrant -", "coin - -", "- coin -", "- - coin",
              "car - - - coin -", "- - hydrant coin - -"],
    "rural": ["- - -", "- - -", "- - -", "hay - -", "- - fence", "- hay -", "- coin -", "coin coin -",
              "fence - - - - hay"],
    "desert": ["- - -", "- - -", "- - -", "- - -", "cactus - -", "- - rock", "- cactus -", "- - coin",
               "rock - coin", "- coin -"],
}
PLATFORM_STATES = 5
PROP_STATES = 8
LINES, PHRASES_PER_LINE = 60, 12


def corpus_text(phrases: list[str], rng: np.random.Generator) -> str:
    lines = [" ".join(phrases[k] for k in rng.integers(0, len(phrases), PHRASES_PER_LINE)) for _ in range(LINES)]
    return "".join(line + "\n" for line in lines)


def build(folder: str = HERE) -> None:
    rng = np.random.default_rng(2024)
    for kind, phrases, states in (("platforms", PLATFORM_PHRASES, PLATFORM_STATES),
                                  ("props", PROP_PHRASES, PROP_STATES)):
        for zone in ZONES:
            text = corpus_text(phrases[zone], rng)
            name = f"{zone}_{kind}"
            with open(os.path.join(folder, name + ".txt"), "w", encoding="utf-8") as out:
                out.write(f"# {name}: written by make_models.py from hand-made phrases (see its docstring)\n")
                out.write(text)
            model = train(parse_corpus(text, name), num_states=states, restarts=5, method="fast", seed=0)
            model.save(os.path.join(folder, name + ".json"))
            print(f"{name}: {len(text.split())} labels, log-likelihood {model.training['log_likelihood']:.1f}")


if __name__ == "__main__":
    build()
