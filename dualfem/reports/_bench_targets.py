"""The "Performance targets" section of ``dualfem report bench``: our solvers against the floor
(one factorization + one solve of K) and against the fastest competitor at equal error."""
from __future__ import annotations

import math

from dualfem.reports._bench_util import COMPETITORS, _f, _fmt, _scene_of


def _scene_txt(sc: tuple) -> str:
    return f"{sc[0]} N={sc[1]:g} delta={sc[2]:g}"


def _unmet(sc: tuple, s: str, srows: list[dict], err_target: float, flt: float, tag) -> tuple[str, str]:
    """(table line, miss) for a solver none of whose claimed runs reached ``err_target``."""
    st = sorted({r["status"] for r in srows if r["solver"] == s}) or ["not run"]
    # accurate but not claimed: the solver's own test did not certify what the reference shows
    quiet = [r for r in srows if r["solver"] == s and _f(r.get("err_x_energy")) <= err_target
             and math.isfinite(_f(r.get("total_s")))]
    if quiet:
        q = min(quiet, key=lambda r: _f(r["total_s"]))
        qt = _f(q["total_s"])
        qr = f"{qt / flt:.2f} x the floor" if math.isfinite(flt) and flt > 0 else "floor n/a"
        return (f"| {sc[0]} | {sc[1]:g} | {sc[2]:g} | {s} | status {q['status']}{tag(q)}: error "
                f"{_f(q['err_x_energy']):.1e} in {qt:.3g} s ({qr}), not claimed by the solver "
                f"| | | {_fmt(flt)} | MISSED | | |",
                f"{s} at {_scene_txt(sc)}: status {q['status']}, although its "
                f"error against the reference is {_f(q['err_x_energy']):.1e} ({qr}): its own "
                f"stopping test could not certify the answer ({str(q.get('message') or '')[:200]})")
    return (f"| {sc[0]} | {sc[1]:g} | {sc[2]:g} | {s} | no run reached {err_target:g} ({', '.join(st)}) "
            f"| | | {_fmt(flt)} | MISSED | | |",
            f"{s} at {_scene_txt(sc)}: no run reached error {err_target:g}")


def _floor_miss(sc: tuple, s: str, best: dict, ratio: float, flt: float, fl: dict, floor_target: float) -> str:
    """Why a run missed the floor target: which of setup and solve dominates."""
    t = _f(best["total_s"])
    su, so = _f(best.get("setup_s")), _f(best.get("solve_s"))
    why = ""
    if math.isfinite(su) and math.isfinite(so) and t > 0:
        part = "setup (matrix factorizations)" if su >= so else "solve (iterations)"
        why = (f"; {part} dominates: setup {su:.3g} s = {su / flt:.2f} x the floor, "
               f"solve {so:.3g} s = {so / flt:.2f} x the floor")
    return (f"{s} at {_scene_txt(sc)}: {ratio:.2f} x the floor "
            f"({ratio / floor_target:.2f} x over the target){why}; floor {_fmt(flt)} s ({fl['solver']})")


def _versus(sc: tuple, s: str, t: float, comp: list[dict], comp_ok: list[dict], err_target: float,
            speed_target: float, tag) -> tuple[str, str, str | None]:
    """(competitor cell, speed-up cell, miss or None) of our time ``t`` against the competitors."""
    if comp_ok:
        cb = min(comp_ok, key=lambda r: _f(r["total_s"]))
        ct = _f(cb["total_s"])
        sp = ct / t
        miss = None if sp >= speed_target else (
            f"{s} at {_scene_txt(sc)}: {sp:.1f} x faster than {cb['variant']} "
            f"(target {speed_target:g} x: {100 * (1 - sp / speed_target):.0f} % short)")
        return (f"{ct:.3g} ({cb['variant']}, tier {cb['tier']}){tag(cb)}",
                f"{sp:.1f}" + (" ok" if sp >= speed_target else " MISSED"), miss)
    if comp:
        slowest = max((_f(r.get("total_s")) for r in comp if math.isfinite(_f(r.get("total_s")))),
                      default=float("nan"))
        if any(r["status"] == "time_limit" for r in comp):
            slowest = max(slowest if math.isfinite(slowest) else 0.0, max(_f(r.get("time_limit")) for r in comp))
        errs = [_f(r.get("err_x_energy")) for r in comp if math.isfinite(_f(r.get("err_x_energy")))]
        be = f"best error {min(errs):.1e}" if errs else "no error measured"
        return (f"none reached {err_target:g} ({be}; statuses {', '.join(sorted({r['status'] for r in comp}))})",
                f"> {slowest / t:.1f} (lower bound)" if math.isfinite(slowest) else "n/a", None)
    return "not run at this size (spec limit or skipped)", "n/a", None


