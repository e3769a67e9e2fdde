"""The data of the HTML dashboard (``dualfem report html``): results folders read, merged and summarised
into one JSON-able payload that the page's script filters (:mod:`dualfem.reports.html` renders it).

What the payload holds (every number as measured; NaN and infinities become ``null``):

* ``scenes``: the scene identities (:class:`dualfem.reports._bench_util.SceneId`: the scene's name and
  the values of its grid keys that vary, e.g. ``f2, N = 64`` or ``plate, mesh_size = 0.02``), as labels,
  with ``scene_names`` (the scene name of each) and ``scene_unknowns`` (median unknowns of each);
* ``runs``: one entry per run row that was not skipped (bench rows of kind ``run``, stress rows of kind
  ``stress``), in columns: solver variant, scene identity (index into ``scenes``), delta, tier, status,
  claimed status, grade, whether the solver is the reference solver of its scene (``selfref``: its
  energy-norm error is 0 by construction),
  time = setup + solve [s] (``total_s``), relative energy-norm error against the certified reference
  (``err_x_energy``), the evaluator's KKT error, run id, label, results index, a short message;
* ``curves``: per run id, the samples of its convergence curve (time [s], error, iteration) from the
  folder's ``curves.csv`` (:mod:`dualfem.experiments.curves`), only for runs whose row is kept (of a run
  timed in several repeats, its first repeat's curve);
* ``rank``: the ranking tables of ``dualfem report bench`` (:func:`dualfem.reports._bench_rank.rank_table`:
  success rate, correct rate, shifted geometric mean of time) per tier, for every scene / delta
  selection (all, or one value of each) the runs cover, keyed ``"tier|scene|delta"`` (-1 = all);
* ``targets``: the performance-target checks of ``dualfem report bench``
  (:func:`dualfem.reports._bench_targets.target_checks`), only when ``show_targets`` (else []);
* ``solvers``: every solver variant of the input (also those only skipped) with its family and
  plotly style (:meth:`dualfem.post.style.Style.plotly`: Okabe-Ito colours, one marker set per family);
* ``floors``: the floor (one factorization + one solve of K) per scene identity of the same number of
  unknowns (``scene``: index into ``scenes``).

Stress rows (``dualfem stress``) have no tier: they are put in the tier ``declared`` (each solver's own
declared tolerance, graded as recorded), their scene is the scene's name (``scene_name``: ``curved``,
not its problem or load; older rows: the scene's load), and their scene
key the stress axis and its coordinates.
"""
from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.io import RESULTS_ENTRIES, check_folder_files
from dualfem.experiments.curves import read_curves
from dualfem.experiments.row import Row
from dualfem.experiments.store import read_results
from dualfem.experiments.stress import load_results
from dualfem.post.style import FAMILIES, MAX_SERIES, family, styles
from dualfem.reports._bench_rank import deltas_of, rank_table, tiers_of
from dualfem.reports._bench_targets import target_checks
from dualfem.reports._bench_util import OURS, _f, group_scenes, unknowns
from dualfem.reports._correct_rate import DEFINITION, SUCCESS
from dualfem.reports.bench import _slot

#: the tier of stress rows (their solvers' own declared tolerances)
STRESS_TIER = "declared"
#: the columns of a ranking row in the payload (``rank``), in order
RANK_COLUMNS = ("solver", "runs", "success", "claims", "certified", "over_time", "correct", "agree", "demoted",
                "flagged", "silent_wrong", "unverified", "sgm", "sgm_rel", "gm_rel")


@dataclass
class Source:
    """One results folder: its path, ``kind`` (``bench`` or ``stress``), the command that wrote it (its
    sweep.json / meta.json, when there), and how many of its rows are shown (after merging)."""

    results: str
    kind: str
    command: str | None
    started_utc: str | None
    finished_utc: str | None
    n_rows: int
    kept: int = 0


