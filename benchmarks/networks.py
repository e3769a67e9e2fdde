"""Fracture networks from files (issue 35, items 2 and 4): sizes and times, the pair checks, ``size_growth``.

    python benchmarks/networks.py --out benchmarks/results/networks --report reports

Stages (each appends JSON lines to OUT/runs.jsonl; ``--render-only`` re-renders reports/networks.md):

* ``files``: the cracks of the ``fractured`` scenes of benchmarks/fractured.toml (400 and 2,000 cracks,
  seed 1) written by ``write_defects(path, random_cracks(...), 2)`` as CSV files, and scene files
  ``problem = "fractured"``, ``defects_file = ...`` beside them;
* ``solve``: ``dualfem solve`` of the generated scene and of the scene reading the file, each in its own
  process (solver mprgp, the fastest on these scenes in reports/fractured.md), alternating, ``--repeat``
  times (400 cracks) and twice (2,000 from the file; once generated): wall time, the command's own time
  split and peak RSS;
* ``checks``: the geometry checks alone (no meshing) for 2,000 and 10,000 random cracks (2D,
  ``gmsh_mesh.validate``) and 2,000 disks (3D, ``check_apart``), median of 3, in this process;
* ``refine``: a Griffith crack (half-length a = 1, body 100 a x 100 a: a finite-width effect of ~3e-4,
  E = 1000, nu = 0.3, plane strain, remote tension 1 normal to it, delta = 1e3: open, no contact) meshed
  with ``mesh_size`` 5 a and ``tip_size`` halved from 0.1 a to 0.00625 a, for ``size_growth`` 0.3 (the
  earlier fixed slope), 0.1 and 0.03:
  the opening's relative L2 error over |x| <= 0.8 a against 4 (1 - nu^2) sigma / E sqrt(a^2 - x^2),
  solved by pdas and certified.
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

import numpy as np

HERE = Path(__file__).resolve().parent
CLI = "import sys; from dualfem.cli import main; sys.exit(main())"
SOLVER = "mprgp"
#: the fractured scenes of benchmarks/fractured.toml (seed 1, load f1)
SCENES = {400: {"crack_length": 0.025, "mesh_size": 0.003}, 2000: {"crack_length": 0.012, "mesh_size": 0.0014}}
E, NU, A = 1000.0, 0.3, 1.0
GROWTHS = (0.3, 0.1, 0.03)
TIPS = (0.1, 0.05, 0.025, 0.0125, 0.00625)


def _append(path: Path, row: dict) -> None:
    with open(path, "a") as fh:
        fh.write(json.dumps(row) + "\n")


def _load(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []


def _run(cmd: list[str], timeout: float = 900.0) -> tuple[float, dict]:
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=dict(os.environ, MPLBACKEND="Agg"))
    wall = time.perf_counter() - t0
    try:
        return wall, json.loads(p.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return wall, {"error": (p.stderr or p.stdout).strip()[-300:]}


def _keys(n: int) -> dict:
    s = SCENES[n]
    return {"crack_length": s["crack_length"], "mesh_size": s["mesh_size"], "tip_size": s["mesh_size"],
            "load": "f1"}


def files(out: Path) -> None:
    """The generated cracks as CSV files and scene files reading them."""
    from dualfem.problems.defects_file import write_defects
    from dualfem.problems.fractured import random_cracks

    for n, s in SCENES.items():
        tables = random_cracks(cracks=n, crack_length=s["crack_length"], min_gap=2 * s["mesh_size"], seed=1)
        write_defects(out / f"network{n}.csv", tables, 2)
        (out / f"network{n}.toml").write_text(
            f'problem = "fractured"\ndefects_file = "network{n}.csv"\nmesh_size = {s["mesh_size"]}\n'
            f'tip_size = {s["mesh_size"]}\nload = "f1"\n')


def _solve_cmd(n: int, source: str, out: Path) -> list[str]:
    if source == "file":
        scene = [str(out / f"network{n}.toml")]
    else:
        scene = ["fractured", *[a for k, v in {"cracks": n, "seed": 1, **_keys(n)}.items()
                                for a in ("--set", f"{k}={v}")]]
    return [sys.executable, "-c", CLI, "solve", *scene, "--solver", SOLVER, "--json", "--quiet"]


def solve(out: Path, runs: Path, repeat: int, only: list[int] | None = None) -> None:
    plan = [(400, src) for _ in range(repeat) for src in ("generated", "file")]
    plan += [(2000, "file"), (2000, "generated"), (2000, "file")]
    for n, src in plan:
        if only and n not in only:
            continue
        wall, res = _run(_solve_cmd(n, src, out))
        row = {"stage": "solve", "cracks": n, "source": src, "wall": wall, "load1": os.getloadavg()[0],
               "result": {k: res.get(k) for k in ("status", "ndof", "n_defect_nodes", "time_s", "peak_rss_mb",
                                                  "iterations", "error", "threads")}}
        _append(runs, row)
        print(f"[solve] {n} {src}: {res.get('status', res.get('error'))} in {wall:.1f} s", file=sys.stderr, flush=True)


def _median_time(fn, k: int = 3) -> float:
    times = []
    for _ in range(k):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def checks(runs: Path) -> None:
    from dualfem.problems import gmsh_mesh
    from dualfem.problems.fractured import random_cracks
    from dualfem.problems.three_d.geometry import check_apart, parse_surface

    for n, length, gap in ((2000, 0.012, 0.0028), (10000, 0.005, 0.0012)):
        cracks = random_cracks(cracks=n, crack_length=length, min_gap=gap, seed=1)
        t = _median_time(lambda c=cracks, g=gap: gmsh_mesh.validate(1.0, 1.0, c, g, g))
        _append(runs, {"stage": "checks", "what": f"2D: {n:,} cracks (gmsh_mesh.validate)", "seconds": t})
    rng = np.random.default_rng(1)
    centres = np.stack(np.meshgrid(*[np.arange(13)] * 3, indexing="ij"), -1).reshape(-1, 3)[:2000] + 1.0
    disks = [parse_surface(i, {"shape": "disk", "center": (c + 0.03 * rng.standard_normal(3)).tolist(),
                               "normal": rng.standard_normal(3).tolist(), "radius": 0.3}, 1e-5)
             for i, c in enumerate(centres)]
    t = _median_time(lambda: check_apart(disks, 0.05))
    _append(runs, {"stage": "checks", "what": "3D: 2,000 disks (check_apart)", "seconds": t})


def griffith(tip: float, growth: float) -> dict:
    """One Griffith level: unknowns, the opening's relative L2 error, the solver's status."""
    from dualfem.experiments.runner import run
    from dualfem.scene import load_scene

    L = 100.0 * A
    pr = load_scene("f2", {"mesh": "gmsh", "width": L, "height": L, "E": E, "nu": NU, "delta": 1e3,
                           "mesh_size": 5.0, "tip_size": tip, "size_growth": growth,
                           "defects": [{"points": [[L / 2 - A, L / 2], [L / 2 + A, L / 2]]}],
                           "remote_stress": [[0.0, 0.0], [0.0, 1.0]]})
    qp = pr.build()
    sol = run("pdas", qp)
    jump = qp.B @ sol.x                     # the normal opening at each doubled node
    x = qp.geometry.nodes[0, qp.interface.lower] - L / 2
    exact = 4 * (1 - NU ** 2) / E * np.sqrt(np.maximum(A ** 2 - x ** 2, 0.0))
    k = np.abs(x) <= 0.8 * A
    w = qp.weights[k]
    err = float(np.sqrt(np.sum(w * (jump[k] - exact[k]) ** 2) / np.sum(w * exact[k] ** 2)))
    return {"tip_size": tip, "size_growth": growth, "ndof": int(qp.n), "defect_nodes": int(qp.B.shape[0]),
            "error": err, "status": sol.status.value}


def refine(runs: Path) -> None:
    for g in GROWTHS:
        for tip in TIPS:
            row = griffith(tip, g)
            _append(runs, {"stage": "refine", **row})
            print(f"[refine] growth {g} tip {tip}: {row['ndof']} unknowns, error {row['error']:.4f} "
                  f"({row['status']})", file=sys.stderr, flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="dualfem-results/networks")
    ap.add_argument("--stages", nargs="*", default=["files", "solve", "checks", "refine"])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each 400-crack scene (median)")
    ap.add_argument("--cracks", nargs="*", type=int, default=None, help="solve only these scenes (400, 2000)")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--report", default=None, metavar="DIR", help="write DIR/networks.md and its figure")
    a = ap.parse_args()
    out = Path(a.out)
    runs = out / "runs.jsonl"
    if not a.render_only:
        out.mkdir(parents=True, exist_ok=True)
        meta = {"machine": platform.node(), "cpu": platform.processor() or platform.machine(),
                "cores": os.cpu_count(), "python": platform.python_version(),
                "started_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
        (out / "meta.json").write_text(json.dumps(meta, indent=1))
        if "files" in a.stages or "solve" in a.stages:
            files(out)
        if "solve" in a.stages:
            solve(out, runs, a.repeat, a.cracks)
        if "checks" in a.stages:
            checks(runs)
        if "refine" in a.stages:
            refine(runs)
    if a.report:
        from networks_report import render  # benchmarks/networks_report.py

        render(_load(runs), json.loads((out / "meta.json").read_text()), Path(a.report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
