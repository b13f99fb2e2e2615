"""The three packages' import rules, read from the source (an AST scan of every import):

* ``protos`` (the wire contract) imports neither ``trainer`` nor ``unity_stub_env``;
* ``unity_stub_env`` imports ``protos``, itself and third-party libraries, never ``trainer``;
  the Gymnasium and PettingZoo forms (the ``gym`` extra) are imported only in ``unity_stub_env/gym/``
  (and ``mlagents_like_envs/envs/``), so the stub and the API run without them;
* ``trainer`` uses only the stub's public API: names in ``unity_stub_env.__all__``, imported from
  the package itself (``from unity_stub_env import TASK_NAMES``), never a stub module;
* ``mlagents_like_envs`` (the mlagents_envs-compatible API) drives environments through the
  trainer's launcher, server and codec, so it may import the few ``trainer`` modules in
  ``ENVS_API_USES`` and the stub's public API, nothing else of either; ``protos`` and ``trainer``
  never import it, and the stub only its light modules (``ENVS_API_LIGHT``: the data types and
  exceptions, which themselves import nothing of the project but ``protos``).

Inside ``trainer``, the shared pieces (``trainer/common/``) import no algorithm package
(``trainer.ppo``, ``trainer.sac``, ``trainer.poca``), and PPO and SAC import neither each other nor
POCA (POCA builds on PPO's trainer and may import it).

So a bug in a shared encoder cannot hide behind one side's private copy, and either package can
change its internals without breaking the other.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from protos import wire
from protos.communicator_objects import header_pb2
import unity_stub_env

REPO = Path(__file__).resolve().parents[2]


def imports(package: str) -> list[tuple[str, int, str, tuple[str, ...]]]:
    """(file, line, imported module, imported names) for every import under ``package``,
    including imports inside functions."""
    found = []
    for path in sorted((REPO / package).rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        where = str(path.relative_to(REPO))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                found += [(where, node.lineno, alias.name, ()) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative import: stays inside its own package
                    continue
                found.append((where, node.lineno, node.module or "", tuple(a.name for a in node.names)))
    return found


def top(module: str) -> str:
    return module.split(".")[0]


def test_the_scan_sees_imports_inside_functions_and_from_imports(tmp_path, monkeypatch):
    """The scanner itself: a lazy import in a function body and a ``from`` import both count."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "m.py").write_text("import os\ndef f():\n    from trainer.errors import ConfigError\n")
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert [(line, module, names) for _, line, module, names in imports("pkg")] == [
        (1, "os", ()), (3, "trainer.errors", ("ConfigError",))]


# the trainer modules behind mlagents_like_envs.environment: launcher, server (with its codec),
# their errors, and the one reader of MLAGENTS_LIKE_* variables
ENVS_API_USES = {"trainer.envs.launcher", "trainer.envs.cpus", "trainer.protocol.server", "trainer.errors",
                 "trainer.config.env_vars"}
ENVS_API_LIGHT = {"mlagents_like_envs", "mlagents_like_envs.base_env", "mlagents_like_envs.exception"}


@pytest.mark.parametrize("package, forbidden", [
    ("protos", {"trainer", "unity_stub_env", "mlagents_like_envs"}),
    ("unity_stub_env", {"trainer"}),
    ("trainer", {"mlagents_like_envs"}),
])
def test_package_imports_none_of(package, forbidden):
    bad = [f"{where}:{line} imports {module}" for where, line, module, _ in imports(package)
           if top(module) in forbidden]
    assert bad == []


@pytest.mark.parametrize("package, home", [("unity_stub_env", "unity_stub_env/gym/"),
                                           ("mlagents_like_envs", "mlagents_like_envs/envs/")])
def test_only_the_gym_subpackages_import_the_gym_extra(package, home):
    bad = [f"{where}:{line} imports {module}" for where, line, module, _ in imports(package)
           if top(module) in {"gymnasium", "pettingzoo"} and not where.startswith(home)]
    assert bad == []
    assert any(where.startswith(home) and top(module) == "gymnasium"
               for where, _, module, _ in imports(package))  # the scan sees that subpackage


