"""End to end: the whole `dualfem solve` process against the floor, per N (issue 17's table).

For each N: the floor (the fastest installed library factorization + one solve of K, in its own
process, after assembly) and, per solver and delta, the whole command `dualfem solve f2 --set N=..
--solver S --json --quiet` (wall time of the process, and its own time_s split and peak_rss_mb).
One run each unless --repeat; the machine, threads and load are recorded.

    python benchmarks/end_to_end.py --N 256 512 1024 --solvers pdas uzawa_auto --deltas 1e-5 1e-9 \\
        --out benchmarks/results/end_to_end
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

FLOOR = Path(__file__).resolve().parent / "floor.py"       # the floor, in its own process


def _run(cmd: list[str], env: dict | None = None) -> tuple[float, dict]:
    """(wall time, the command's last JSON line or {"error": its stderr's tail})."""
    env = dict(os.environ, MPLBACKEND="Agg") if env is None else env
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    try:
        return wall, json.loads(r.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return wall, {"error": (r.stderr or r.stdout).strip()[-300:]}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--N", type=int, nargs="+", default=[256, 512, 1024])
    ap.add_argument("--solvers", nargs="+", default=["pdas", "uzawa_auto"])
    ap.add_argument("--deltas", type=float, nargs="+", default=[1e-5, 1e-9])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--out", default="dualfem-results/end_to_end")
    ap.add_argument("--render-only", action="store_true", help="re-render the table and figure of --out")
    ap.add_argument("--report", default=None, metavar="DIR",
                    help="with --render-only: write end_to_end.md and end_to_end/scaling.png into DIR (e.g. reports)")
    ap.add_argument("--force", action="store_true", help="replace the results already in --out")
    a = ap.parse_args()
    if a.render_only:
        rerender(Path(a.out), Path(a.report) if a.report else None)
        return 0
    from dualfem.core.errors import InputError
    from dualfem.core.io import refuse_overwrite

    try:
        refuse_overwrite([Path(a.out) / f for f in ("end_to_end.json", "end_to_end.md", "scaling_end_to_end.png")],
                         a.force)
    except InputError as exc:
        ap.error(str(exc))
    load0 = os.getloadavg()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    rows = []
    for N in a.N:
        fl = [_run([sys.executable, str(FLOOR), "f2", json.dumps({"N": N})]) for _ in range(a.repeat)]
        floor = {"N": N, "kind": "floor", **fl[-1][1],
                 "floor_s": statistics.median(r[1].get("factor", float("nan")) + r[1].get("solve", 0) for r in fl)}
        rows.append(floor)
        print(json.dumps(floor), file=sys.stderr, flush=True)
        for s in a.solvers:
            for d in a.deltas:
                runs = [_run([sys.executable, "-m", "dualfem", "solve", "f2", "--set", f"N={N}", "--set", f"delta={d}",
                              "--solver", s, "--json", "--quiet"]) for _ in range(a.repeat)]
                wall = statistics.median(r[0] for r in runs)
                rec = runs[-1][1]
                t = rec.get("time_s", {})
                row = {"N": N, "kind": "solve", "solver": s, "delta": d, "status": rec.get("status"),
                       "whole_process_s": wall, "assembly_s": t.get("assembly"), "setup_s": t.get("setup"),
                       "solve_s": t.get("solve"), "certify_s": t.get("certify"), "total_s": t.get("total"),
                       "peak_rss_mb": rec.get("peak_rss_mb"), "factor": rec.get("factor"),
                       "threads": rec.get("threads"), "floor_s": floor["floor_s"],
                       "setup_solve_over_floor": ((t.get("setup") or 0) + (t.get("solve") or 0)) / floor["floor_s"],
                       "whole_over_floor": wall / floor["floor_s"], "error": rec.get("error")}
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"loadavg_start": load0, "loadavg_end": os.getloadavg(), "cores": os.cpu_count(), "argv": sys.argv[1:],
            "started": started, "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    from dualfem.core.io import atomic_write_text

    atomic_write_text(out / "end_to_end.json", json.dumps({"meta": meta, "rows": rows}, indent=1))
    atomic_write_text(out / "end_to_end.md", render(rows, meta))
    figure(rows, out / "scaling_end_to_end.png")
    print(render(rows, meta))
    return 0


def _f(v, fmt=".2f") -> str:
    return "-" if v is None else format(v, fmt)


def render(rows: list[dict], meta: dict) -> str:
    """The table of the issue: per N, solver, delta: assembly, setup, solve, certify, whole process, peak, floor."""
    L = ["# End to end: `dualfem solve f2` against the floor", "",
         f"Generated by `python benchmarks/end_to_end.py {' '.join(meta['argv'])}` ({meta['started']} to "
         f"{meta['finished']}); cores {meta['cores']}, load average at start {meta['loadavg_start'][0]:.1f}, "
         f"at end {meta['loadavg_end'][0]:.1f}. One run each. **floor** = factorization + one solve of K by "
         "the fastest installed backend in its own process (after assembly). **whole process** = wall time of "
         "the command `dualfem solve f2 --set N=.. --set delta=.. --solver .. --json --quiet` (Python start, "
         "imports, assembly, setup, solve, certification, output); its parts from the command's own JSON "
         "`time_s`; peak = its `peak_rss_mb`.", "",
         "| N | unknowns | solver | delta | status | assembly | setup | solve | certify | whole process | peak MB "
         "| floor (backend) | (setup+solve)/floor | whole/floor |", "|---" * 14 + "|"]
    floors = {r["N"]: r for r in rows if r["kind"] == "floor"}
    for r in rows:
        if r["kind"] != "solve":
            continue
        f = floors[r["N"]]
        L.append(f"| {r['N']} | {f.get('n', 0):,} | {r['solver']} | {r['delta']:g} | {r['status']} | "
                 f"{_f(r['assembly_s'])} | {_f(r['setup_s'])} | {_f(r['solve_s'])} | {_f(r['certify_s'])} | "
                 f"{_f(r['whole_process_s'], '.1f')} | {_f(r['peak_rss_mb'], '.0f')} | {f['floor_s']:.2f} "
                 f"({f.get('backend')}) | {r['setup_solve_over_floor']:.2f} | {r['whole_over_floor']:.2f} |")
    L += ["", "![scaling](scaling_end_to_end.png)", ""]
    return "\n".join(L)


def figure(rows: list[dict], path: Path) -> None:
    """Time and peak memory against the number of unknowns (log-log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    floors = sorted((r for r in rows if r["kind"] == "floor"), key=lambda r: r["N"])
    fig, (ax, am) = plt.subplots(1, 2, figsize=(11, 4.2))
    n = [r["n"] for r in floors]
    ax.loglog(n, [r["floor_s"] for r in floors], "k--", label=f"floor ({floors[0].get('backend')} factor + solve of K)")
    keys = sorted({(r["solver"], r["delta"]) for r in rows if r["kind"] == "solve"})
    for s, d in keys:
        rs = sorted((r for r in rows if r["kind"] == "solve" and r["solver"] == s and r["delta"] == d),
                    key=lambda r: r["N"])
        nn = [next(f["n"] for f in floors if f["N"] == r["N"]) for r in rs]
        ln, = ax.loglog(nn, [r["whole_process_s"] for r in rs], "o-", label=f"{s} delta={d:g}: whole process")
        ax.loglog(nn, [(r["setup_s"] or 0) + (r["solve_s"] or 0) for r in rs], "s:", color=ln.get_color(),
                  label=f"{s} delta={d:g}: setup + solve")
        am.loglog(nn, [r["peak_rss_mb"] / 1024 for r in rs], "o-", color=ln.get_color(), label=f"{s} delta={d:g}")
    ax.set_xlabel("unknowns")
    ax.set_ylabel("seconds")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    am.set_xlabel("unknowns")
    am.set_ylabel("peak RSS (GiB)")
    am.grid(True, which="both", alpha=0.3)
    am.legend(fontsize=7)
    fig.suptitle("f2, plane strain: the whole `dualfem solve` command against the floor")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def rerender(folder: Path, report: Path | None = None) -> None:
    """Re-render end_to_end.md and the figure from end_to_end.json (into ``report`` if given)."""
    from dualfem.core.io import atomic_write_text

    data = json.loads((folder / "end_to_end.json").read_text())
    if report is None:
        atomic_write_text(folder / "end_to_end.md", render(data["rows"], data["meta"]))
        figure(data["rows"], folder / "scaling_end_to_end.png")
        return
    (report / "end_to_end").mkdir(parents=True, exist_ok=True)
    text = render(data["rows"], data["meta"]).replace("](scaling_end_to_end.png)", "](end_to_end/scaling.png)")
    text = text.replace("Generated by `python benchmarks/end_to_end.py", "Data from `python benchmarks/end_to_end.py")
    text += (f"\nRendered by `python benchmarks/end_to_end.py --render-only --out {folder} --report {report}` "
             f"from `{folder}/end_to_end.json`.\n")
    atomic_write_text(report / "end_to_end.md", text)
    figure(data["rows"], report / "end_to_end" / "scaling.png")


if __name__ == "__main__":
    sys.exit(main())
