#!/usr/bin/env bash
# Creates .venv-interop: the real ML-Agents 1.1.0 Python packages, used only as an interop peer
# in their own process (they pin protobuf 3.20.3, so they never share a process with our code).
# The wheels declare Python 3.10.1-3.10.12; they run on newer Pythons with --ignore-requires-python.
# tensorboard is pinned to 2.18.0: later releases generate protos that need protobuf>=5
# (google.protobuf.runtime_version), which breaks mlagents-learn's import of SummaryWriter.
# absl-py is needed by torch.utils.tensorboard (everything here is installed with --no-deps).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
venv=.venv-interop
stamp="$venv/.interop-stamp"
want="mlagents-1.1.0-torch-2.13.0-v2"
if [ -x "$venv/bin/python" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then exit 0; fi
py="${PYTHON:-python3}"
# numpy 1.23.5 (ML-Agents 1.1.0's pin) has wheels up to Python 3.11 only
if ! "$py" -c 'import sys; sys.exit(0 if sys.version_info < (3, 12) else 1)'; then
  echo "ensure_interop_venv.sh: the ML-Agents 1.1.0 interop peer needs Python 3.10 or 3.11 (numpy 1.23.5);" \
       "$("$py" --version 2>&1) found. Set PYTHON=/path/to/python3.11 and run ./test.sh again." >&2
  exit 2
fi
rm -rf "$venv"
"$py" -m venv "$venv"
wheels="$(mktemp -d)"
trap 'rm -rf "$wheels"' EXIT
"$venv/bin/python" -m pip download -q --no-deps --python-version 3.10.12 --only-binary=:all: \
  -d "$wheels" mlagents==1.1.0 mlagents-envs==1.1.0
"$venv/bin/python" -m pip install -q "torch==2.13.0"
"$venv/bin/python" -m pip install -q --no-deps --ignore-requires-python "$wheels"/*.whl \
  grpcio "protobuf==3.20.3" "numpy==1.23.5" pyyaml Pillow cloudpickle filelock h5py "tensorboard==2.18.0" \
  six absl-py attrs "cattrs==1.5.0" onnx huggingface-hub "setuptools<70"
"$venv/bin/python" -c "import mlagents.trainers.learn, mlagents_envs.environment"
echo "$want" > "$stamp"
