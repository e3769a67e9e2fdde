"""The correct-rate tables of ``dualfem report stability``: how far each solver's ``solved`` can be trusted.

Per solver over the whole stress grid, then per solver and axis; definitions in
:mod:`dualfem.reports._correct_rate` (the tolerance is the one each solver instance declares,
the grade the one stored in each run's record by :func:`dualfem.verify.grading.grade`).
"""
from __future__ import annotations

import math
from collections import defaultdict

from dualfem.reports._correct_rate import DEFINITION, claim_stats, pct

AXES_ORDER = ("delta", "r", "units", "load", "nu", "N")


def solver_stats(recs: list) -> list[dict]:
    """:func:`claim_stats` per solver (grades as recorded), best correct rate first; solvers whose runs
    were all skipped come last with ``runs == 0``."""
    by = defaultdict(list)
    for r in recs:
        by[r["solver"]].append(r)
    out = [{"solver": s, **claim_stats(rs)} for s, rs in by.items()]

    def key(s: dict) -> tuple:
        rate = s["correct_rate"]
        return (s["runs"] == 0, -(rate if math.isfinite(rate) else -1.0), -s["claims"], s["solver"])

    return sorted(out, key=key)


def correct_rate_section(recs: list) -> list[str]:
    """Markdown: the per-solver table, then the per-axis table (certified / claims per cell)."""
    stats = solver_stats(recs)
    ran = [s for s in stats if s["runs"]]
    L = ["## Correct rate of solved claims", "",
         DEFINITION.replace("<= tol", "<= t") + " Here tol = t, the tolerance each solver instance declares (the "
         "grading above); skipped runs are not counted.", "",
         "| rank | solver | runs | solved claims | certified correct | correct rate | claims agree | demoted by "
         "certification | flagged | silent wrong | unverified |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for i, s in enumerate(ran, 1):
        L.append(f"| {i} | {s['solver']} | {s['runs']} | {s['claims']} | {s['certified']} | {pct(s['correct_rate'])} "
                 f"| {pct(s['agree'])} | {s['demoted']} | {s['flagged']} | {s['silent_wrong']} | {s['unverified']} |")
    L.append("")
    legacy = sum(1 for r in recs if r.get("claimed_status") is None and r.get("status") != "skipped")
    if legacy:
        L += [f"{legacy} runs were recorded before dualfem kept the solver's own claim (`claimed_status`): for them "
              "the claim is read from the certified status, so a claim that the certification demoted counts as an "
              "honest failure, not as a wrong claim (rerun `dualfem stress` to record it).", ""]
    idle = [s["solver"] for s in stats if not s["runs"]]
    if idle:
        L += ["Every run skipped (not installed, or not applicable): " + ", ".join(f"`{s}`" for s in idle) + ".", ""]
    axes = [a for a in AXES_ORDER if any(r["axis"] == a for r in recs)]
    axes += sorted({str(r["axis"]) for r in recs} - set(axes))
    if len(axes) > 1 and ran:
        L += ["Per axis: certified correct / checkable solved claims (correct rate); empty: no run on that axis, "
              "`0/0`: no checkable solved claim.", "",
              "| solver | " + " | ".join(axes) + " |", "|---" * (len(axes) + 1) + "|"]
        for s in ran:
            cells = []
            for a in axes:
                st = claim_stats([r for r in recs if r["solver"] == s["solver"] and r["axis"] == a])
                checked = st["claims"] - st["unverified"]
                cells.append("" if not st["runs"] else
                             f"{st['certified']}/{checked}" + (f" ({pct(st['correct_rate'])})" if checked else ""))
            L.append(f"| {s['solver']} | " + " | ".join(cells) + " |")
        L.append("")
    return L
