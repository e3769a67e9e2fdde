# Sourced by scripts/run.sh and scripts/test.sh: use the active virtual environment, or create and
# use .venv in the repository (so the README commands also work on a Python that refuses global
# installs, PEP 668). Sets PY to the interpreter to use.
if [ -n "${VIRTUAL_ENV:-}" ]; then
  PY="$VIRTUAL_ENV/bin/python"
else
  if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv || { echo "cannot create .venv: install python3-venv" >&2; exit 1; }
  fi
  PY="$PWD/.venv/bin/python"
fi
export PATH="$(dirname "$PY"):$PATH"
export MPLBACKEND=Agg