def test_trainer_uses_only_the_stubs_public_api():
    public = set(unity_stub_env.__all__)
    bad = []
    for where, line, module, names in imports("trainer"):
        if top(module) != "unity_stub_env":
            continue
        if module != "unity_stub_env" or not names or not set(names) <= public:
            bad.append(f"{where}:{line} imports {module} {names}")
    assert bad == []


def test_the_envs_api_uses_only_the_trainers_transport_and_the_stubs_public_api():
    public = set(unity_stub_env.__all__)
    bad = []
    for where, line, module, names in imports("mlagents_like_envs"):
        if top(module) == "trainer" and module not in ENVS_API_USES:
            bad.append(f"{where}:{line} imports {module}")
        if top(module) == "unity_stub_env" and (module != "unity_stub_env" or not set(names) <= public):
            bad.append(f"{where}:{line} imports {module} {names}")
    assert bad == []


def test_the_stub_imports_only_the_envs_apis_light_modules():
    light_files = {m.replace(".", "/") + suffix for m in ENVS_API_LIGHT for suffix in (".py", "/__init__.py")}
    bad = [f"{where}:{line} imports {module}" for where, line, module, _ in imports("unity_stub_env")
           if top(module) == "mlagents_like_envs" and module not in ENVS_API_LIGHT]
    bad += [f"{where}:{line} imports {module}" for where, line, module, _ in imports("mlagents_like_envs")
            if where in light_files and top(module) in {"trainer", "unity_stub_env", "mlagents_like_envs"}]
    assert bad == []


def test_the_stubs_public_api_is_there():
    for name in unity_stub_env.__all__:
        assert getattr(unity_stub_env, name) is not None
    assert unity_stub_env.spin_wait_args(0.0015) == ["--spin-wait-ms", "1.5"]
    assert unity_stub_env.spin_wait_args(0.0) == []


def test_the_status_200_header_is_protobufs():
    header = header_pb2.HeaderProto(status=200).SerializeToString()
    assert wire.HEADER_OK_FIELD == b"\x0a" + bytes([len(header)]) + header == b"\x0a\x03\x08\xc8\x01"


def test_the_stub_imports_only_public_names_of_protos():
    """What the stub shares with the trainer (the HTTP/2 framing, the codec pieces) is public in
    ``protos``: a private name imported across the boundary would be a contract nobody sees."""
    bad = [f"{where}:{line} imports {module} {[n for n in names if n.startswith('_')]}"
           for where, line, module, names in imports("unity_stub_env")
           if top(module) == "protos" and any(n.startswith("_") for n in names)]
    assert bad == []


ALGORITHMS = ("trainer.ppo", "trainer.sac", "trainer.poca")


def imported_modules(package: str) -> list[tuple[str, int, str]]:
    """(file, line, module) for every import under ``package``; ``from trainer import ppo`` names
    the module ``trainer.ppo``."""
    found = []
    for where, line, module, names in imports(package):
        found.append((where, line, module))
        found += [(where, line, f"{module}.{name}") for name in names]
    return found


def in_package(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


@pytest.mark.parametrize("package, forbidden", [
    ("trainer/common", ALGORITHMS),
    ("trainer/ppo", ("trainer.sac", "trainer.poca")),
    ("trainer/sac", ("trainer.ppo", "trainer.poca")),
])
def test_the_common_package_imports_no_algorithm_and_ppo_and_sac_not_each_other(package, forbidden):
    bad = [f"{where}:{line} imports {module}" for where, line, module in imported_modules(package)
           if any(in_package(module, other) for other in forbidden)]
    assert bad == []
    assert any(in_package(module, "trainer.common") or package == "trainer/common"
               for _, _, module in imported_modules(package))  # the scan sees the package's imports
