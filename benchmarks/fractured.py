"""Where dual methods differ: fractured bodies (issue 25), from benchmarks/fractured.toml.

Per scene: the floor (meshing + assembly timed, then the fastest library factorization + one
solve of K, PARDISO here, in its own process) and, per solver, the whole command
``dualfem solve SCENE --set ... --solver S --json --quiet`` in its own process (its wall time, its
own time split, status, certificate, energy, iterations, work counters and peak RSS). A solver entry
``"pdas:operator=dense"`` passes ``-p operator=dense`` (the crossover of the two dual operators).
Each finished run is appended to ``OUT/runs.jsonl`` (one line, flushed: a killed sweep loses no
finished run; ``--resume`` skips them); the report is rendered from that file.

    python benchmarks/fractured.py --out benchmarks/results/fractured --report reports
    python benchmarks/fractured.py --out benchmarks/results/fractured --render-only --report reports
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

HERE = Path(__file__).resolve().parent
CLI = "import sys; from dualfem.cli import main; sys.exit(main())"
FLOOR = Path(__file__).resolve().parent / "floor.py"       # the floor, in its own process


def _run(cmd: list[str], timeout: float) -> tuple[float, dict]:
    """Wall time and the last JSON line of a command run in its own process group (killed at timeout)."""
    env = dict(os.environ, MPLBACKEND="Agg")
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                         start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()
        return time.perf_counter() - t0, {"error": f"killed after {timeout:.0f} s"}
    wall = time.perf_counter() - t0
    try:
        return wall, json.loads(out.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return wall, {"error": (err or out).strip()[-300:]}


def _sets(d: dict) -> list[str]:
    return [a for k, v in d.items() for a in ("--set", f"{k}={v}")]


def _solver_args(entry: str) -> tuple[str, list[str]]:
    name, _, params = entry.partition(":")
    args = ["--solver", name]
    for kv in filter(None, params.split(",")):
        args += ["-p", kv]
    return name, args


def _append(path: Path, row: dict) -> None:
    with open(path, "a") as fh:
        fh.write(json.dumps(row) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


def _load(path: Path) -> list[dict]:
    rows = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except ValueError:          # a half line of a killed run: dropped, the run is redone
                pass
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spec", default=str(HERE / "fractured.toml"))
    ap.add_argument("--out", default="dualfem-results/fractured")
    ap.add_argument("--only", nargs="*", default=None, help="scene labels to run")
    ap.add_argument("--solvers", nargs="*", default=None, help="solver entries to run (default: the spec's)")
    ap.add_argument("--resume", action="store_true", help="keep finished runs of --out")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--report", default=None, metavar="DIR", help="write DIR/NAME.md and its figure")
    ap.add_argument("--name", default="fractured", help="the report's name: DIR/NAME.md, figure DIR/NAME/ "
                    "(fractured3d: the 3D report of benchmarks/fractured3d.toml)")
    a = ap.parse_args()
    out = Path(a.out)
    runs = out / "runs.jsonl"
    if not a.render_only:
        if runs.exists() and not a.resume:
            print(f"fractured.py: error: {runs} exists; pass --resume to keep its runs, or another --out",
                  file=sys.stderr)
            return 2
        spec = tomllib.loads(Path(a.spec).read_text())
        out.mkdir(parents=True, exist_ok=True)
        done = {(r["label"], r["entry"]) for r in _load(runs) if "error" not in r.get("result", {})}
        tl = float(spec.get("time_limit", 900.0))
        meta = {"machine": platform.node(), "cpu": platform.processor() or platform.machine(),
                "cores": os.cpu_count(), "python": platform.python_version(), "spec": a.spec,
                "started_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
        (out / "meta.json").write_text(json.dumps(meta, indent=1))
        for sc in spec["scenes"]:
            if a.only and sc["label"] not in a.only:
                continue
            sets = json.dumps(sc.get("set", {}))
            if (sc["label"], "floor") not in done:
                print(f"[{sc['label']}] floor ...", file=sys.stderr, flush=True)
                wall, res = _run([sys.executable, str(FLOOR), sc["scene"], sets], 4 * tl)
                _append(runs, {"label": sc["label"], "entry": "floor", "wall": wall, "result": res})
            for entry in a.solvers or sc.get("solvers", spec["solvers"]):
                if (sc["label"], entry) in done:
                    continue
                name, args = _solver_args(entry)
                cmd = [sys.executable, "-c", CLI, "solve", sc["scene"], *_sets(sc.get("set", {})), *args,
                       "-p", f"time_limit={tl}", "--json", "--quiet"]
                print(f"[{sc['label']}] {entry} ...", file=sys.stderr, flush=True)
                wall, res = _run(cmd, 2 * tl + 120)
                _append(runs, {"label": sc["label"], "entry": entry, "wall": wall, "result": res})
                print(f"[{sc['label']}] {entry}: {res.get('status', res.get('error'))} in {wall:.1f} s",
                      file=sys.stderr, flush=True)
    if a.report:
        from fractured_report import render  # benchmarks/fractured_report.py

        render(_load(runs), json.loads((out / "meta.json").read_text()), Path(a.report), name=a.name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
