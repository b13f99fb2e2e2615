"""docs/architecture.md's package map against the code: every module of protos/, trainer/, unity_stub_env/
and mlagents_like_envs/ is in one row, and each row's imports column names exactly the other rows its
modules import (an AST scan of every import, lazy ones inside functions included, as in
test_package_boundaries.py)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "architecture.md"
PACKAGES = ("protos", "trainer", "unity_stub_env", "mlagents_like_envs")
#: imported almost everywhere, so the map leaves it out of the imports column (the page says so)
UNLISTED = ("trainer/errors.py",)


def package_map() -> list[tuple[tuple[str, ...], set[str]]]:
    """(the row's paths, the paths its imports column names) for each row of the package map."""
    text = DOC.read_text(encoding="utf-8")
    start = text.index("| package / module |")
    rows = []
    for line in text[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        paths = tuple(p for p in re.findall(r"`([^`]+)`", cells[0]) if p.split("/")[0] in PACKAGES)
        named = {p for p in re.findall(r"`([^`]+)`", cells[-1]) if p.split("/")[0] in PACKAGES}
        rows.append((paths, named))
    return rows


def modules() -> list[str]:
    """Every module file, as a path relative to the repository."""
    return sorted(str(path.relative_to(REPO)) for package in PACKAGES for path in (REPO / package).rglob("*.py")
                  if "communicator_objects" not in path.parts)


def row_of(path: str, rows) -> int | None:
    """The row whose path holds ``path`` (a file or a folder ending in /), the longest match."""
    best, length = None, -1
    for index, (paths, _) in enumerate(rows):
        for candidate in paths:
            covers = path == candidate or (candidate.endswith("/") and path.startswith(candidate))
            if covers and len(candidate) > length:
                best, length = index, len(candidate)
    return best


def module_path(name: str) -> str | None:
    """trainer.config.settings -> trainer/config/settings.py (or the package's __init__.py)."""
    parts = name.split(".")
    while parts:
        base = REPO.joinpath(*parts)
        for candidate in (base.with_suffix(".py"), base / "__init__.py"):
            if candidate.exists():
                return str(candidate.relative_to(REPO))
        parts = parts[:-1]
    return None


def imported_paths(path: str) -> set[str]:
    tree = ast.parse((REPO / path).read_text(encoding="utf-8"), filename=path)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            # ``from package import module`` imports that module; ``from module import name``, the module
            names = [f"{node.module}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            if name.split(".")[0] in PACKAGES:
                target = module_path(name)
                if target is not None:
                    found.add(target)
    return found


def test_every_module_is_in_one_row():
    rows = package_map()
    assert rows, "no package map in docs/architecture.md"
    missing = [path for path in modules() if row_of(path, rows) is None]
    assert missing == []


def test_every_path_named_exists():
    for paths, named in package_map():
        for path in (*paths, *named):
            assert (REPO / path).exists(), path


ROWS = package_map()


@pytest.mark.parametrize("index", range(len(ROWS)), ids=[", ".join(paths) for paths, _ in ROWS])
def test_a_rows_imports_column_is_what_its_modules_import(index):
    rows = ROWS
    unlisted = {row_of(path, rows) for path in UNLISTED}
    imported = set()
    for path in modules():
        if row_of(path, rows) != index:
            continue
        for target in imported_paths(path):
            row = row_of(target, rows)
            if row is not None and row != index and row not in unlisted:
                imported.add(row)
    unknown = sorted(path for path in rows[index][1] if row_of(path, rows) is None)
    assert unknown == [], f"the imports column names paths that are in no row: {unknown}"
    named = {row_of(path, rows) for path in rows[index][1]}
    name = lambda rs: sorted(", ".join(rows[r][0]) for r in rs)  # noqa: E731
    assert name(named) == name(imported), f"listed but not imported: {name(named - imported)}; " \
                                          f"imported but not listed: {name(imported - named)}"
