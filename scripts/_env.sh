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

# quiet_pip ARGS...: "$PY" -m pip ARGS with its output (setuptools' build warnings, pip's notices) held
# back; shown in full on stderr, with the exit status, only when pip fails.
quiet_pip() {
  local log rc=0
  log="$(mktemp "${TMPDIR:-/tmp}/dualfem-pip.XXXXXX")" || { "$PY" -m pip "$@"; return; }
  "$PY" -m pip "$@" >"$log" 2>&1 || rc=$?
  if [ "$rc" -ne 0 ]; then
    cat "$log" >&2
    echo "pip $* failed (exit $rc): its output is above" >&2
  fi
  rm -f "$log"
  return "$rc"
}
