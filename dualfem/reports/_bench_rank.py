"""Ranking of every solver of a sweep per tolerance tier and per delta (``dualfem report bench``).

For each tier (and each delta within it): success rate, qpbenchmark's correct rate of ``solved``
claims (:mod:`dualfem.reports._correct_rate`), and the shifted geometric mean of time. Render
only: everything comes from the rows of ``results.csv``.

Time of a run = setup + solve (s). A run that is not a success is shown as a failure (the success
rate), never charged a time: the shifted geometric mean exp(mean(log(t + shift))) - shift of a solver
is over its successful runs only, with their number beside it, normalised to the best solver of the
table (1.00 = best). qpbenchmark's convention (every scene that all ranked solvers ran, a run that is
not a success counted at its time limit) is a separate column labelled so.
"""
from __future__ import annotations

import math
from collections import defaultdict

from dualfem.reports._bench_util import _f, _fmt
from dualfem.reports._correct_rate import DEFINITION, SUCCESS, certified_correct, claim_stats, pct


def _sgm(times: list[float], shift: float) -> float:
    if not times:
        return float("nan")
    return math.exp(sum(math.log(t + shift) for t in times) / len(times)) - shift


def _delta(r: dict) -> float:
    return _f(r.get("scene_delta"))


def rank_table(runs: list[dict], tier: str, tol: float, shift: float,
               delta: float | None = None) -> tuple[list[dict], int]:
    """Per-variant statistics at one tier (rows of ``tier`` plus tolerance-free ``any`` rows), optionally
    only the scenes with ``scene_delta == delta``; sorted best first (success, then time, then correct
    rate). Returns (stats, number of scenes every variant ran)."""
    rows = [r for r in runs if r["tier"] in (tier, "any") and r["status"] != "skipped"
            and (delta is None or math.isclose(_delta(r), delta, rel_tol=1e-9))]
    by_var: dict[str, dict[str, dict]] = defaultdict(dict)
    for r in rows:
        by_var[r["variant"]][str(r["scene_key"])] = r
    if not by_var:
        return [], 0
    common = set.intersection(*(set(d) for d in by_var.values()))
    stats = []
    for var, d in by_var.items():
        st = claim_stats(d.values(), tol)
        qpb = []
        for key in sorted(common):
            r = d[key]
            t, tl = _f(r.get("total_s")), _f(r.get("time_limit"))
            qpb.append(t if _success(r, tol) and math.isfinite(t) else (tl if math.isfinite(tl) else t))
        qpb = [t for t in qpb if math.isfinite(t)]
        times = [t for r in d.values() if _success(r, tol) and math.isfinite(t := _f(r.get("total_s")))]
        st.update(variant=var, n=st["runs"], success=st["success_rate"], correct=st["correct_rate"],
                  n_timed=len(times), sgm=_sgm(times, shift), gm=_sgm([max(t, 1e-6) for t in times], 0.0),
                  sgm_qpb=_sgm(qpb, shift))
        stats.append(st)
    for key in ("sgm", "gm", "sgm_qpb"):
        best = min((s[key] for s in stats if math.isfinite(s[key])), default=float("nan"))
        for s in stats:
            s[key + "_rel"] = s[key] / best if best and math.isfinite(best) and best > 0 else float("nan")
    stats.sort(key=lambda s: (-(s["success"] if math.isfinite(s["success"]) else -1),
                              s["sgm"] if math.isfinite(s["sgm"]) else math.inf,
                              -(s["correct"] if math.isfinite(s["correct"]) else -1), s["variant"]))
    return stats, len(common)


def _success(r: dict, tol: float) -> bool:
    """A certified correct run within its time limit (the success rate's numerator)."""
    return certified_correct(r, tol) and r["status"] != "time_limit"


def _wrong(s: dict) -> str:
    parts = [f"{s[k]} {k.replace('_', ' ')}" for k in ("demoted", "flagged", "silent_wrong") if s[k]]
    return (", ".join(parts) or "0") + (f" (+{s['unverified']} unverified)" if s["unverified"] else "")


