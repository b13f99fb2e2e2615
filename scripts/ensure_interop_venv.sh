#!/usr/bin/env bash
# Creates .venv-interop: the real ML-Agents 1.1.0 Python packages, used only as an interop peer
# in their own process (they pin protobuf 3.20.3, so they never share a process with our code).
#   PYTHON=python3.13                 the interpreter (default: python3)
#   INTEROP_VENV=.venv-interop-3.13   the venv's folder (default: .venv-interop); the tests read the
#                                     same variable (tests/interop_venv.py)
# The wheels declare Python 3.10.1-3.10.12; they run on newer Pythons with --ignore-requires-python.
# Everything is installed with --no-deps, so the pins below are the only ones:
#   protobuf 3.20.3, cattrs 1.5.0: ML-Agents 1.1.0's own pins.
#   numpy 1.23.5: ML-Agents' pin, on Python 3.10/3.11. It has no wheel past 3.11, so there the
#     current numpy is used and scripts/interop_sitecustomize.py puts back the two things
#     ML-Agents needs from numpy 1.23.5 and Python 3.11 (docs/python-versions.md says which, and
#     which tests prove it changes no number).
#   tensorboard 2.18.0: later releases generate protos that need protobuf>=5
#     (google.protobuf.runtime_version), which breaks mlagents-learn's import of SummaryWriter.
#   setuptools<70: ML-Agents imports pkg_resources and distutils.version (setuptools provides
#     distutils from Python 3.12 on); see docs/python-versions.md for what later releases break.
#   torch 2.13.0: as in scripts/ensure_venv.sh.
# absl-py is needed by torch.utils.tensorboard.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
venv="${INTEROP_VENV:-.venv-interop}"
stamp="$venv/.interop-stamp"
want="mlagents-1.1.0-torch-2.13.0-v3"
if [ -x "$venv/bin/python" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then exit 0; fi
py="${PYTHON:-python3}"
if "$py" -c 'import sys; sys.exit(0 if sys.version_info < (3, 12) else 1)'; then
  numpy="numpy==1.23.5"; adapt=""
else
  numpy="numpy"; adapt="scripts/interop_sitecustomize.py"
fi
rm -rf "$venv"
"$py" -m venv "$venv"
wheels="$(mktemp -d)"
trap 'rm -rf "$wheels"' EXIT
"$venv/bin/python" -m pip download -q --no-deps --python-version 3.10.12 --only-binary=:all: \
  -d "$wheels" mlagents==1.1.0 mlagents-envs==1.1.0
"$venv/bin/python" -m pip install -q "torch==2.13.0"
"$venv/bin/python" -m pip install -q --no-deps --ignore-requires-python "$wheels"/*.whl \
  grpcio "protobuf==3.20.3" "$numpy" pyyaml Pillow cloudpickle filelock h5py "tensorboard==2.18.0" \
  six absl-py attrs "cattrs==1.5.0" onnx huggingface-hub "setuptools<70"
if [ -n "$adapt" ]; then
  cp "$adapt" "$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("purelib"))')/sitecustomize.py"
fi
"$venv/bin/python" -c "import mlagents.trainers.learn, mlagents_envs.environment"
"$venv/bin/mlagents-learn" --help >/dev/null
echo "$want" > "$stamp"
