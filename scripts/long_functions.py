"""Count the production functions longer than a limit (default 80 lines): the size report of
issue reviews, before and after a change.

    python scripts/long_functions.py [--repo DIR] [--limit 80] [--list]

A function's length is its ``def`` line through its last line (docstring, comments and blank
lines inside it included; decorators not), read with ``ast`` (``end_lineno``); nested functions
and methods count on their own as well as inside their parent. Production code: every ``.py``
under protos/, trainer/, unity_stub_env/ and mlagents_like_envs/ except protobuf's generated
modules (``communicator_objects/``); tests, bench/ and scripts/ are not counted.
"""
from __future__ import annotations

import argparse
import ast
from pathlib import Path

PACKAGES = ("protos", "trainer", "unity_stub_env", "mlagents_like_envs")


def long_functions(repo: Path, limit: int) -> list[tuple[int, str, int, str]]:
    """(length, file, line, name) of every production function longer than ``limit`` lines, longest first."""
    found = []
    for package in PACKAGES:
        for path in sorted((repo / package).rglob("*.py")):
            if "communicator_objects" in path.parts:
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    length = node.end_lineno - node.lineno + 1
                    if length > limit:
                        found.append((length, str(path.relative_to(repo)), node.lineno, node.name))
    return sorted(found, key=lambda row: (-row[0], row[1], row[2]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1], help="the tree to count")
    parser.add_argument("--limit", type=int, default=80, help="count functions longer than this many lines")
    parser.add_argument("--list", action="store_true", help="print each function too")
    args = parser.parse_args()
    rows = long_functions(args.repo, args.limit)
    if args.list:
        for length, path, line, name in rows:
            print(f"{length:5d}  {path}:{line}  {name}")
    print(f"{len(rows)} production functions over {args.limit} lines in {args.repo}")


if __name__ == "__main__":
    main()
