"""Convergence curves: a bench run's error along its solver's iterations, against time.

With ``curves = true`` in a bench spec (:mod:`dualfem.experiments.spec`), every timed repeat of a run
gets an :class:`IterateMonitor`, attached to the solver for its ``solve()`` by
:func:`dualfem.experiments.runner.run`. A solver that has iterates reports them with
:meth:`dualfem.core.solver.Solver.report_iterate` (every built-in iterative solver does); the others
(OSQP, Clarabel, the qpsolvers backends: no Python callback) report nothing and stay points.

**Sampling.** A monitor keeps at most :data:`MAX_SAMPLES` iterates: every reported one until the list
is full, then every second one of those kept (the stride doubles), so the samples stay evenly spread
over the whole run whatever its length; the answer the solver returns (its ``Solution``'s x and
multipliers) is always the last sample, at the last reported iteration. A sample is a copy of
(x, mu) and the clock; an unsampled iteration costs one call. The copies are bounded:
at most :data:`MEMORY_BUDGET` bytes, so a huge QP keeps fewer samples (at least 2, the first and the
last), and the row's ``message`` says so.

**Time.** ``time_s`` of a sample = the run's setup time + the solve time elapsed at the sample, minus
the time spent inside the monitor so far (copies, and the x a dual method computes only for a kept
sample): the last sample lies at that repeat's ``setup_s + solve_s``, on the axis of the rows'
``total_s``. The monitor's time is excluded from the run's ``solve_s`` too (every timed repeat is
monitored, so the repeats stay comparable); a solver's own ``time_limit`` clock still runs through
it. **Repeats**: every timed repeat gives a curve (``repeat`` = 1, 2, ...: the median curve and its
quantile band across repeats show the timing spread); the iterates are copied only for the last one,
the one whose answer the row's errors are measured on, and an earlier repeat's sample takes the
error of the last repeat's sample at the same iteration (a deterministic solver repeats its
iterates exactly; a sample of an iteration the last repeat did not sample is left out, and a
repeat that reached another answer keeps no curve).

**Error** of each sample, computed after the solve (untimed): with a certified reference of the
scene, the row's ``err_x_energy`` (:func:`dualfem.core.evaluator.compare`: |x - x_ref|_K / |x_ref|_K;
``error_kind = "reference"``), else the evaluator's KKT error of (x, mu)
(:func:`dualfem.core.evaluator.kkt_error`, the row's ``kkt_error``; ``error_kind = "kkt"``). The last
sample's error is the row's error exactly (the same function of the same answer); an error that
cannot be computed (NaN in the iterate) is NaN, an empty field in curves.csv.

**Files** (:class:`CurveStore`): ``curves/<run_id>.json`` (one atomic file per run's curve, written
before the run's row) and ``curves.csv`` beside ``results.csv`` (rewritten atomically with it), one line
per (run, sample), columns :data:`COLUMNS`. A curve is kept only while its run's row is there (a
run killed before its row leaves no curve; a redone run replaces its curve; a resumed sweep keeps
finished runs' curves and never duplicates them). Read it with
``dualfem.results.load(DIR, table="curves")``.
"""
from __future__ import annotations

import csv
import io
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.core.io import atomic_write_text

#: the columns of curves.csv, in order (a stable interface: run_id joins results.csv's run rows)
COLUMNS = ("run_id", "solver", "tier", "scene_key", "iteration", "time_s", "error", "error_kind", "repeat")
#: what ``error`` measures: the energy-norm error against the certified reference, or the KKT error
ERROR_KINDS = ("reference", "kkt")
#: samples kept per run at most (the last iterate included)
MAX_SAMPLES = 50
#: bytes of (x, mu) copies a monitor keeps at most (a huge QP gets fewer samples, at least 2)
MEMORY_BUDGET = 256 * 2**20


@dataclass
class Sample:
    """One kept iterate: its report index, the solver's iteration number, time (s), and copies of x, mu."""

    index: int
    iteration: int
    time_s: float
    x: np.ndarray
    mu: np.ndarray


