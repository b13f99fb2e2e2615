#!/usr/bin/env bash
# Creates or updates .venv (and .venv-interop, the real ML-Agents 1.1.0 used as interop peer),
# then runs the whole test suite. Extra arguments go to pytest, e.g. ./test.sh -k codec
set -euo pipefail
cd "$(dirname "$0")"
./scripts/ensure_venv.sh
./scripts/ensure_interop_venv.sh
exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