def _meta(folder: Path, name: str) -> dict:
    try:
        data = json.loads((folder / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _stress_row(r: dict) -> dict:
    """A stress row in the bench row's terms (scene name, N, delta, scene key, tier, variant)."""
    sc = r.get("scene") if isinstance(r.get("scene"), dict) else {}
    coords = r.get("coords") if isinstance(r.get("coords"), dict) else {}
    r = dict(r)
    r.update(scene=str(r.get("scene_name") or sc.get("scene") or sc.get("load") or "?"), scene_N=_f(sc.get("N")),
             scene_delta=_f(sc.get("delta")), tier=STRESS_TIER, variant=str(r.get("solver")),
             solver=str(r.get("solver")),
             scene_key=f"{r.get('axis')}:{json.dumps(coords, sort_keys=True, default=str)}",
             label=f"{r.get('axis')} {', '.join(f'{k}={v}' for k, v in sorted(coords.items()))}")
    return r


def _read_one(item: str | Path) -> tuple[list[dict], Source, Path]:
    """The rows of one results folder (or its results.csv / runs.jsonl), normalised, and its Source."""
    p = Path(item)
    if not p.exists():
        raise InputError(f"RESULTS {str(p)!r} does not exist (give a 'dualfem bench' or 'dualfem stress' "
                         "results folder)")
    folder = p if p.is_dir() else p.parent
    # a FIFO or a device in it: refused before anything reads it
    check_folder_files(folder, "RESULTS", only=None if p.is_dir() else RESULTS_ENTRIES)
    if p.suffix == ".csv" or (p.is_dir() and (p / "results.csv").is_file()):
        raw = read_results(p)
        rows = [_stress_row(Row.from_dict(r).to_dict()) if r.get("kind") == "stress" else r for r in raw]
    elif p.suffix == ".jsonl" or (p.is_dir() and (p / "runs.jsonl").is_file()):
        rows = [_stress_row(r.to_dict()) for r in load_results(p)[1]]
    else:
        raise InputError(f"RESULTS {str(p)!r} is not a 'dualfem bench' folder (results.csv) or a 'dualfem stress' "
                         "folder (results.csv or runs.jsonl)")
    stress = any(r.get("kind") == "stress" for r in rows)
    meta = _meta(folder, "sweep.json") or _meta(folder, "meta.json")
    for r in rows:
        r["tier"] = str(r.get("tier")) if r.get("tier") is not None else ""
        r["variant"] = str(r.get("variant") or r.get("solver"))
        r["solver"] = str(r.get("solver"))
    src = Source(results=str(item), kind="stress" if stress else "bench",
                 command=str(meta["command"]) if meta.get("command") else None,
                 started_utc=meta.get("started_utc"), finished_utc=meta.get("finished_utc"), n_rows=len(rows))
    return rows, src, folder


def load(results: list[str | Path]) -> tuple[list[dict], list[dict], dict[str, list[dict]], list[Source]]:
    """(run rows, floor rows, curve samples per run id, sources) of several results; a later results
    replaces the rows of an earlier one that measure the same thing (as ``dualfem report bench``: a
    run is its scene, solver variant and tier; a stress row its run id). InputError for a missing or
    unreadable folder, or when no results hold any run."""
    if not results:
        raise InputError("give at least one RESULTS (a 'dualfem bench' or 'dualfem stress' results folder)")
    merged: dict[tuple, dict] = {}
    sources, folders = [], []
    for i, item in enumerate(results):
        rows, src, folder = _read_one(item)
        for r in rows:
            r["_source"] = i
            merged[("stress", r.get("run_id")) if r.get("kind") == "stress" else _slot(r)] = r
        sources.append(src)
        folders.append(folder)
    rows = list(merged.values())
    runs = [r for r in rows if r.get("kind") in ("run", "stress")]
    if not runs:
        raise InputError(f"RESULTS {', '.join(map(str, results))} hold no runs (only references or floors, or "
                         "nothing): run 'dualfem bench SPEC --out DIR' first")
    for i, src in enumerate(sources):
        src.kept = sum(r["_source"] == i for r in rows)
    curves: dict[str, list[dict]] = {}
    for i, folder in enumerate(folders):
        if (folder / "curves.csv").is_file():
            kept = {r["run_id"] for r in runs if r["_source"] == i}
            for rec in read_curves(folder / "curves.csv"):
                if rec["run_id"] in kept:
                    curves.setdefault(rec["run_id"], []).append(rec)
    floors = [r for r in rows if r.get("kind") == "floor"]
    return runs, floors, curves, sources


def _num(v: Any, digits: int = 5) -> float | None:
    """A finite number rounded to ``digits`` significant digits, else None (JSON null)."""
    f = _f(v)
    return float(f"{f:.{digits}g}") if math.isfinite(f) else None


def _index(values) -> tuple[list, dict]:
    vals = list(values)
    return vals, {v: i for i, v in enumerate(vals)}


def _solvers(runs: list[dict]) -> list[dict]:
    """Every variant, ordered by family (as :data:`FAMILIES`) then name, with its style and whether it ran."""
    names = sorted({r["variant"] for r in runs})
    order = list(FAMILIES)
    st = styles(names)
    ran = {r["variant"] for r in runs if r.get("status") != "skipped"}
    skipped = defaultdict(set)
    for r in runs:
        if r.get("status") == "skipped":
            skipped[r["variant"]].add(str(r.get("message") or "")[:150])
    out = []
    for n in sorted(names, key=lambda n: (order.index(family(n)), n)):
        look = st[n].plotly()
        out.append({"name": n, "family": family(n), "color": look["color"], "symbol": look["symbol"],
                    "dash": look["dash"], "edge": look["edge"], "ran": n in ran,
                    "skipped": "; ".join(sorted(skipped[n])) if n not in ran else ""})
    return out


def _runs_columns(runs: list[dict], sidx: dict, dims: dict[str, dict]) -> dict[str, list]:
    """The non-skipped runs as columns (indices into the payload's lists where a value repeats)."""
    cols: dict[str, list] = defaultdict(list)
    for r in runs:
        if r.get("status") == "skipped":
            continue
        cols["solver"].append(sidx[r["variant"]])
        cols["scene"].append(dims["scene"][id(r)])
        cols["selfref"].append(int(bool(r.get("ref_solver")) and str(r.get("ref_solver")) == r["solver"]))
        cols["delta"].append(_num(r.get("scene_delta")))
        cols["tier"].append(dims["tier"][r["tier"]])
        cols["status"].append(dims["status"][str(r.get("status"))])
        cols["claimed"].append(str(r.get("claimed_status") or r.get("status") or ""))
        cols["grade"].append(str(r.get("grade") or ""))
        cols["time"].append(_num(r.get("total_s")))
        cols["err"].append(_num(r.get("err_x_energy"), 4))
        cols["kkt"].append(_num(r.get("kkt_error"), 4))
        cols["id"].append(str(r.get("run_id") or ""))
        cols["label"].append(str(r.get("label") or ""))
        cols["source"].append(int(r["_source"]))
        cols["message"].append("" if r.get("status") == "solved" else str(r.get("message") or "")[:140])
    return dict(cols)


def _curves(curves: dict[str, list[dict]]) -> dict[str, dict]:
    """Per run id: time [s], error and iteration of each sample in time order, and the error kind; of a
    run timed in several repeats (one curve each), the curve of its first recorded repeat (mixing
    them would interleave two descents into one saw-tooth)."""
    out = {}
    for rid, recs in curves.items():
        first = min(int(c.get("repeat") or 1) for c in recs)
        recs = [c for c in recs if int(c.get("repeat") or 1) == first]
        recs = sorted(recs, key=lambda c: (_f(c["time_s"]), c["iteration"]))
        out[rid] = {"t": [_num(c["time_s"], 6) for c in recs], "e": [_num(c["error"], 5) for c in recs],
                    "it": [c["iteration"] for c in recs], "kind": recs[0]["error_kind"]}
    return out


def _rank(live: list[dict], tiers: list[tuple[str, float | None]], groups: list[list[dict]],
          deltas: list[float], shift: float, sidx: dict) -> dict[str, dict]:
    """The ranking tables keyed ``"tier|scene|delta"`` (indices into the payload's lists, -1 = all);
    ``groups``: the runs of each scene identity."""
    out = {}
    for si, sub in [(-1, live)] + list(enumerate(groups)):
        for ti, (tier, tol) in enumerate(tiers):
            for di, delta in [(-1, None)] + list(enumerate(deltas)):
                # tol None (stress): each run graded as recorded, at its solver's declared tolerance
                stats, ncommon = rank_table(sub, tier, tol, shift, delta)  # type: ignore[arg-type]
                if stats:
                    out[f"{ti}|{si}|{di}"] = {"n": ncommon, "rows": [
                        [sidx[s["variant"]]] + [_num(s[k], 4) for k in RANK_COLUMNS[1:]] for s in stats]}
    return out


def _targets(runs: list[dict], floors: list[dict], ours: list[str], err_target: float, floor_target: float,
             speed_target: float) -> list[dict]:
    bench_runs = [r for r in runs if r.get("kind") == "run"]
    if not any(r["solver"] in ours and r.get("status") != "skipped" for r in bench_runs):
        return []
    checks = target_checks(bench_runs, floors, ours, err_target, floor_target, speed_target)
    return [{k: (_num(v) if isinstance(v, float) else v) for k, v in asdict(c).items()} for c in checks]


def _floors(floors: list[dict], sizes: list[float]) -> list[dict]:
    """The usable floors, one entry per scene identity of the same number of unknowns."""
    out = []
    for f in floors:
        if f.get("status") in ("solved", "inaccurate"):
            out += [{"scene": i, "time": _num(f.get("total_s")), "backend": str(f.get("solver")),
                     "source": f["_source"]} for i, n in enumerate(sizes) if n == _f(f.get("n_unknowns"))]
    return out


def payload(results: list[str | Path], *, shift: float = 10.0, ours: list[str] | None = None,
            err_target: float = 1e-8, floor_target: float = 1.5, speed_target: float = 10.0,
            command: str = "", show_targets: bool = False) -> dict:
    """The dashboard's data (module docstring) of one or several results folders; ``show_targets``:
    include dualfem's own performance-target checks (off: ``targets`` is [])."""
    runs, floors, curves, sources = load(results)
    ours = list(OURS) if ours is None else list(ours)
    solvers = _solvers(runs)
    names, sidx = _index(s["name"] for s in solvers)
    live = [r for r in runs if r.get("status") != "skipped"]
    tiers: list[tuple[str, float | None]] = list(tiers_of([r for r in live if r["tier"] != STRESS_TIER]))
    if any(r["tier"] == STRESS_TIER for r in live):
        tiers.append((STRESS_TIER, None))
    if not tiers and live:          # only tolerance-free runs: one table of them, graded as recorded
        tiers.append(("any", None))
    groups = group_scenes(live)
    sizes = [unknowns(g) for g in groups.values()]
    deltas = deltas_of(live)
    tier_names = [t for t, _ in tiers] + sorted({r["tier"] for r in live} - {t for t, _ in tiers})
    statuses = sorted({str(r.get("status")) for r in live})
    dims = {"scene": {id(r): i for i, g in enumerate(groups.values()) for r in g}, "tier": _index(tier_names)[1],
            "status": _index(statuses)[1]}
    return {
        "title": "dualfem benchmark dashboard", "command": command,
        "sources": [asdict(s) for s in sources],
        "solvers": solvers, "families": [f for f in FAMILIES if any(s["family"] == f for s in solvers)],
        "max_series": MAX_SERIES,
        "scenes": [s.label for s in groups], "scene_names": [s.scene for s in groups],
        "scene_unknowns": [_num(n) for n in sizes], "deltas": [_num(d) for d in deltas], "statuses": statuses,
        "tiers": [{"name": t, "tol": _num(tol) if tol is not None else None} for t, tol in tiers]
        + [{"name": t, "tol": None} for t in tier_names[len(tiers):]],
        "ranked_tiers": len(tiers),
        "runs": _runs_columns(runs, sidx, dims),
        "curves": _curves(curves),
        "floors": _floors(floors, sizes),
        "rank_columns": list(RANK_COLUMNS),
        "rank": _rank(live, tiers, list(groups.values()), deltas, shift, sidx),
        "show_targets": show_targets,
        "targets": _targets(runs, floors, ours, err_target, floor_target, speed_target) if show_targets else [],
        "target_settings": {"ours": ours, "error": err_target, "floor": floor_target, "speed": speed_target},
        "shift": shift,
        "definitions": {"correct": DEFINITION, "success": SUCCESS},
        "solver_names": names,
    }
