#!/usr/bin/env bash
# Install dualfem (into the active virtual environment, else ./.venv) and run the main job: the
# paper's f2 scene solved by the default solver (uzawa_auto: the paper's Uzawa method with r from the
# QP), certified by the evaluator. Extra arguments go to `dualfem solve`.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/_env.sh
quiet_pip install -q --upgrade pip
EXTRAS="gmsh"
case "$(uname -m)" in x86_64|AMD64) EXTRAS="$EXTRAS,pardiso" ;; esac   # MKL PARDISO wheels: x86-64 only
quiet_pip install -q -e ".[$EXTRAS]"
rc=0
dualfem solve f2 --set N=64 --set delta=1e-5 "$@" || rc=$?
if [ -z "${VIRTUAL_ENV:-}" ]; then     # installed into ./.venv: say how to reach the command from this shell
  echo "dualfem is installed in $(dirname "$(dirname "$PY")"): 'source $(dirname "$PY")/activate' puts the" \
       "dualfem command on your PATH (or call $(dirname "$PY")/dualfem)" >&2
fi
exit "$rc"
