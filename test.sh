#!/usr/bin/env bash
# Creates or updates .venv (and .venv-interop, the real ML-Agents 1.1.0 used as interop peer),
# then runs the whole test suite. Extra arguments go to pytest, e.g. ./test.sh -k codec
#   PYTHON=python3.13 VENV=.venv-3.13 INTEROP_VENV=.venv-interop-3.13 ./test.sh   another Python
#   (the venvs' folders: scripts/ensure_venv.sh, scripts/ensure_interop_venv.sh; the tests find
#   the interop venv through INTEROP_VENV too)
set -euo pipefail
cd "$(dirname "$0")"
# The two venvs are independent and pip uses one CPU: they are made side by side.
./scripts/ensure_interop_venv.sh &
interop=$!
venv_status=0
./scripts/ensure_venv.sh || venv_status=$?
interop_status=0
wait "$interop" || interop_status=$?
[ "$venv_status" -eq 0 ] || exit "$venv_status"
[ "$interop_status" -eq 0 ] || exit "$interop_status"
# One pytest-xdist worker per CPU; tests that share something (the private Slurm cluster, a fixed
# port, an expensive module fixture) are a group run by one worker: XDIST_GROUPS in
# tests/conftest.py (docs/testing.md). ./test.sh -n 0 runs everything in one process.
exec "${VENV:-.venv}/bin/python" -m pytest -q -p no:cacheprovider -n auto --dist loadgroup "$@"