def _scene_lines(sc: tuple, runs, present, fl: dict | None, err_target: float, floor_target: float,
                 speed_target: float, tag) -> tuple[list[str], list[str]]:
    """Table lines and misses of one scene, one line per solver of ``present``."""
    srows = [r for r in runs if _scene_of(r) == sc and r["status"] != "skipped"]
    comp = [r for r in srows if r["solver"] in COMPETITORS]
    comp_ok = [r for r in comp if r["status"] == "solved" and _f(r.get("err_x_energy")) <= err_target]
    flt = _f(fl["total_s"]) if fl else float("nan")
    lines, misses = [], []
    for s in present:
        mine = [r for r in srows if r["solver"] == s and r["status"] == "solved"
                and _f(r.get("err_x_energy")) <= err_target]
        if not mine:
            line, miss = _unmet(sc, s, srows, err_target, flt, tag)
            lines.append(line)
            misses.append(miss)
            continue
        best = min(mine, key=lambda r: _f(r["total_s"]))
        t = _f(best["total_s"])
        ratio = t / flt if math.isfinite(flt) and flt > 0 else float("nan")
        fmark = "" if not math.isfinite(ratio) else (" ok" if ratio <= floor_target else " MISSED")
        if math.isfinite(ratio) and ratio > floor_target:
            misses.append(_floor_miss(sc, s, best, ratio, flt, fl, floor_target))
        cmp_txt, sp_txt, miss = _versus(sc, s, t, comp, comp_ok, err_target, speed_target, tag)
        if miss:
            misses.append(miss)
        e2e = t + _f(best.get("assembly_s")) if best.get("assembly_s") is not None else float("nan")
        floor_name = f" ({str(fl['solver']).removeprefix('floor_')})" if fl else ""
        lines.append(f"| {sc[0]} | {sc[1]:g} | {sc[2]:g} | {s} | {t:.3g} ({_fmt(best.get('setup_s'))} + "
                     f"{_fmt(best.get('solve_s'))}){tag(best)} | {_fmt(e2e)} | "
                     f"{_fmt(_f(best.get('peak_rss_mb')), '.0f')} "
                     f"| {_fmt(flt)}{floor_name}{tag(fl) if fl else ''} | "
                     f"{_fmt(ratio, '.2f')}{fmark} | {cmp_txt} | {sp_txt} |")
    return lines, misses


def targets(runs, floors, ours: list[str], err_target: float, floor_target: float, speed_target: float,
            top: int = 2, tag_sources: bool = False) -> list[str]:
    """Markdown lines checking the performance targets at the largest N of the sweep
    (``tag_sources``: mark each time with the [number] of the results it comes from)."""
    def tag(r: dict) -> str:
        return f" [{r['_source'] + 1}]" if tag_sources and r.get("_source") is not None else ""

    floor_t = {_f(f.get("scene_N")): f for f in floors if f["status"] in ("solved", "inaccurate")}
    Ns = sorted({_f(r.get("scene_N")) for r in runs if r["status"] != "skipped"
                 and math.isfinite(_f(r.get("scene_N")))})[-top:]
    present = sorted({r["solver"] for r in runs if r["solver"] in ours and r["status"] != "skipped"})
    if not present:
        return [f"No run of {', '.join(ours)} in these results: the targets cannot be checked."]
    lines = [f"Checked at N in {{{', '.join(f'{n:g}' for n in Ns)}}} (the largest sizes of this sweep), "
             f"for {', '.join(present)}. A run counts when its status is solved and its relative "
             f"energy-norm error against the reference is <= {err_target:g}; its time is setup + solve; end to "
             "end adds the assembly of the QP from the scene (`assembly_s`); peak RSS is that of the worker "
             "process of the run (`peak_rss_mb`: assembly, reference excluded, every repeat). The floor is "
             "the fastest installed factorization + one solve of K at the same threads.", "",
             f"| scene | N | delta | solver | time [s] (setup + solve) | end to end [s] (+ assembly) | peak RSS "
             f"[MB] | floor [s] (backend) | x floor (target <= "
             f"{floor_target:g}) | fastest of {'/'.join(COMPETITORS)} at error <= {err_target:g} [s] | speed-up "
             f"(target >= {speed_target:g}) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    misses = []
    scenes = sorted({_scene_of(r) for r in runs if _f(r.get("scene_N")) in Ns}, key=lambda s: (s[1], s[0], -s[2]))
    for sc in scenes:
        sl, sm = _scene_lines(sc, runs, present, floor_t.get(sc[1]), err_target, floor_target, speed_target, tag)
        lines += sl
        misses += sm
    lines.append("")
    if misses:
        lines += [f"**Targets missed ({len(misses)}):**", ""] + [f"- {m}" for m in misses]
    else:
        lines.append("All targets that could be checked in these results were met.")
    return lines