def _tier_section(runs: list[dict], tier: str, tol: float, shift: float, deltas: list[float]) -> list[str]:
    stats, ncommon = rank_table(runs, tier, tol, shift)
    if not stats:
        return []
    L = [f"### tier {tier} (tol {tol:g})", "",
         "All deltas. Time: shifted geometric mean over each solver's successful runs (how many in brackets); "
         + (f"the last column is qpbenchmark's convention over the {ncommon} scenes every solver of this tier ran, "
            "a run that is not a success counted at its time limit." if ncommon else
            "no scene was run by every solver of this tier: the qpbenchmark-convention column is n/a."), "",
         "| rank | solver | runs | success rate | solved claims | certified correct | correct rate | claims agree "
         "| wrong claims | shifted GM of time of successes (rel.) | plain GM (rel.) "
         "| qpbenchmark convention: failures at the time limit (rel.) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for i, s in enumerate(stats, 1):
        over = f" ({s['over_time']} over time)" if s["over_time"] else ""
        L.append(f"| {i} | {s['variant']} | {s['runs']} | {pct(s['success'])} | {s['claims']} | {s['certified']}{over} "
                 f"| {pct(s['correct'])} | {pct(s['agree'])} | {_wrong(s)} | {_time(s)} | {_fmt(s['gm_rel'], '.2f')} "
                 f"| {_fmt(s['sgm_qpb_rel'], '.2f')} ({_fmt(s['sgm_qpb'])} s) |")
    L.append("")
    if len(deltas) > 1:
        per = {d: {s["variant"]: s for s in rank_table(runs, tier, tol, shift, d)[0]} for d in deltas}
        L += [f"Per delta (tier {tier}): success rate / correct rate / shifted GM of the time of successes relative "
              "to the best solver at that delta (`failed`: no success to time); rows in the order of the table "
              "above.", "",
              "| solver | " + " | ".join(f"delta = {d:g}" for d in deltas) + " |", "|---" * (len(deltas) + 1) + "|"]
        for s in stats:
            cells = []
            for d in deltas:
                x = per[d].get(s["variant"])
                time = _fmt(x['sgm_rel'], '.2f') if x is not None and x["n_timed"] else "failed"
                cells.append("" if x is None else f"{pct(x['success'])} / {pct(x['correct'])} / {time}")
            L.append(f"| {s['variant']} | " + " | ".join(cells) + " |")
        L.append("")
    return L


def _time(s: dict) -> str:
    if not s["n_timed"]:
        return "failed (no success)"
    return f"{_fmt(s['sgm_rel'], '.2f')} ({_fmt(s['sgm'])} s, {s['n_timed']} runs)"


def tiers_of(runs: list[dict]) -> list[tuple[str, float]]:
    """The (tier, tolerance) pairs of the runs, loosest first (tolerance-free ``any`` rows are no tier)."""
    return sorted({(r["tier"], _f(r.get("tol"))) for r in runs if r["tier"] not in ("any", "")}, key=lambda t: -t[1])


def deltas_of(runs: list[dict]) -> list[float]:
    """The deltas of the runs' scenes, largest first."""
    return sorted({_delta(r) for r in runs if math.isfinite(_delta(r))}, reverse=True)


def ranking(runs: list[dict], shift: float) -> list[str]:
    """The section ``Per tolerance tier``: a ranked table per tier, then per delta within it."""
    tiers = tiers_of(runs)
    deltas = deltas_of(runs)
    L = ["## Per tolerance tier and delta", "", DEFINITION + " " + SUCCESS, "",
         f"Solvers are ranked by success rate, then by the shifted geometric mean of time of their successful runs "
         f"(shift {shift:g} s; a failed run is a failure, never a time), then by correct rate. "
         "*wrong claims* splits the checkable solved claims that are not certified correct: *demoted* "
         "(dualfem's certification turned the claim into "
         "`inaccurate`, or the run ended otherwise), *flagged* (status solved to the solver's declared tolerance, "
         "KKT residual above the tier's), *silent wrong* (residuals within tol, answer off the reference); "
         "*unverified* claims (no certified reference) are not wrong claims and not in the correct rate. A "
         "solver without tolerance options (tier `any`) is scored in every "
         "tier with its one run.", ""]
    skipped = defaultdict(set)
    for r in runs:
        if r["status"] == "skipped":
            skipped[r["variant"]].add(str(r.get("message") or "")[:150])
    ran = {r["variant"] for r in runs if r["status"] != "skipped"}
    if set(skipped) - ran:
        L += ["Not run (skipped, so not ranked): " + "; ".join(
            f"`{v}` ({'; '.join(sorted(m))})" for v, m in sorted(skipped.items()) if v not in ran) + ".", ""]
    for tier, tol in tiers:
        L += _tier_section(runs, tier, tol, shift, deltas)
    return L
