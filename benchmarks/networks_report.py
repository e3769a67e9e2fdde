"""reports/networks.md from the runs of benchmarks/networks.py (render only: no solver runs here)."""
from __future__ import annotations

import math
import statistics
from pathlib import Path

from dualfem.post.style import PALETTE


def _median(xs: list[float]) -> float:
    return statistics.median(xs) if xs else math.nan


def _solve_table(rows: list[dict]) -> list[str]:
    out = ["| cracks | source | runs | unknowns | defect nodes | status | wall (s), median | scene to QP (s) | "
           "setup + solve (s) | peak RSS (GB), max | machine load after the run (1 min, 2 cores) |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple[int, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["cracks"], r["source"]), []).append(r)
    for (n, src), rs in sorted(groups.items()):
        res = [r["result"] for r in rs]
        ok = [x for x in res if not x.get("error")]
        status = ", ".join(sorted({x.get("status") or "error" for x in res}))
        t = [x.get("time_s") or {} for x in ok]
        setup_solve = [(d.get("setup") or 0) + (d.get("solve") or 0) for d in t]
        rss = max((x.get("peak_rss_mb") or 0 for x in ok), default=0) / 1024
        first = ok[0] if ok else {}
        out.append(f"| {n:,} | {'CSV file (fractured, defects_file)' if src == 'file' else 'generated (fractured)'} "
                   f"| {len(rs)} | {first.get('ndof') or 0:,} | {first.get('n_defect_nodes') or 0:,} | {status} | "
                   f"{_median([r['wall'] for r in rs]):.1f} | "
                   f"{_median([d.get('assembly', math.nan) for d in t]):.2f} | "
                   f"{_median(setup_solve):.2f} | {rss:.2f} | "
                   f"{_loads(rs)} |")
    return out


def _loads(rs: list[dict]) -> str:
    return ", ".join(f"{r['load1']:.1f}" for r in rs if "load1" in r) or "not recorded"


def _verdict(rows: list[dict]) -> list[str]:
    """What the rows say about the targets, in words (no number here that the table does not hold)."""
    big = [r for r in rows if r["cracks"] == 2000 and r["source"] == "file" and not r["result"].get("error")]
    if not big:
        return []
    wall = _median([r["wall"] for r in big])
    rss = max(r["result"].get("peak_rss_mb") or 0 for r in big) / 1024
    time_ok = "met" if wall <= 120 else "not met on this run"
    return [f"2,000 cracks from the file: median wall time {wall:.0f} s (target <= 120 s: {time_ok}), peak memory "
            f"{rss:.1f} GB (target <= 12 GB: {'met' if rss <= 12 else 'not met'}). Both sources give the same QP "
            "(the same unknowns and defect nodes here; bit-identical K, F, B in tests/test_networks.py), so a "
            "difference between their times is the machine's, not the file's: the two cores were shared with "
            "other jobs (load column; where it reads 'not recorded' the run predates the record). The solve "
            "times of the generated scenes in reports/fractured.md, measured at a lower load, are the "
            "reference for the scene itself."]


def _ratio(rows: list[dict], n: int) -> str:
    walls = {src: _median([r["wall"] for r in rows if r["cracks"] == n and r["source"] == src])
             for src in ("file", "generated")}
    if not all(math.isfinite(v) for v in walls.values()):
        return "not measured"
    return f"{walls['file'] / walls['generated']:.3f}"


def _refine_table(rows: list[dict]) -> list[str]:
    growths = sorted({r["size_growth"] for r in rows}, reverse=True)
    tips = sorted({r["tip_size"] for r in rows}, reverse=True)
    by = {(r["size_growth"], r["tip_size"]): r for r in rows}
    head = "| tip_size / a | " + " | ".join(f"size_growth {g:g}: unknowns, error (ratio)" for g in growths) + " |"
    out = [head, "|---|" + "---|" * len(growths)]
    for k, t in enumerate(tips):
        cells = []
        for g in growths:
            r = by.get((g, t))
            if not r:
                cells.append("-")
                continue
            prev = by.get((g, tips[k - 1])) if k else None
            ratio = f" ({r['error'] / prev['error']:.2f})" if prev else ""
            cells.append(f"{r['ndof']:,}, {r['error']:.4f}{ratio}" + ("" if r["status"] == "solved" else
                                                                      f" [{r['status']}]"))
        out.append(f"| {t:g} | " + " | ".join(cells) + " |")
    return out


def _figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    markers = "osD^v"
    for i, g in enumerate(sorted({r["size_growth"] for r in rows}, reverse=True)):
        rs = sorted((r for r in rows if r["size_growth"] == g), key=lambda r: -r["tip_size"])
        ax.plot([r["tip_size"] for r in rs], [r["error"] for r in rs], marker=markers[i % len(markers)],
                color=PALETTE[i % len(PALETTE)], label=f"size_growth = {g:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("tip_size / a (mesh_size 5 a fixed)")
    ax.set_ylabel("opening error (relative L2, |x| <= 0.8 a)")
    ax.set_title("Griffith crack: refinement at the tips with a fixed size_growth", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render(rows: list[dict], meta: dict, report_dir: Path) -> Path:
    """Write ``report_dir/networks.md`` (and ``report_dir/networks/refinement.png``) from the runs."""
    solve = [r for r in rows if r.get("stage") == "solve"]
    checks = [r for r in rows if r.get("stage") == "checks"]
    refine = [r for r in rows if r.get("stage") == "refine"]
    lines = ["# Fracture networks from files", "",
             "Generated by `python benchmarks/networks.py --out benchmarks/results/networks --report reports` "
             f"(started {meta.get('started_utc', '?')}, {meta.get('cores', '?')} cores shared with other jobs, "
             f"Python {meta.get('python', '?')}); the scenes, the file format and the keys: docs/fractured.md.", ""]
    if solve:
        lines += ["## A network from a CSV file against the generated scene", "",
                  "The cracks of the `fractured` scenes of benchmarks/fractured.toml (seed 1, load f1; 400 cracks of "
                  "length 0.025 at mesh_size 0.003, 2,000 of length 0.012 at 0.0014) written by "
                  "`write_defects(path, random_cracks(...), 2)` and read back by a scene file "
                  "`problem = \"fractured\"`, `defects_file = \"network400.csv\"`. Each run is the whole "
                  "`dualfem solve ... --solver mprgp --json` "
                  "in its own process (import, reading, checks, meshing, assembly, solve, certification); runs of the "
                  "two sources alternate. `scene to QP` is the command's own `assembly` time (reading the file, the "
                  "checks, gmsh, the node doubling, the stiffness).", "",
                  *_solve_table(solve), "",
                  f"Wall time, file / generated (medians): 400 cracks {_ratio(solve, 400)}, 2,000 cracks "
                  f"{_ratio(solve, 2000)} (target: within 10 %, and 2,000 cracks in <= 120 s, <= 12 GB).", "",
                  *_verdict(solve), ""]
    if checks:
        lines += ["## The geometry checks alone (before meshing), median of 3", "",
                  "| what | seconds |", "|---|---|", *[f"| {r['what']} | {r['seconds']:.3f} |" for r in checks], ""]
    if refine:
        _figure(refine, report_dir / "networks" / "refinement.png")
        lines += ["## Refinement with `size_growth`", "",
                  "A Griffith crack (half-length a, body 100 a x 100 a, plane strain, E = 1000, nu = 0.3, remote "
                  "tension 1 normal to it, delta = 1e3: open), `mesh_size` 5 a, `tip_size` halved; the opening's "
                  "relative L2 error over |x| <= 0.8 a against 4 (1 - nu^2) sigma / E sqrt(a^2 - x^2), solved by "
                  "pdas (status `solved`: certified). In parentheses: the error over the previous level's.", "",
                  *_refine_table(refine), "", "![refinement](networks/refinement.png)", ""]
    report_dir.mkdir(parents=True, exist_ok=True)
    path = report_dir / "networks.md"
    path.write_text("\n".join(lines))
    return path
