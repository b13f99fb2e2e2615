#!/usr/bin/env bash
# Creates or updates .venv, then trains the default stub task (3DBall on the MuJoCo stub simulator)
# end to end. Extra arguments go to mlagents-like-learn, e.g. ./run.sh --max-steps ... or --force
# PYTHON=python3.X picks the interpreter and VENV=DIR the venv's folder (scripts/ensure_venv.sh).
set -euo pipefail
cd "$(dirname "$0")"
./scripts/ensure_venv.sh
run_id="${RUN_ID:-ball3d}"
config="${CONFIG:-configs/ball3d.yaml}"
task="${TASK:-ball3d}"
args=("$config" --env "stub:$task" --run-id "$run_id" --no-graphics)
# Re-running continues the earlier run instead of refusing to overwrite it.
if [ -d "results/$run_id" ] && [[ " $* " != *" --force "* ]]; then args+=(--resume); fi
status=0
"${VENV:-.venv}/bin/mlagents-like-learn" "${args[@]}" "$@" || status=$?
echo
echo "Results:     $(pwd)/results/$run_id   (final model: results/$run_id/*.onnx)"
echo "TensorBoard: ${VENV:-.venv}/bin/tensorboard --logdir $(pwd)/results   then open http://localhost:6006"
exit $status
