"""``dualfem report bench RESULTS``: reports/benchmark.md and PNG figures from a sweep's results.

RESULTS is a ``results.csv`` written by ``dualfem bench`` (or its directory); several RESULTS
are merged into one report, a later one replacing the rows of an earlier one that measure the same
thing (a run: scene, solver variant and tier; a floor: its group of scenes; a reference: its
scene), e.g. a quick parallel sweep followed by a serial sweep of the large sizes. Definitions used
in the report (also printed in it):

* time of a run = setup + solve (median over the timed repeats; the factorization cache of
  :mod:`dualfem.linalg` is cleared before every repeat when the sweep had ``cold_setup``);
* success at a tier of tolerance tol = the solver's status is ``solved`` AND the evaluator's
  largest KKT residual is <= tol;
* correct = the solver's claim agrees with the evaluator: (status == solved) == (KKT <= tol);
* shifted geometric mean of time (qpbenchmark): exp(mean(log(t + 10))) - 10 with t in seconds,
  failures counted at the time limit, over the scenes that every solver of the tier ran;
  normalised to the best solver of the tier (1.00 = best).
"""
from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from pathlib import Path

from dualfem.cli.report import register_report
from dualfem.core.errors import InputError
from dualfem.reports._bench_plots import plots
from dualfem.reports._bench_targets import targets
from dualfem.reports._bench_util import _f, _fmt


def _sgm(times: list[float], shift: float) -> float:
    if not times:
        return float("nan")
    return math.exp(sum(math.log(t + shift) for t in times) / len(times)) - shift


def tier_table(runs: list[dict], tier: str, tol: float, shift: float) -> tuple[list[dict], int]:
    """Per-variant statistics at one tier (rows of tier ``tier`` plus tolerance-free 'any' rows)."""
    rows = [r for r in runs if r["tier"] in (tier, "any") and r["status"] != "skipped"]
    by_var: dict[str, dict[str, dict]] = defaultdict(dict)
    for r in rows:
        by_var[r["variant"]][r["scene_key"]] = r
    if not by_var:
        return [], 0
    common = set.intersection(*(set(d) for d in by_var.values()))
    stats = []
    for var, d in sorted(by_var.items()):
        n = len(d)
        succ = corr = 0
        times = []
        for key, r in d.items():
            k = _f(r.get("kkt_error"))
            within = math.isfinite(k) and k <= tol
            claims = r["status"] == "solved"
            ok = claims and within
            succ += ok
            corr += claims == within
            if key in common:
                tl = _f(r.get("time_limit"))
                t = _f(r.get("total_s"))
                times.append(t if ok and math.isfinite(t) else (tl if math.isfinite(tl) else t))
        stats.append({"variant": var, "n": n, "success": succ / n, "correct": corr / n,
                      "sgm": _sgm([t for t in times if math.isfinite(t)], shift),
                      "gm": _sgm([max(t, 1e-6) for t in times if math.isfinite(t)], 0.0)})
    for key in ("sgm", "gm"):
        best = min((s[key] for s in stats if math.isfinite(s[key])), default=float("nan"))
        for s in stats:
            s[key + "_rel"] = s[key] / best if best and math.isfinite(best) and best > 0 else float("nan")
    return stats, len(common)



def _slot(r: dict) -> tuple:
    """What a row measures: rows of two sweeps with the same slot measure the same thing."""
    if r["kind"] == "run":
        return ("run", str(r.get("scene_key")), r["variant"], r["tier"])
    if r["kind"] == "floor":
        return ("floor", str(r.get("label")), _f(r.get("n_unknowns")))
    return (str(r["kind"]), str(r.get("scene_key")))