class IterateMonitor:
    """Samples a solver's reported iterates (module docstring); attached by the runner for one solve.

    ``n``, ``m``: the QP's unknowns and constraint rows (``QP.m_total``: every block's multipliers, as
    solvers report them; iterates of other shapes end the sampling with a note); ``max_samples`` (>= 2)
    and ``budget`` (bytes) bound the copies kept.
    """

    def __init__(self, n: int, m: int, max_samples: int = MAX_SAMPLES, budget: int = MEMORY_BUDGET) -> None:
        self.n, self.m = int(n), int(m)
        per = 8 * (self.n + self.m)
        self.cap = max(2, min(int(max_samples), budget // max(per, 1)))
        self.note = "" if self.cap >= max_samples else (
            f"curve limited to {self.cap} samples: one copy of (x, mu) is {per / 2**20:.3g} MiB, "
            f"the monitor's budget {budget / 2**20:.0f} MiB")
        self.room = self.cap - 1          # for reported iterates; the last slot is the answer's
        self.samples: list[Sample] = []
        self.stride = 1
        self.count = 0
        self.last_iteration: int | None = None
        self.overhead = 0.0
        self.t0: float | None = None
        self.offset = 0.0
        self.stopped = False
        #: (iteration, time_s) samples of the earlier timed repeats, one list per repeat (copies dropped)
        self.earlier: list[list[tuple[int, float]]] = []

    def start(self, t0: float, offset: float = 0.0) -> None:
        """The solve starts at ``t0`` (``time.perf_counter()``), after ``offset`` seconds of setup."""
        self.t0, self.offset = t0, float(offset)

    def report(self, iteration: Any, x: Any, mu: Any) -> None:
        """Take iterate ``iteration`` (x and mu arrays or zero-argument callables) if it is sampled."""
        enter = time.perf_counter()
        try:
            self._report(enter, iteration, x, mu)
        except Exception as exc:  # noqa: BLE001 - the monitor never breaks the solve it watches
            if not self.stopped:
                self.note = (self.note + "; " if self.note else "") + \
                    f"curve sampling stopped at iteration {iteration!r}: {type(exc).__name__}: {exc}"
            self.stopped = True
        finally:
            self.overhead += time.perf_counter() - enter

    def _report(self, enter: float, iteration: Any, x: Any, mu: Any) -> None:
        if self.t0 is None:
            return
        it = _whole(iteration)
        self.last_iteration = it           # stopped or not: the answer is the last reported iterate
        if self.stopped:
            return
        i = self.count
        self.count += 1
        if i % self.stride:
            return
        if len(self.samples) >= self.room:          # full: keep every second sample, double the stride
            self.stride *= 2
            self.samples = [s for s in self.samples if s.index % self.stride == 0]
            if i % self.stride or len(self.samples) >= self.room:
                return
        t = self.offset + (enter - self.t0 - self.overhead)
        self.samples.append(Sample(i, it, t, _copy(x, self.n, "x"), _copy(mu, self.m, "mu")))

    def finish(self, x: np.ndarray, mu: np.ndarray | None, solve_s: float) -> None:
        """The answer the solver returned, as the last sample (at the last reported iteration, at
        ``offset + solve_s``); nothing when the solver reported no iterate (it stays a point)."""
        if self.last_iteration is None or x is None:
            return
        mu = np.zeros(self.m) if mu is None else mu
        last = Sample(self.count, self.last_iteration, self.offset + float(solve_s),
                      np.array(x, dtype=float), np.array(mu, dtype=float))
        if self.samples and self.samples[-1].iteration == last.iteration:
            self.samples[-1] = last
        else:
            self.samples.append(last)


def _whole(v: Any) -> int:
    f = float(v)
    if not math.isfinite(f) or f != int(f):
        raise ValueError(f"the iteration number must be a whole number, got {v!r}")
    return int(f)


def _copy(v: Any, size: int, what: str) -> np.ndarray:
    a = v() if callable(v) else v
    out = np.array(a, dtype=float)          # a copy: the solver goes on changing its own arrays
    if out.shape != (size,):
        raise ValueError(f"{what} has shape {out.shape}, the QP's is ({size},)")
    return out


# ------------------------------------------------------------------------- in the worker
def sample_errors(qp, monitor: IterateMonitor | None, ref: dict | None) -> dict | None:
    """The curve of a monitored run: ``{"error_kind", "samples": [(iteration, time_s, error), ...],
    "note"}`` (module docstring), or None when the solver reported no iterate. ``ref``: the scene's
    certified reference (x, multipliers, qp_key), used when it belongs to ``qp``. Frees the copies."""
    from dualfem.core import evaluator

    if monitor is None or not monitor.samples:
        return None
    use_ref = ref is not None and ref.get("qp_key") == qp.key()

    def error(s: Sample) -> float:
        try:
            if use_ref:
                return float(evaluator.compare(qp, s.x, s.mu, ref["x"], ref["multipliers"])["x_energy"])
            return float(evaluator.kkt_error(evaluator.residuals(qp, s.x, s.mu)))
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return float("nan")

    last = len(monitor.earlier) + 1
    out = [(s.iteration, s.time_s, error(s), last) for s in monitor.samples]
    at = {it: e for it, _, e, _ in out}
    final = out[-1][0]
    for r, samples in enumerate(monitor.earlier, start=1):
        if samples and samples[-1][0] == final:        # the same run of iterates (a repeat that stopped
            out.extend((it, t, at[it], r) for it, t in samples if it in at)   # elsewhere keeps no curve)
    monitor.samples = []
    return {"error_kind": "reference" if use_ref else "kkt", "samples": out, "note": monitor.note}


def timed_runs(task: dict, qp, name: str, params: dict, tick, warmup: bool, repeats: int):
    """Warm-up (untimed, unmonitored) then ``repeats`` timed runs, each monitored when ``task["curves"]``;
    returns (last solution, setup list, solve list, repeats done, note, the last repeat's monitor or None)."""
    from dualfem.core.solution import Status
    from dualfem.experiments.runner import run
    from dualfem.numerics import linalg

    setups, solves, statuses = [], [], []
    sol = monitor = None
    earlier: list[list[tuple[int, float]]] = []
    stop = {Status.TIME_LIMIT, Status.ERROR, Status.SKIPPED}
    if warmup:
        tick("warmup", task["hard_limit"])
        if task.get("cold_setup", True):
            linalg.store_of(qp).clear()
        sol = run(name, qp, params, tol=task.get("tol"), grades=task.get("grades"))
        if sol.status in stop:     # nothing to time: report the warm-up as is
            return sol, [sol.time_s["setup"]], [sol.time_s["solve"]], 0, "from the warm-up run", None
    done = 0
    for i in range(repeats):
        tick(f"repeat {i + 1}", task["hard_limit"])
        if task.get("cold_setup", True):
            linalg.store_of(qp).clear()
        if monitor is not None:             # the previous repeat keeps its times; its copies are freed first
            earlier.append([(smp.iteration, smp.time_s) for smp in monitor.samples])
        monitor = None
        monitor = IterateMonitor(qp.n, qp.m_total) if task.get("curves") else None
        sol = run(name, qp, params, tol=task.get("tol"), monitor=monitor, grades=task.get("grades"))
        setups.append(sol.time_s["setup"])
        solves.append(sol.time_s["solve"])
        statuses.append(str(sol.status))
        done += 1
        if sol.status in stop:
            break
    note = "" if len(set(statuses)) <= 1 else f"statuses differ across repeats: {statuses}"
    if monitor is not None:
        monitor.earlier = earlier
    return sol, setups, solves, done, note, monitor


# ------------------------------------------------------------------------- in the parent
class CurveStore:
    """``curves/<run_id>.json`` and ``curves.csv`` of a results folder (module docstring).

    ``store``: the folder's open :class:`dualfem.experiments.store.ResultStore`; its rows decide
    which curves are kept. Attach with :meth:`open` (it also makes ``store.write_csv`` write curves.csv).
    """

    def __init__(self, store) -> None:
        self.store = store
        self.dir = store.out / "curves"
        self.csv = store.out / "curves.csv"
        self.curves: dict[str, dict] = {}

    def open(self) -> CurveStore:
        """Read curves/ and curves.csv, keep a run's curve only with the very row it was written with
        (a file carries its row's ``started_utc``; a line of curves.csv the one results.csv gave the run
        when both were written): a file first, else the CSV's; files of interrupted writes are removed."""
        self.dir.mkdir(parents=True, exist_ok=True)
        for p in self.dir.glob(".*"):
            if p.is_file():
                p.unlink()
        found: dict[str, list[dict]] = {}
        for p in sorted(self.dir.glob("[!.]*.json")):
            try:
                c = json.loads(p.read_text(encoding="utf-8"))
                found.setdefault(str(c["run_id"]), []).append(c)
            except (OSError, ValueError, KeyError, TypeError):
                self.store.set_aside(p, "unreadable curve file; its curve is dropped (curves.csv may hold it)")
        for rid, c in self._read_csv().items():
            found.setdefault(rid, []).append(c)
        for rid, cands in found.items():
            row = self.store.rows.get(rid)
            ok = [c for c in cands if row is not None and row.get("started_utc") == c.get("started_utc")]
            if ok:
                self.curves[rid] = ok[0]
            file = self.dir / f"{rid}.json"
            if not ok or ok[0] is not cands[0] or not file.is_file():
                file.unlink(missing_ok=True)  # no row, another attempt's row, or only in curves.csv (not committed)
                if ok:
                    self._write(rid)
        self.store.curves = self
        return self

    def _read_csv(self) -> dict[str, dict]:
        """The curves of curves.csv, each stamped with its run's ``started_utc`` in results.csv."""
        if not self.csv.is_file():
            return {}
        from dualfem.core.errors import InputError
        from dualfem.experiments.store import read_results_checked

        try:
            recs, bad = read_curves_checked(self.csv)
        except InputError as exc:
            self.store.set_aside(self.csv, f"unreadable curves.csv ({exc})")
            return {}
        if bad:
            from dualfem.core.io import move_aside

            dest = move_aside(self.csv, "corrupt")
            self.store.warn(f"{len(bad)} unreadable line(s) of curves.csv: the file as it was is kept as "
                            f"{str(dest)!r}; the curves of its readable lines are kept")
        try:
            stamps = {r["run_id"]: r.get("started_utc") for r in read_results_checked(self.store.out)[0]}
        except InputError:
            stamps = {}
        return {rid: {**c, "started_utc": stamps.get(rid, "(not in results.csv)")}
                for rid, c in _group(recs).items()}

    def add(self, row: dict, payload: Any) -> None:
        """The curve of a finished run (``payload`` of its task), written before its row; a run without
        one (a point, a failed or skipped run) loses any curve an earlier attempt left."""
        rid = row["run_id"]
        curve = payload.get("curve") if isinstance(payload, dict) else None
        if not curve or not curve.get("samples"):
            if rid in self.curves:
                self._drop(rid)
            return
        self.curves[rid] = {"run_id": rid, "started_utc": row.get("started_utc"), "solver": row.get("solver"),
                            "tier": row.get("tier"), "scene_key": row.get("scene_key"),
                            "error_kind": curve["error_kind"], "samples": [list(s) for s in curve["samples"]]}
        self._write(rid)

    def _write(self, rid: str) -> None:
        from dualfem.core.io import jsonable

        atomic_write_text(self.dir / f"{rid}.json", json.dumps(jsonable(self.curves[rid]), sort_keys=True))

    def _drop(self, rid: str) -> None:
        self.curves.pop(rid, None)
        (self.dir / f"{rid}.json").unlink(missing_ok=True)

    def write_csv(self, keep: Callable[[dict], bool] | None = None) -> Path:
        """curves.csv (atomically) of the curves whose run row is in the store (and passes ``keep``)."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(COLUMNS)
        for rid in sorted(self.curves):
            row = self.store.rows.get(rid)
            if row is None or (keep is not None and not keep(row)):
                continue
            c = self.curves[rid]
            for it, t, err, *r in c["samples"]:
                w.writerow([rid, _text(c["solver"]), _text(c["tier"]), _text(c["scene_key"]), int(it),
                            _num(t), _num(err), c["error_kind"], int(r[0]) if r else 1])
        return atomic_write_text(self.csv, buf.getvalue())


def _text(v: Any) -> str:
    return "" if v is None else str(v)


def _num(v: Any) -> str:
    return repr(float(v)) if v is not None and math.isfinite(float(v)) else ""


def _group(recs: list[dict]) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for r in recs:
        c = out.setdefault(r["run_id"], {"run_id": r["run_id"], "solver": r["solver"], "tier": r["tier"],
                                         "scene_key": r["scene_key"], "error_kind": r["error_kind"], "samples": []})
        c["samples"].append([r["iteration"], r["time_s"], r["error"], r["repeat"]])
    return out


def read_curves_checked(path: str | Path) -> tuple[list[dict], list[int]]:
    """(records, bad line numbers) of a curves.csv: numbers parsed (an empty error or time is NaN); a
    line cut by a kill, of the wrong width or with an unreadable number is left out. A file without the
    header :data:`COLUMNS` is a :class:`dualfem.core.errors.InputError`."""
    from dualfem.core.errors import InputError

    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from None
    lines = text.splitlines(keepends=True)
    if not lines or next(csv.reader([lines[0]]), []) != list(COLUMNS):
        raise InputError(f"{str(path)!r} is not a dualfem curves.csv (its header is not {', '.join(COLUMNS)})")
    recs, bad = [], []
    for k, line in enumerate(lines[1:], start=2):
        try:
            rec = next(csv.reader([line]))
            if not line.endswith("\n") or len(rec) != len(COLUMNS) or not rec[0] or rec[7] not in ERROR_KINDS:
                raise ValueError(line)
            r = dict(zip(COLUMNS, rec))
            r.update(iteration=_whole(r["iteration"]), time_s=float(r["time_s"] or "nan"),
                     error=float(r["error"] or "nan"), repeat=_whole(r["repeat"]))
            if r["repeat"] < 1:
                raise ValueError(line)
            for key in ("solver", "tier", "scene_key"):
                r[key] = r[key] or None
        except (ValueError, StopIteration, csv.Error):
            bad.append(k)
            continue
        recs.append(r)
    return recs, bad


def read_curves(path: str | Path, warn: Callable[[str], None] | None = None) -> list[dict]:
    """The records of a curves.csv (:func:`read_curves_checked`); unreadable lines are skipped with one
    warning (``warn``, default a ``dualfem: warning:`` line on stderr), nothing is changed on disk."""
    recs, bad = read_curves_checked(path)
    if bad:
        (warn or (lambda msg: print(f"dualfem: warning: {msg}", file=sys.stderr)))(
            f"{len(bad)} unreadable line(s) of {str(path)!r} skipped (a cut or damaged write?): lines "
            f"{', '.join(map(str, bad[:5]))}{' ...' if len(bad) > 5 else ''}")
    return recs
