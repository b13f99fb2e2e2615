"""The wheel works without the checkout: what a user who runs ``pip install mlagents-like`` gets.

The wheel is built from a copy of exactly the files the Dockerfile copies (pyproject.toml,
README.md, the four packages, configs/ and docker/slurm/, which trainer/shipped/ links to), so
nothing else of the checkout can leak into it. It is installed into a new venv in a temporary
folder (no system site-packages). Its third-party dependencies are not downloaded again (torch alone
is 0.7-4.7 GB): the new venv reads them from this test venv's site-packages through one .pth line,
and the test first checks that every requirement in the wheel's metadata is met there. A folder
named on a .pth line is only appended to sys.path; the .pth files inside it (this venv's editable
install of the checkout) are not run, and the test asserts that ``trainer`` and ``unity_stub_env``
are imported from the new venv. Every command runs from a folder outside the checkout, without
PYTHONPATH. One test, several steps: each needs the installed wheel of the step before.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from tests.integration.conftest import free_port_block

ROOT = Path(__file__).resolve().parents[2]
WHEEL_SOURCES = ("pyproject.toml", "README.md", "trainer", "unity_stub_env", "protos", "mlagents_like_envs", "configs",
                 "docker/slurm")

pytestmark = pytest.mark.wheel

CHECK_REQUIREMENTS = r"""
import json, sys
from importlib import metadata
from packaging.requirements import Requirement
dist = metadata.distribution("mlagents-like")
unmet = []
for line in dist.requires or []:
    req = Requirement(line)
    if req.marker is not None and not req.marker.evaluate({"extra": ""}):
        continue  # an extra (test): not needed by a user
    try:
        have = metadata.version(req.name)
    except metadata.PackageNotFoundError:
        unmet.append(f"{req} (missing)")
        continue
    if not req.specifier.contains(have, prereleases=True):
        unmet.append(f"{req} (have {have})")
import trainer, unity_stub_env, mlagents_like_envs.environment
print(json.dumps({"envs": mlagents_like_envs.__file__, "unmet": unmet, "version": dist.version, "requires_python": dist.metadata["Requires-Python"],
                  "classifiers": dist.metadata.get_all("Classifier"),
                  "trainer": trainer.__file__, "unity_stub_env": unity_stub_env.__file__,
                  "trainer_version": trainer.__version__}))
"""


def run(cmd, cwd, env, timeout=300):
    done = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{cmd}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return done


def test_wheel_installs_and_trains_without_the_checkout(tmp_path):
    unset = ("PYTHONPATH", "VIRTUAL_ENV", "http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "grpc_proxy")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    source = tmp_path / "src"
    for name in WHEEL_SOURCES:
        origin = ROOT / name
        if origin.is_dir():
            shutil.copytree(origin, source / name, symlinks=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
        else:
            source.mkdir(exist_ok=True)
            shutil.copy2(origin, source / name)
    # no build isolation: the build backend (setuptools) is already in this venv; an isolated
    # build would download it again
    run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", tmp_path / "dist",
         source], cwd=tmp_path, env=env)
    (wheel,) = (tmp_path / "dist").glob("mlagents_like-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "trainer/shipped/configs/basic.yaml" in names and "trainer/shipped/slurm/train.sbatch" in names
    assert not any(name.startswith(("tests/", "bench/", "configs/", "docker/")) for name in names)

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp_path, env=env)
    python, bin_dir = venv / "bin" / "python", venv / "bin"
    purelib = Path(run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                       cwd=tmp_path, env=env).stdout.strip())
    (purelib / "test-venv-dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    # pip itself comes through the .pth line too; --ignore-installed: the checkout's editable
    # install is visible there as well and must neither count as this wheel nor be uninstalled
    run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--ignore-installed", wheel],
        cwd=tmp_path, env=env)

    work = tmp_path / "user"
    work.mkdir()
    facts = json.loads(run([python, "-c", CHECK_REQUIREMENTS], cwd=work, env=env).stdout)
    assert facts["unmet"] == []
    assert all(Path(facts[name]).is_relative_to(venv) for name in ("trainer", "unity_stub_env", "envs"))
    assert facts["version"] == facts["trainer_version"]
    assert facts["requires_python"] == ">=3.10"
    assert {f"Programming Language :: Python :: 3.{minor}" for minor in (10, 11, 12, 13)} <= set(facts["classifiers"])

    learn, stub = bin_dir / "mlagents-like-learn", bin_dir / "unity-stub-env"
    listed = run([learn, "--list-configs"], cwd=work, env=env).stdout.split()
    assert [Path(p).name for p in listed if p.endswith("basic.yaml")] == ["basic.yaml"]
    assert all(Path(p).is_relative_to(venv) for p in listed)
    run([learn, "--copy-configs", "configs"], cwd=work, env=env)
    assert (work / "configs" / "basic.yaml").read_text() == (ROOT / "configs" / "basic.yaml").read_text()

    written = run([learn, "--write-slurm-template", "slurm"], cwd=work, env=env).stdout
    assert f"MLAGENTS_LIKE_VENV={venv}" in written
    sbatch = work / "slurm" / "train.sbatch"
    assert sbatch.read_bytes() == (ROOT / "docker" / "slurm" / "train.sbatch").read_bytes()
    assert os.access(sbatch, os.X_OK)
    refused = subprocess.run([learn, "--write-slurm-template", "slurm"], cwd=work, env=env,
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "exists already" in refused.stderr and "Traceback" not in refused.stderr

    # the second console script on its own: the stub records a demonstration with its scripted policy
    run([stub, "--task", "basic", "--record-demo", "basic.demo", "--policy", "scripted", "--demo-steps", "200"],
        cwd=work, env=env)
    assert (work / "basic.demo").stat().st_size > 0

    # the first one trains the shipped config against the stub (a separate process, real gRPC)
    run([learn, "configs/basic.yaml", "--env", "stub:basic", "--max-steps", "4000", "--num-areas", "4", "--seed", "1",
         "--run-id", "wheel", "--base-port", free_port_block()], cwd=work, env=env, timeout=400)
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(work / "results" / "wheel" / "Basic"), size_guidance={"scalars": 0})
    events.Reload()
    steps = [event.step for event in events.Scalars("Environment/Cumulative Reward")]
    assert steps and steps[-1] >= 4000, steps
    assert (work / "results" / "wheel" / "Basic.onnx").stat().st_size > 0
