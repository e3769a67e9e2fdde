#!/usr/bin/env bash
# Install dualfem (into the active virtual environment, else ./.venv) and run the main job: the
# paper's f2 scene solved by the paper's method (uzawa), cross-checked by the evaluator. Extra
# arguments go to `dualfem solve`.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/_env.sh
"$PY" -m pip install -q --upgrade pip >/dev/null
EXTRAS="gmsh"
case "$(uname -m)" in x86_64|AMD64) EXTRAS="$EXTRAS,pardiso" ;; esac   # MKL PARDISO wheels: x86-64 only
"$PY" -m pip install -q -e ".[$EXTRAS]"
dualfem solve f2 --set N=64 --set delta=1e-5 "$@"
