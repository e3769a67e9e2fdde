#!/usr/bin/env bash
# Install dualfem with its test extras (into the active virtual environment, else ./.venv), then
# lint (ruff), type-check the core (mypy) and run the test suite. pytest's exit code 5 ("no tests
# collected") is turned into a failure: a suite that ran no test must never pass by accident.
set -uo pipefail
cd "$(dirname "$0")/.."
. scripts/_env.sh
quiet_pip install -q --upgrade pip || exit 1
EXTRAS="test,parallel,xdmf,gmsh,analysis,testset,html,amg"
case "$(uname -m)" in x86_64|AMD64) EXTRAS="$EXTRAS,pardiso" ;; esac   # MKL PARDISO wheels: x86-64 only
quiet_pip install -q -e ".[$EXTRAS]" || exit 1
# the qpsolvers backends (qp_<backend> solvers): tested where they install; a backend without a wheel
# for this platform is reported NOT INSTALLED by dualfem and skipped by its tests, never a failure
quiet_pip install -q -e ".[qp]" || echo "note: some qpsolvers backends did not install (see above)" >&2
# headless Chromium for the dashboard's browser test (tests/test_dashboard.py skips without it): installed
# where allowed (apt-get, and root or passwordless sudo); never a failure of this script when it cannot be
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1 \
   && command -v apt-get >/dev/null 2>&1; then
  if [ "$(id -u)" -eq 0 ]; then ASROOT=""; elif sudo -n true 2>/dev/null; then ASROOT="sudo -n"; else ASROOT="no"; fi
  if [ "$ASROOT" != "no" ]; then
    { $ASROOT env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1 \
      || { $ASROOT apt-get update -q >/dev/null 2>&1 \
           && $ASROOT env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1; }; } \
      || echo "note: chromium did not install: the dashboard's browser test will be skipped" >&2
  fi
fi
"$PY" -m ruff check . || { echo "ruff found problems (see above)" >&2; exit 1; }
"$PY" -m mypy || { echo "mypy found problems in dualfem/core (see above)" >&2; exit 1; }
# one test process per core (pytest-xdist): the suite is CPU-bound and its tests are independent
"$PY" -m pytest -q -n auto "$@"
rc=$?
if [ "$rc" -eq 5 ]; then
  echo "pytest collected no tests: failing on purpose" >&2
  exit 1
fi
exit "$rc"
