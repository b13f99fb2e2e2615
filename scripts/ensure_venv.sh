#!/usr/bin/env bash
# Creates or updates .venv with the project and its test tools. Idempotent: a stamp file
# records the hash of pyproject.toml, so an unchanged project costs nothing the second time.
#   PYTHON=python3.13            the interpreter that makes the venv (default: python3)
#   VENV=.venv-3.13   the venv's folder (default: .venv); .ci/run's second leg uses it
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
py="${PYTHON:-python3}"
venv="${VENV:-.venv}"
"$py" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else 1)' || {
  echo "ensure_venv.sh: mlagents-like needs Python 3.10 or newer; $("$py" --version 2>&1) found." \
       "Set PYTHON=/path/to/python3.X and run again." >&2
  exit 2
}
[ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
stamp="$venv/.mlagents-like-stamp"
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  # torch first and pinned (docs/python-versions.md "torch"): on this project's machines pip takes
  # 2.13.0's CPU wheel from local disk for Python 3.11; for 3.12/3.13 PyPI has only the CUDA build
  # (4.7 GB with its nvidia-* wheels, runs on the CPU), unless PIP_EXTRA_INDEX_URL names
  # PyTorch's CPU index. A bare 'torch' requirement would pull the newest CUDA build.
  "$venv/bin/python" -m pip install -q --upgrade pip
  "$venv/bin/python" -m pip show torch >/dev/null 2>&1 || "$venv/bin/python" -m pip install -q "torch==2.13.0"
  "$venv/bin/python" -m pip install -q -e ".[test]"
  echo "$want" > "$stamp"
else
  # cheap re-link of the editable install in case the tree moved
  "$venv/bin/python" -c "import trainer, unity_stub_env, protos, mlagents_like_envs" 2>/dev/null \
    || "$venv/bin/python" -m pip install -q --no-deps -e .
fi
# Byte-compile the project's own modules (pip compiles installed wheels, not an editable tree):
# where PYTHONDONTWRITEBYTECODE is set, as on this project's CI machines, every process would
# otherwise recompile them from source on import (measured: +0.2 s per trainer start).
"$venv/bin/python" -m compileall -q trainer unity_stub_env protos mlagents_like_envs >/dev/null
