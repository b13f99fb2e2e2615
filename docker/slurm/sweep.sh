#!/usr/bin/env bash
# Seed x hyperparameter sweeps as one Slurm job array of train.sbatch, and a summary table:
#   docker/slurm/sweep.sh CONFIG --seeds 1-5 [--set behaviors.X.hyperparameters.lambd=0.9,0.95] [-- learn args]
#   docker/slurm/sweep.sh summary results/sweeps/NAME
# Run it from the project root. The work is done by sweep.py beside this file (its docstring and
# docs/cluster.md explain the options), with the project's Python (.venv, or $MLAGENTS_LIKE_VENV).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
py=${MLAGENTS_LIKE_VENV:-$PWD/.venv}/bin/python
[ -x "$py" ] || py=python3
exec "$py" "$here/sweep.py" "$@"
