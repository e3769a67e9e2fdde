#!/usr/bin/env bash
# Install dualfem and run the main job: the paper's f2 scene solved by the paper's method
# (uzawa), cross-checked by the evaluator. Extra arguments go to `dualfem solve`.
set -euo pipefail
cd "$(dirname "$0")/.."
python -m pip install -q -e .
export MPLBACKEND=Agg
dualfem solve f2 --set N=64 --set delta=1e-5 "$@"
