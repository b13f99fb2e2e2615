"""Procedural creatures (the creature report: docs/stub-tasks.md, "Seed projects"): parametric bipeds
and quadrupeds, stochastic L-system creatures, and their MuJoCo models. Usable without the stub's protocol::

    from unity_stub_env.creatures import generate, to_mjcf
    xml = to_mjcf(generate("quadruped", seed=7))

or ``unity-stub-env creature --kind quadruped --seed 7 --mjcf out.xml``.
"""
from __future__ import annotations

from unity_stub_env.creatures.lsystem import lsystem
from unity_stub_env.creatures.mjcf import to_mjcf
from unity_stub_env.creatures.parametric import biped, quadruped
from unity_stub_env.creatures.skeleton import LIMITS, Bone, Skeleton

KINDS = {"quadruped": quadruped, "biped": biped, "lsystem": lsystem}


def generate(kind: str, seed: int) -> Skeleton:
    """The creature of ``kind`` (quadruped, biped, lsystem) for ``seed``."""
    if kind not in KINDS:
        raise ValueError(f"unknown creature kind {kind!r}; choose one of {', '.join(KINDS)}")
    return KINDS[kind](int(seed))


def main(argv: list[str]) -> int:
    """``unity-stub-env creature --kind K --seed S [--mjcf FILE]``: write (or print) the MJCF."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="unity-stub-env creature",
                                     description="Write the MuJoCo model of a generated creature.")
    parser.add_argument("--kind", choices=tuple(KINDS), default="quadruped")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mjcf", default="-", metavar="FILE", help="output file ('-' = stdout, default)")
    args = parser.parse_args(argv)
    xml = to_mjcf(generate(args.kind, args.seed))
    if args.mjcf == "-":
        sys.stdout.write(xml)
        return 0
    try:
        with open(args.mjcf, "w") as out:
            out.write(xml)
    except OSError as error:
        print(f"unity-stub-env creature: cannot write --mjcf {args.mjcf}: {error.strerror}; "
              "choose a writable path.", file=sys.stderr)
        return 2
    return 0


__all__ = ["KINDS", "LIMITS", "Bone", "Skeleton", "generate", "to_mjcf", "biped", "quadruped", "lsystem", "main"]