def load_sources(results: list[str | Path]) -> tuple[list[dict], list[dict]]:
    """Rows of several results (later ones replace earlier rows of the same slot) and one
    source record per results (path, directory, sweep.json, rows kept)."""
    from dualfem.experiments.store import read_results

    merged: dict[tuple, dict] = {}
    sources = []
    for i, item in enumerate(results):
        rows = read_results(item)
        if not rows:
            raise InputError(f"results file {str(item)!r} has no rows")
        res_path = Path(item)
        res_dir = res_path if res_path.is_dir() else res_path.parent
        meta = {}
        if (res_dir / "sweep.json").is_file():
            try:
                meta = json.loads((res_dir / "sweep.json").read_text(encoding="utf-8"))
            except ValueError:
                meta = {}
        for r in rows:
            r["tier"] = str(r.get("tier")) if r.get("tier") is not None else ""
            r["variant"] = str(r.get("variant") or r.get("solver"))
            r["solver"] = str(r.get("solver"))
            r["_source"] = i
            merged[_slot(r)] = r
        sources.append({"results": str(item), "dir": res_dir, "meta": meta, "n_rows": len(rows)})
    rows = list(merged.values())
    for i, src in enumerate(sources):
        src["kept"] = sum(r["_source"] == i for r in rows)
    return rows, sources

def _header(results: list, sources: list[dict], rows: list[dict], command: str) -> list[str]:
    """Title, the command, and one line per merged results directory."""
    L = ["# Benchmark: run time against error", ""]
    names = " ".join(str(x) for x in results)
    L.append(f"Generated by `{command or 'dualfem report bench ' + names}` from "
             + ", ".join(f"`{x}`" for x in results) + ".")
    if len(sources) > 1:
        L.append(f"The rows of {len(sources)} sweeps are merged: where two sweeps measured the same thing "
                 "(a run: scene, solver variant and tier; a floor; a reference), the later one on the command "
                 "line replaces the earlier one.")
    L.append("")
    for i, src in enumerate(sources):
        meta = src["meta"]
        tag = f"[{i + 1}] " if len(sources) > 1 else ""
        sizes = sorted({_f(r.get("scene_N")) for r in rows if r["_source"] == i and r["kind"] == "run"
                        and math.isfinite(_f(r.get("scene_N")))})
        kept = (f" {src['kept']} of its {src['n_rows']} rows are in this report (N = "
                f"{', '.join(f'{n:g}' for n in sizes)})." if len(sources) > 1 else "")
        if meta.get("command"):
            L.append(f"- {tag}`{src['results']}` was produced by `{meta['command']}` (spec `{meta.get('spec')}`, "
                     f"jobs {meta.get('jobs')}, dask {meta.get('dask') or 'no'}; started {meta.get('started_utc')}, "
                     f"finished {meta.get('finished_utc', 'not finished')}).{kept}")
        else:
            L.append(f"- {tag}`{src['results']}` (no sweep.json beside it).{kept}")
        inv = meta.get("invocations") or []
        if len(inv) > 1:
            L.append(f"  This results directory was written by {len(inv)} invocations (a resumed or extended "
                     "sweep; results.csv keeps the rows of the current spec only): "
                     + "; ".join(f"`{x['command']}` at {x['started_utc']}" for x in inv) + ".")
    return L + [""]


def _machine(rows: list[dict], sources: list[dict]) -> list[str]:
    """Machine, versions and the load average while the sweeps ran."""
    L = ["## Machine and versions", ""]
    mach = defaultdict(set)
    for r in rows:
        for k in ("cpu", "cores", "affinity", "threads", "python", "platform", "versions", "git"):
            if r.get(k) is not None:
                mach[k].add(str(r[k]))
    for k in ("cpu", "cores", "affinity", "threads", "python", "platform", "git"):
        L.append(f"- {k}: {'; '.join(sorted(mach.get(k, {'?'})))}")
    for i, src in enumerate(sources):
        loads = sorted(_f(r.get("loadavg")) for r in rows
                       if r["_source"] == i and math.isfinite(_f(r.get("loadavg"))))
        if loads:
            jobs = src["meta"].get("jobs")
            which = f" ([{i + 1}], jobs {jobs})" if len(sources) > 1 else ""
            L.append(f"- 1-minute load average when a task started{which}"
                     f": min {loads[0]:.1f}, median {loads[len(loads) // 2]:.1f}, max {loads[-1]:.1f} (the sweep's "
                     "own workers count; above the core count, processes shared the machine and every time is "
                     "inflated: compare ratios measured together, not seconds)")
    for v in sorted(mach.get("versions", [])):
        try:
            L.append("- versions: " + ", ".join(f"{a} {b}" for a, b in sorted(json.loads(v).items())))
        except ValueError:
            L.append(f"- versions: {v}")
    return L + [""]


