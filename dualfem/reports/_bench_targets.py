"""The "Performance targets" section of ``dualfem report bench``: our solvers against the floor
(one factorization + one solve of K) and against the fastest competitor at equal error.

:func:`target_checks` returns the checks as data (:class:`TargetCheck`, one per scene and solver, with
the misses in words); :func:`targets` renders them as the report's Markdown (the dashboard of
``dualfem report html`` reads the same data).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from dualfem.reports._bench_util import COMPETITORS, _f, _fmt, _scene_of


def _scene_txt(sc: tuple) -> str:
    return f"{sc[0]} N={sc[1]:g} delta={sc[2]:g}"


@dataclass
class TargetCheck:
    """One (scene, solver) of the targets table: times in seconds (setup + solve; ``end_to_end_s`` adds
    the QP's assembly), memory in MB; NaN where not measured. ``met``: a run the solver claimed
    ``solved`` reached the error target (then ``time_s`` ... are those of the fastest such run); else
    ``statuses`` are the statuses of its runs and, when a run reached the target without the solver
    claiming it, ``quiet_status``, ``quiet_error``, ``time_s`` and ``floor_ratio`` are those of the fastest
    such run (``quiet_status`` None when none did). ``source``, ``floor_source``, ``competitor_source``:
    the index of the results each row comes from (None when not known)."""

    scene: str
    N: float
    delta: float
    solver: str
    met: bool
    floor_s: float = math.nan
    floor_backend: str | None = None
    floor_source: int | None = None
    time_s: float = math.nan
    setup_s: float = math.nan
    solve_s: float = math.nan
    end_to_end_s: float = math.nan
    peak_rss_mb: float = math.nan
    source: int | None = None
    floor_ratio: float = math.nan
    floor_ok: bool | None = None
    competitor: str | None = None
    competitor_tier: str | None = None
    competitor_s: float = math.nan
    competitor_source: int | None = None
    speedup: float = math.nan
    speedup_ok: bool | None = None
    speedup_lower_bound: bool = False
    competitor_note: str = ""
    quiet_status: str | None = None
    quiet_error: float = math.nan
    statuses: list[str] = field(default_factory=list)
    misses: list[str] = field(default_factory=list)


def _unmet(chk: TargetCheck, srows: list[dict], err_target: float) -> None:
    """Fill ``chk`` for a solver none of whose claimed runs reached ``err_target``."""
    sc, s, flt = (chk.scene, chk.N, chk.delta), chk.solver, chk.floor_s
    chk.statuses = sorted({r["status"] for r in srows if r["solver"] == s}) or ["not run"]
    # accurate but not claimed: the solver's own test did not certify what the reference shows
    quiet = [r for r in srows if r["solver"] == s and _f(r.get("err_x_energy")) <= err_target
             and math.isfinite(_f(r.get("total_s")))]
    if quiet:
        q = min(quiet, key=lambda r: _f(r["total_s"]))
        chk.quiet_status, chk.quiet_error, chk.time_s = str(q["status"]), _f(q["err_x_energy"]), _f(q["total_s"])
        chk.source = q.get("_source")
        chk.floor_ratio = chk.time_s / flt if math.isfinite(flt) and flt > 0 else math.nan
        chk.misses.append(f"{s} at {_scene_txt(sc)}: status {q['status']}, although its "
                          f"error against the reference is {chk.quiet_error:.1e} ({_quiet_ratio(chk)}): its own "
                          f"stopping test could not certify the answer ({str(q.get('message') or '')[:200]})")
    else:
        chk.misses.append(f"{s} at {_scene_txt(sc)}: no run reached error {err_target:g}")


def _quiet_ratio(chk: TargetCheck) -> str:
    return f"{chk.floor_ratio:.2f} x the floor" if math.isfinite(chk.floor_ratio) else "floor n/a"


def _floor_miss(chk: TargetCheck, floor_target: float) -> str:
    """Why a run missed the floor target: which of setup and solve dominates."""
    t, su, so, flt, ratio = chk.time_s, chk.setup_s, chk.solve_s, chk.floor_s, chk.floor_ratio
    why = ""
    if math.isfinite(su) and math.isfinite(so) and t > 0:
        part = "setup (matrix factorizations)" if su >= so else "solve (iterations)"
        why = (f"; {part} dominates: setup {su:.3g} s = {su / flt:.2f} x the floor, "
               f"solve {so:.3g} s = {so / flt:.2f} x the floor")
    return (f"{chk.solver} at {_scene_txt((chk.scene, chk.N, chk.delta))}: {ratio:.2f} x the floor "
            f"({ratio / floor_target:.2f} x over the target){why}; floor {_fmt(flt)} s ({chk.floor_backend})")


def _versus(chk: TargetCheck, comp: list[dict], comp_ok: list[dict], err_target: float, speed_target: float) -> None:
    """Fill the competitor fields of ``chk`` (our time ``chk.time_s`` against the competitors)."""
    t = chk.time_s
    if comp_ok:
        cb = min(comp_ok, key=lambda r: _f(r["total_s"]))
        chk.competitor, chk.competitor_tier = str(cb["variant"]), str(cb["tier"])
        chk.competitor_s, chk.competitor_source = _f(cb["total_s"]), cb.get("_source")
        chk.speedup = chk.competitor_s / t
        chk.speedup_ok = chk.speedup >= speed_target
        if not chk.speedup_ok:
            chk.misses.append(f"{chk.solver} at {_scene_txt((chk.scene, chk.N, chk.delta))}: {chk.speedup:.1f} x "
                              f"faster than {cb['variant']} (target {speed_target:g} x: "
                              f"{100 * (1 - chk.speedup / speed_target):.0f} % short)")
    elif comp:
        slowest = max((_f(r.get("total_s")) for r in comp if math.isfinite(_f(r.get("total_s")))),
                      default=float("nan"))
        if any(r["status"] == "time_limit" for r in comp):
            slowest = max(slowest if math.isfinite(slowest) else 0.0, max(_f(r.get("time_limit")) for r in comp))
        errs = [_f(r.get("err_x_energy")) for r in comp if math.isfinite(_f(r.get("err_x_energy")))]
        be = f"best error {min(errs):.1e}" if errs else "no error measured"
        chk.competitor_note = (f"none reached {err_target:g} ({be}; statuses "
                               f"{', '.join(sorted({r['status'] for r in comp}))})")
        chk.speedup, chk.speedup_lower_bound = slowest / t, True
    else:
        chk.competitor_note = "not run at this size (spec limit or skipped)"


def _check(sc: tuple, s: str, srows: list[dict], comp: list[dict], comp_ok: list[dict], fl: dict | None,
           err_target: float, floor_target: float, speed_target: float) -> TargetCheck:
    """The check of solver ``s`` on scene ``sc`` (rows ``srows`` of that scene)."""
    chk = TargetCheck(scene=sc[0], N=sc[1], delta=sc[2], solver=s, met=False)
    if fl:
        chk.floor_s, chk.floor_backend, chk.floor_source = _f(fl["total_s"]), str(fl["solver"]), fl.get("_source")
    mine = [r for r in srows if r["solver"] == s and r["status"] == "solved"
            and _f(r.get("err_x_energy")) <= err_target]
    if not mine:
        _unmet(chk, srows, err_target)
        return chk
    best = min(mine, key=lambda r: _f(r["total_s"]))
    chk.met, chk.time_s, chk.source = True, _f(best["total_s"]), best.get("_source")
    chk.setup_s, chk.solve_s = _f(best.get("setup_s")), _f(best.get("solve_s"))
    chk.peak_rss_mb = _f(best.get("peak_rss_mb"))
    chk.end_to_end_s = chk.time_s + _f(best.get("assembly_s")) if best.get("assembly_s") is not None else math.nan
    flt = chk.floor_s
    chk.floor_ratio = chk.time_s / flt if math.isfinite(flt) and flt > 0 else float("nan")
    if math.isfinite(chk.floor_ratio):
        chk.floor_ok = chk.floor_ratio <= floor_target
        if not chk.floor_ok:
            chk.misses.append(_floor_miss(chk, floor_target))
    _versus(chk, comp, comp_ok, err_target, speed_target)
    return chk


def target_sizes(runs: list[dict], top: int = 2) -> list[float]:
    """The ``top`` largest N of the runs (the sizes the targets are checked at)."""
    return sorted({_f(r.get("scene_N")) for r in runs if r["status"] != "skipped"
                   and math.isfinite(_f(r.get("scene_N")))})[-top:]


def target_checks(runs: list[dict], floors: list[dict], ours: list[str], err_target: float, floor_target: float,
                  speed_target: float, top: int = 2) -> list[TargetCheck]:
    """The checks of the performance targets at the ``top`` largest N of the sweep: one per scene of those
    sizes and solver of ``ours`` that ran (none when none ran), in the order of the report's table."""
    floor_t = {_f(f.get("scene_N")): f for f in floors if f["status"] in ("solved", "inaccurate")}
    Ns = target_sizes(runs, top)
    present = sorted({r["solver"] for r in runs if r["solver"] in ours and r["status"] != "skipped"})
    scenes = sorted({_scene_of(r) for r in runs if _f(r.get("scene_N")) in Ns}, key=lambda s: (s[1], s[0], -s[2]))
    out = []
    for sc in scenes:
        srows = [r for r in runs if _scene_of(r) == sc and r["status"] != "skipped"]
        comp = [r for r in srows if r["solver"] in COMPETITORS]
        comp_ok = [r for r in comp if r["status"] == "solved" and _f(r.get("err_x_energy")) <= err_target]
        out += [_check(sc, s, srows, comp, comp_ok, floor_t.get(sc[1]), err_target, floor_target, speed_target)
                for s in present]
    return out


def _line(c: TargetCheck, err_target: float, tag) -> str:
    """The Markdown table line of one check (``tag(source)``: the [number] of a results, or '')."""
    head = f"| {c.scene} | {c.N:g} | {c.delta:g} | {c.solver} | "
    if not c.met:
        if c.quiet_status is not None:
            return (head + f"status {c.quiet_status}{tag(c.source)}: error {c.quiet_error:.1e} in {c.time_s:.3g} s "
                    f"({_quiet_ratio(c)}), not claimed by the solver | | | {_fmt(c.floor_s)} | MISSED | | |")
        return head + (f"no run reached {err_target:g} ({', '.join(c.statuses)}) | | | {_fmt(c.floor_s)} | MISSED "
                       "| | |")
    fmark = "" if c.floor_ok is None else (" ok" if c.floor_ok else " MISSED")
    if c.competitor is not None:
        cmp_txt = f"{c.competitor_s:.3g} ({c.competitor}, tier {c.competitor_tier}){tag(c.competitor_source)}"
        sp_txt = f"{c.speedup:.1f}" + (" ok" if c.speedup_ok else " MISSED")
    else:
        cmp_txt = c.competitor_note
        sp_txt = f"> {c.speedup:.1f} (lower bound)" if math.isfinite(c.speedup) else "n/a"
    floor_name = f" ({c.floor_backend.removeprefix('floor_')})" if c.floor_backend is not None else ""
    floor_tag = tag(c.floor_source) if c.floor_backend is not None else ""
    return (head + f"{c.time_s:.3g} ({_fmt(c.setup_s)} + {_fmt(c.solve_s)}){tag(c.source)} | {_fmt(c.end_to_end_s)} | "
            f"{_fmt(c.peak_rss_mb, '.0f')} | {_fmt(c.floor_s)}{floor_name}{floor_tag} | "
            f"{_fmt(c.floor_ratio, '.2f')}{fmark} | {cmp_txt} | {sp_txt} |")


def targets(runs, floors, ours: list[str], err_target: float, floor_target: float, speed_target: float,
            top: int = 2, tag_sources: bool = False) -> list[str]:
    """Markdown lines checking the performance targets at the largest N of the sweep
    (``tag_sources``: mark each time with the [number] of the results it comes from)."""
    def tag(source: int | None) -> str:
        return f" [{source + 1}]" if tag_sources and source is not None else ""

    Ns = target_sizes(runs, top)
    present = sorted({r["solver"] for r in runs if r["solver"] in ours and r["status"] != "skipped"})
    if not present:
        return [f"No run of {', '.join(ours)} in these results: the targets cannot be checked."]
    if not Ns:
        return ["No scene of these results is given by N (the targets are defined on the paper's scenes at "
                "their largest N): the targets cannot be checked."]
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
    checks = target_checks(runs, floors, ours, err_target, floor_target, speed_target, top)
    lines += [_line(c, err_target, tag) for c in checks]
    misses = [m for c in checks for m in c.misses]
    lines.append("")
    if misses:
        lines += [f"**Targets missed ({len(misses)}):**", ""] + [f"- {m}" for m in misses]
    else:
        lines.append("All targets that could be checked in these results were met.")
    return lines
