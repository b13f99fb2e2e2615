"""The bones, hinges and observation sizes of generated creatures, for the counts written in
bench/RESULTS.md and docs (generated here, not typed):

    .venv/bin/python bench/creature_counts.py [--seeds 0 7]

Prints one markdown row per kind and seed: bones, hinge axes (= continuous actions) and the
``creature`` task's observation size (14 + 10 per bone + 1 per hinge).
"""
from __future__ import annotations

import argparse

from unity_stub_env.creatures import KINDS, generate
from unity_stub_env.tasks.creature import observation_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 7])
    args = parser.parse_args()
    print("| kind | creature_seed | bones | hinges (actions) | observations |")
    print("|---|---:|---:|---:|---:|")
    for kind in KINDS:
        for seed in args.seeds:
            skeleton = generate(kind, seed)
            print(f"| {kind} | {seed} | {len(skeleton.bones)} | {skeleton.num_hinges()} | {observation_size(skeleton)} |")


if __name__ == "__main__":
    main()