def _method(runs: list[dict], shift: float) -> list[str]:
    cold = {str(r.get("cold_setup")) for r in runs}
    reps = sorted({str(r.get("repeats")) for r in runs})
    return ["## How it was measured", "",
            f"- Time of a run = setup (assembly of solver data, scaling, factorizations) + solve, median of "
            f"{'/'.join(reps)} timed repeats after one untimed warm-up run (per scene block of the spec). "
            f"Assembly of the QP itself (scikit-fem) is excluded and recorded separately (`assembly_s`).",
            f"- Cold setup: {'yes' if cold == {'True'} else 'no' if cold == {'False'} else 'mixed'} - "
            "`dualfem.linalg.clear_cache()` is called before every timed repeat, so a solver that factorizes "
            "K_fixed pays for it in every repeat (the cache that shares it across delta and loads is not "
            "allowed to hide it).",
            "- Floor: one sparse factorization + one solve of the unconstrained K of the same size (scipy "
            "`splu` with `permc_spec=\"MMD_AT_PLUS_A\"`, symmetric mode; CHOLMOD too when scikit-sparse is "
            "installed, the faster one is the floor).",
            "- Errors: against a reference per scene, solved once by a certified exact solver and checked by "
            "the evaluator (KKT error below the spec's `reference.certify`); relative energy-norm error of x, "
            "relative max error of the multipliers, relative objective gap. A run of the reference's own solver "
            "is compared against itself (error 0 or near): its accuracy is certified by the KKT residuals only.",
            f"- Success at a tier: status solved and the evaluator's KKT error <= the tier's tolerance. Correct: "
            f"(status == solved) == (KKT error <= tolerance). Shifted geometric mean of time: shift {shift:g} s, "
            "failures counted at the time limit, over the scenes every solver of the tier ran, normalised to the "
            "best (1.00). Solvers without tolerance options (tier `any`) are scored in every tier with one run.",
            "- Failed runs (error, time_limit, max_iter, ...) are rows with their status and message, never "
            "results: they have no error columns unless the solver returned an iterate.", ""]


def _cached_references(sources: list[dict]) -> list[tuple[str, float]]:
    """(solver, KKT error) of every reference in the results directories' refs/ caches."""
    import numpy as np

    cached = {}
    for src in sources:
        if (src["dir"] / "refs").is_dir():
            for f in sorted((src["dir"] / "refs").glob("[!.]*.npz")):
                try:
                    with np.load(f, allow_pickle=False) as d:
                        cached[f.name] = (str(d["solver"]), float(d["kkt"]))
                except (OSError, ValueError, KeyError):
                    continue
    return list(cached.values())


