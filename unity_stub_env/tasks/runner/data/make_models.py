"""Write the runner's corpora and train its six HMMs (the files beside this script).

    python -m unity_stub_env.tasks.runner.data.make_models          # rewrites *.txt and *.json

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
Prop corpora: the labels of one platform's spawn points, filled left to right (clockwise seen
from above, starting at the left edge), a stackable spawn point taking as many labels as it holds
objects at most, bottom first (``runner.SPAWN_STACKS``: urban 1, 2, 1; rural 2, 1, 2; desert 1, 1, 3
labels, so 4, 5 and 5 labels per platform); ``-`` is the epsilon label, an empty place. Obstacles
(the zone's scenery) cost the agent when it drives into them; ``coin`` rewards it. The phrases
never block all three lanes of a platform. Sizes as the seed's generators: its largest has 20
states and 10 labels (urban props here: 10 labels, 20 states); rural 8 labels, 16 states; desert
7 labels, 14 states; the platform models 5 states over 3 labels.
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
# one phrase = the labels of one or two platforms (urban 4, rural 5, desert 5 labels each: left,
# centre, right, a stackable spawn point's places bottom first); a stack ends at its first '-'
PROP_PHRASES = {
    "urban": ["- - - -", "- - - -", "car - - -", "- - - car", "- hydrant - -", "- crate crate -",
              "coin - - -", "- coin coin -", "- - - coin", "- bench - -", "bin - - -", "- - - lamp",
              "- cone cone -", "- - - mailbox", "car - - - - coin - -", "- - - hydrant coin - - -", "- crate - - bin - - -"],
    "rural": ["- - - - -", "- - - - -", "hay hay - - -", "- - - fence -", "- - tractor - -",
              "coin - - - -", "- - coin - -", "- - - coin coin", "barrel - - - -", "- - - hay hay", "- - log - -", "sheep - - - -",
              "fence - - - - - - - hay -"],
    "desert": ["- - - - -", "- - - - -", "- - - - -", "cactus - - - -", "- - rock rock -", "- skull - - -",
               "- - - - -", "- - coin - -", "rock - coin - -", "- coin - - -", "- - bones - -",
               "- tumbleweed - - -", "- - rock rock rock"],
}
PLATFORM_STATES = 5
PROP_STATES = {"urban": 20, "rural": 16, "desert": 14}
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
            count = states[zone] if isinstance(states, dict) else states
            model = train(parse_corpus(text, name), num_states=count, restarts=5, method="fast", seed=0)
            model.save(os.path.join(folder, name + ".json"))
            print(f"{name}: {len(text.split())} labels, log-likelihood {model.training['log_likelihood']:.1f}")


if __name__ == "__main__":
    build()
