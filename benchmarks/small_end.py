"""The small end stays fast (issue 25, item 7): the whole `dualfem solve f2 --set N=.. --solver pdas` against
the floor, with its breakdown.

    python benchmarks/small_end.py --N 256 512 --repeat 5 [--json results.json]

Per N, ``--repeat`` rounds of three fresh processes (interleaved, so that a change of the machine's load
hits every column alike); medians are printed:

* **whole**: wall time of ``dualfem solve f2 --set N=.. --solver pdas --json --quiet`` (spawn to exit);
  its stages from the command's own ``time_s``: assembly (scene -> QP), setup (pdas: PARDISO analysis,
  factorization of K_fixed with the Schur complement onto the defect unknowns, the reduction), solve,
  certify; **outside** = whole - ``time_s.total``: Python start-up, imports, plugin discovery, thread
  set-up, JSON output and exit.
* **start-up**: wall time of the same command at N = 4 (everything above at a negligible size).
* **floor**: one factorization + one solve of K by the default backend (MKL PARDISO here), in its own
  process, after assembly and a warm-up that loads the library (the definition of
  benchmarks/end_to_end.py); **ratio** = whole / floor (the target: <= 1.5).

The machine (CPU, cores, the commands' threads), the load average before and after, and whether Python
may write bytecode caches (``PYTHONDONTWRITEBYTECODE``: without them every dualfem module is compiled at
every start, 0.1-0.2 s here) are printed with the table. ``--pycache DIR`` runs the processes as an ordinary
installation does, with bytecode caches (kept in DIR: ``PYTHONPYCACHEPREFIX``, so nothing is written
into the repository; one untimed command fills it first).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

from end_to_end import _run as run_json  # noqa: E402  (benchmarks/end_to_end.py, beside this script)

FLOOR = Path(__file__).resolve().parent / "floor.py"       # the floor, in its own process

COLUMNS = ("startup", "outside", "assembly", "setup", "solve", "certify", "total", "whole", "floor_factor",
           "floor_solve", "floor")


#: environment of the timed processes (``--pycache`` changes it)
ENV = dict(os.environ, MPLBACKEND="Agg")


def _run(cmd: list[str]) -> tuple[float, dict]:
    wall, res = run_json(cmd, ENV)
    if "error" in res:
        raise SystemExit(f"{' '.join(cmd)} failed: {res['error']}")
    return wall, res


def _solve_cmd(N: int) -> list[str]:
    return [sys.executable, "-m", "dualfem", "solve", "f2", "--set", f"N={N}", "--solver", "pdas", "--json", "--quiet"]


def one_round(N: int) -> dict:
    """One floor process, one whole command at N and one at N = 4: the columns of :data:`COLUMNS`."""
    _, fl = _run([sys.executable, str(FLOOR), "f2", json.dumps({"N": N})])
    wall, rec = _run(_solve_cmd(N))
    start, _ = _run(_solve_cmd(4))
    t = rec["time_s"]
    return {"startup": start, "outside": wall - t["total"], "assembly": t["assembly"], "setup": t["setup"],
            "solve": t["solve"], "certify": t["certify"], "total": t["total"], "whole": wall,
            "floor_factor": fl["factor"], "floor_solve": fl["solve"], "floor": fl["factor"] + fl["solve"],
            "status": rec["status"], "threads": rec["threads"], "factor": rec["factor"], "n": rec["ndof"],
            "floor_backend": fl["backend"], "floor_threads": fl["threads"]}


def machine() -> str:
    """CPU, cores, Python, the commit, and the bytecode setting of the timed processes."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), cpu)
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    except OSError:
        commit, dirty = "?", ""
    cache = (f"bytecode caches in {ENV['PYTHONPYCACHEPREFIX']}" if "PYTHONPYCACHEPREFIX" in ENV else
             f"PYTHONDONTWRITEBYTECODE={ENV.get('PYTHONDONTWRITEBYTECODE', '')!r}")
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, commit {commit}"
            f"{' (modified)' if dirty else ''}, {cache}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", default=None, metavar="FILE", help="also write every round and the medians here")
    ap.add_argument("--pycache", default=None, metavar="DIR",
                    help="bytecode caches in DIR (PYTHONPYCACHEPREFIX), as an ordinary installation has them")
    a = ap.parse_args()
    if a.pycache:
        ENV.pop("PYTHONDONTWRITEBYTECODE", None)
        ENV["PYTHONPYCACHEPREFIX"] = os.path.abspath(a.pycache)
        _run(_solve_cmd(4))                                     # fills the caches (untimed)
    load0, started = os.getloadavg(), time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    rounds: dict[int, list[dict]] = {}
    for N in a.N:
        rounds[N] = []
        for k in range(a.repeat):
            r = one_round(N)
            rounds[N].append(r)
            print(f"N={N} round {k + 1}: whole {r['whole']:.2f} s, floor {r['floor']:.2f} s, "
                  f"load {os.getloadavg()[0]:.1f}", file=sys.stderr, flush=True)
    med = {N: {c: statistics.median(r[c] for r in rs) for c in COLUMNS} for N, rs in rounds.items()}
    load1 = os.getloadavg()
    print(f"{machine()}; started {started}, load average {load0[0]:.1f} at start, {load1[0]:.1f} at end; "
          f"medians of {a.repeat} (s)\n")
    print("| N | unknowns | threads | start-up (N=4 command) | outside stages | assembly | setup | solve | certify "
          "| whole | floor (factor + solve) | whole / floor |")
    print("|---" * 12 + "|")
    for N, m in med.items():
        r0 = rounds[N][0]
        print(f"| {N} | {r0['n']:,} | {r0['threads']} | {m['startup']:.2f} | {m['outside']:.2f} | "
              f"{m['assembly']:.2f} | {m['setup']:.2f} | {m['solve']:.2f} | {m['certify']:.3f} | {m['whole']:.2f} | "
              f"{m['floor']:.2f} ({m['floor_factor']:.2f} + {m['floor_solve']:.2f}, {r0['floor_backend']}) | "
              f"{m['whole'] / m['floor']:.2f} |")
    if a.json:
        with open(a.json, "w", encoding="utf-8") as fh:
            json.dump({"machine": machine(), "started": started, "loadavg": [load0, load1],
                       "rounds": {str(N): rs for N, rs in rounds.items()},
                       "medians": {str(N): m for N, m in med.items()}}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