def _references(refs: list[dict], sources: list[dict]) -> list[str]:
    L = ["## References", ""]
    ok_refs = [r for r in refs if r["status"] == "solved"]
    L.append(f"{len(ok_refs)} certified references computed in this results directory "
             f"({', '.join(sorted({r['solver'] for r in ok_refs})) or 'none'}); references cached by an earlier "
             "sweep are not listed again.")
    if ok_refs:
        ks = [_f(r.get("kkt_error")) for r in ok_refs]
        L.append(f"KKT error of the references: max {_fmt(max(ks), '.1e')}, "
                 f"median {_fmt(sorted(ks)[len(ks) // 2], '.1e')}.")
    cached = _cached_references(sources)
    if cached:
        ks = sorted(k for _, k in cached)
        where = "these results directories" if len(sources) > 1 else "this results directory"
        L.append(f"Reference cache of {where}: {len(cached)} certified references "
                 f"({', '.join(sorted({s for s, _ in cached}))}), evaluator KKT error max {ks[-1]:.1e}, "
                 f"median {ks[len(ks) // 2]:.1e}.")
    L += [f"- NO certified reference for {r['label']}: {r.get('message')}" for r in refs if r["status"] != "solved"]
    return L + [""]


def _tiers(runs: list[dict], shift: float) -> list[str]:
    tiers = sorted({(r["tier"], _f(r.get("tol"))) for r in runs if r["tier"] not in ("any", "")},
                   key=lambda t: -t[1])
    L = ["## Per tolerance tier", ""]
    for tier, tol in tiers:
        stats, ncommon = tier_table(runs, tier, tol, shift)
        L += [f"### tier {tier} (tol {tol:g})", "",
              f"Shifted geometric means over {ncommon} scenes that every solver of this tier ran.", "",
              "| solver | runs | success rate | correct rate | shifted GM of time (rel.) | plain GM of time (rel.) |",
              "|---|---|---|---|---|---|"]
        L += [f"| {s['variant']} | {s['n']} | {100 * s['success']:.0f} % | {100 * s['correct']:.0f} % "
              f"| {_fmt(s['sgm_rel'], '.2f')} ({_fmt(s['sgm'])} s) | {_fmt(s['gm_rel'], '.2f')} |" for s in stats]
        L.append("")
    return L


def _figures(wp: list[str], sc: list[str], figrel, ok_solvers: list[str]) -> list[str]:
    """Work-precision (largest N per scene inline, the others linked) and scaling figures."""
    L = ["## Work-precision", "",
         "Relative energy-norm error of x against time (setup + solve), one curve per solver through its "
         "tiers; hollow markers: status not solved; dashed line: the floor. Errors below 1e-16 are drawn at 1e-16."
         + (f" The references were computed by {', '.join(ok_solvers)}: that solver's "
            "own runs agree with them by construction (error near 0), their accuracy is the KKT error in the "
            "tier tables." if ok_solvers else ""), ""]
    largest = {}
    for name in wp:
        load, n = name[3:-4].rsplit("_N", 1)
        if int(n) >= largest.get(load, (0, ""))[0]:
            largest[load] = (int(n), name)
    for load, (n, name) in sorted(largest.items()):
        L += [f"![work-precision {load} N={n}]({figrel}/{name})", ""]
    others = [n for n in wp if n not in {v[1] for v in largest.values()}]
    if others:
        L += ["Other sizes: " + ", ".join(f"[{n[3:-4]}]({figrel}/{n})" for n in others), ""]
    L += ["## Scaling", "",
          "Time of the tightest solved tier against the number of unknowns; dashed: the floor (one "
          "factorization + one solve of K), dotted: 1.5 x the floor.", ""]
    for name in sc:
        L += [f"![scaling {name[8:-4]}]({figrel}/{name})", ""]
    return L


def _statuses(runs: list[dict]) -> list[str]:
    L = ["## Statuses", ""]
    variants = sorted({r["variant"] for r in runs})
    statuses = sorted({r["status"] for r in runs})
    L += ["| solver | " + " | ".join(statuses) + " |", "|---|" + "---|" * len(statuses)]
    for v in variants:
        cnt = defaultdict(int)
        for r in runs:
            if r["variant"] == v:
                cnt[r["status"]] += 1
        L.append(f"| {v} | " + " | ".join(str(cnt[s]) for s in statuses) + " |")
    L.append("")
    msgs = defaultdict(list)
    for r in runs:
        if r["status"] not in ("solved",):
            msgs[(r["variant"], r["status"], str(r.get("message") or "")[:160])].append(r["label"])
    if msgs:
        L += ["Messages of the runs that did not end solved (first scene of each):", ""]
        L += [f"- {v} / {st} x{len(labels)} ({labels[0]}): {m}" for (v, st, m), labels in sorted(msgs.items())[:60]]
        L.append("")
    return L


