"""reports/three_d.md in one command: the penny crack against its closed forms per mesh level, and 3D
sizes against time and memory (assembly, setup, solve, certificate, peak; the linear algebra chosen).

    python benchmarks/three_d.py --out benchmarks/results/three_d --report reports
    python benchmarks/three_d.py --out benchmarks/results/three_d --report reports --resume     # keeps done runs
    python benchmarks/three_d.py --out benchmarks/results/three_d --report reports --render-only

Every run is its own process (``--worker``), so its peak RSS is its own; each finished run is one JSON line
appended (and fsynced) to ``OUT/runs.jsonl``; ``--resume`` skips the runs already there, and without
it an existing ``runs.jsonl`` is refused (nothing is overwritten). The scene is the library's ``penny``
(scenes/penny.toml: a disk crack of radius a = 1 at the centre of a cube of side 10 a, E = 1000,
nu = 0.3, delta = 1e3, no supports: the rigid-body motions removed), each level
``mesh_size:tip_size[:surface_size]``, the load cases and closed forms of benchmarks/penny.py (tension:
opening against Sneddon's w(r) = 8 (1 - nu^2) sigma / (pi E) sqrt(a^2 - r^2), relative L2 over
r <= 0.8 a; compression: closure and the mean contact pressure against |sigma|; compression plus shear
with free slip: Segedin's slip 8 (1 - nu) tau / (pi (2 - nu) G) sqrt(a^2 - r^2)). The size table's
floor: one PARDISO factorization + solve of K when the 3D memory model says it fits, else one
AMG-preconditioned CG solve (rtol 1e-8).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
LEVELS = ("1:0.1", "0.5:0.05", "0.5:0.02:0.05", "0.35:0.01:0.05", "0.25:0.007:0.04", "0.2:0.005:0.03")
CASES = ("tension", "compression", "shear")
#: the size table beyond the validation rows: (level, extra runs, all under tension): the floor at each level
#: of the size table, pdas (the dual path) where a factorization still fits, a ~670 k-unknown newton_amg
SIZES = (("0.35:0.01:0.05", ("floor", "pdas")), ("0.2:0.005:0.03", ("floor",)),
         ("0.18:0.005:0.03", ("floor", "newton_amg")), ("0.17:0.005:0.03", ("newton_amg",)))
TIMEOUT = 1800


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def worker(spec: dict) -> dict:
    """One run in this process: build the penny at ``spec['level']`` for ``spec['case']``, run ``spec['solver']``
    (or the floor), certify, measure the errors against the closed forms."""
    sys.path.insert(0, str(HERE))
    import penny

    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run

    t0 = time.perf_counter()
    qp = load_scene("penny", penny.scene(spec["case"], *penny.parse_level(spec["level"]))).build()
    out = {**spec, "n": qp.n, "m": qp.m, "assembly_s": time.perf_counter() - t0}
    if spec["solver"] == "floor":
        return {**out, **_floor(qp), "peak_mb": _peak_mb()}
    sol = run(spec["solver"], qp)
    cert = sol.info.get("certificate") or {}
    out.update(status=str(sol.status), setup_s=sol.time_s.get("setup"), solve_s=sol.time_s.get("solve"),
               certify_s=sol.time_s.get("certify"), iterations=sol.iterations, certified_error=cert.get("value"),
               certificate_path=cert.get("path"), operator=sol.info.get("operator"),
               ksolve=sol.info.get("ksolve", "amg" if spec["solver"] == "newton_amg" else None),
               peak_mb=_peak_mb())
    return {**out, **penny.errors(spec["case"], qp, sol)}


def _floor(qp) -> dict:
    """The floor (benchmarks/three_d_linear_algebra.floor_solve) in this report's row fields."""
    from three_d_linear_algebra import floor_solve

    f = floor_solve(qp)
    return {"status": "pardiso" if f["status"] == "pardiso" else "amg-cg", "setup_s": f["setup"],
            "solve_s": f["solve"], "residual": f["residual"]}


def _runs(levels, sizes) -> list[dict]:
    runs = [{"part": "validation", "level": lv, "case": c, "solver": "newton_amg"} for lv in levels for c in CASES]
    runs += [{"part": "size", "level": lv, "case": "tension", "solver": s} for lv, solvers in sizes for s in solvers]
    return runs


def _key(r: dict) -> tuple:
    return (r["part"], r["level"], r["case"], r["solver"])


def _append(path: Path, row: dict) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(row) + "\n")
        fh.flush()
        os.fsync(fh.fileno())


def read_rows(path: Path) -> list[dict]:
    """The finished rows, the last one of each run (a line cut by a kill is skipped)."""
    rows: dict[tuple, dict] = {}
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                r = json.loads(line)
                rows[_key(r)] = r
            except (ValueError, KeyError):
                continue
    return list(rows.values())


def execute(out: Path, levels, sizes, resume: bool, retry_failed: bool = False) -> None:
    path = out / "runs.jsonl"
    if path.exists() and not resume:
        raise SystemExit(f"three_d.py: error: {path} exists: --resume to continue it, or another --out")
    out.mkdir(parents=True, exist_ok=True)
    done = {_key(r) for r in read_rows(path)
            if not (retry_failed and r.get("status") in ("error", "time_limit"))}
    todo = [r for r in _runs(levels, sizes) if _key(r) not in done]
    for i, spec in enumerate(todo, 1):
        print(f"[{i}/{len(todo)}] {spec['part']} {spec['level']} {spec['case']} {spec['solver']} ...",
              file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            p = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)], capture_output=True,
                               text=True, timeout=TIMEOUT)
            row = json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 else \
                {**spec, "status": "error", "message": p.stderr.strip().splitlines()[-1:] or ""}
        except subprocess.TimeoutExpired:
            row = {**spec, "status": "time_limit", "message": f"killed after {TIMEOUT} s"}
        row["wall_s"] = time.perf_counter() - t0
        _append(path, row)
        print(f"    {row.get('status')} n={row.get('n')} error={row.get('error')} wall {row['wall_s']:.0f} s",
              file=sys.stderr, flush=True)
    meta = {"machine": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "load_at_end": os.getloadavg()[0], "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (out / "meta.json").write_text(json.dumps(meta), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/three_d", help="folder of runs.jsonl")
    ap.add_argument("--report", default=None, help="write three_d.md (and three_d/ figures) into this folder")
    ap.add_argument("--levels", nargs="+", default=list(LEVELS))
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--retry-failed", action="store_true",
                    help="with --resume, run again the runs whose row says error or time_limit (a new row is appended; "
                         "the report reads the last row of each run)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(json.loads(a.worker))))
        return 0
    out = Path(a.out)
    if not a.render_only:
        execute(out, a.levels, SIZES, a.resume, a.retry_failed)
    if a.report:
        sys.path.insert(0, str(HERE))
        from three_d_report import render

        md = render(out, Path(a.report))
        print(f"wrote {md}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