def build_report(results: str | Path | list[str | Path], md: str | Path, figdir: str | Path, *,
                 ours: list[str], shift: float = 10.0, err_target: float = 1e-8, floor_target: float = 1.5,
                 speed_target: float = 10.0, command: str = "") -> Path:
    """Write the markdown report and its figures from one or several results; returns the markdown path."""
    from dualfem.core.io import atomic_write_text

    results = [results] if isinstance(results, (str, Path)) else list(results)
    if not results:
        raise InputError("give at least one RESULTS (a results.csv or a sweep's output directory)")
    rows, sources = load_sources(results)
    runs = [r for r in rows if r["kind"] == "run"]
    refs = [r for r in rows if r["kind"] == "reference"]
    floors = [r for r in rows if r["kind"] == "floor"]
    md, figdir = Path(md), Path(figdir)
    wp, sc = plots(runs, floors, figdir)
    try:
        figrel = figdir.resolve().relative_to(md.parent.resolve())
    except ValueError:
        figrel = figdir.resolve()
    L = _header(results, sources, rows, command) + _machine(rows, sources) + _method(runs, shift)
    L += _references(refs, sources) + _tiers(runs, shift) + ["## Performance targets", ""]
    L += targets(runs, floors, ours, err_target, floor_target, speed_target, tag_sources=len(sources) > 1)
    L.append("")
    L += _figures(wp, sc, figrel, sorted({r["solver"] for r in refs if r["status"] == "solved"}))
    L += _statuses(runs)
    atomic_write_text(md, "\n".join(L) + "\n")
    return md


@register_report("bench", "benchmark report (work-precision, scaling, tiers) from a 'dualfem bench' results.csv")
def run(argv: list[str]) -> int:
    import shlex
    import sys

    p = argparse.ArgumentParser(prog="dualfem report bench",
                                description="reports/benchmark.md + PNGs from a dualfem bench results.csv")
    p.add_argument("results", metavar="RESULTS", nargs="+",
                   help="results.csv or a sweep's output directory; several are merged, a later one replacing "
                        "the rows of an earlier one that measure the same thing")
    p.add_argument("--md", default="dualfem-results/reports/benchmark.md",
                   help="markdown output (default dualfem-results/reports/benchmark.md; reports/benchmark.md for the "
                        "committed one)")
    p.add_argument("--figdir", default=None, help="figure directory (default: bench/ beside --md)")
    p.add_argument("--ours", default="uzawa,uzawa_auto,pdas",
                   help="comma-separated solvers checked against the targets")
    p.add_argument("--shift", type=float, default=10.0, help="shift of the geometric mean in seconds (10)")
    p.add_argument("--error", type=float, default=1e-8, help="equal-error level of the targets (1e-8)")
    try:
        a = p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if not (a.shift >= 0 and math.isfinite(a.shift)):
        raise InputError(f"--shift must be a finite number >= 0, got {a.shift}")
    if not (a.error > 0 and math.isfinite(a.error)):
        raise InputError(f"--error must be a finite number > 0, got {a.error}")
    cmd = "dualfem report bench " + " ".join(shlex.quote(x) for x in argv)
    figdir = a.figdir or str(Path(a.md).parent / "bench")
    md = build_report(a.results, a.md, figdir, ours=[s for s in a.ours.split(",") if s], shift=a.shift,
                      err_target=a.error, command=cmd)
    print(f"wrote {md} and figures in {figdir}", file=sys.stderr)
    return 0
