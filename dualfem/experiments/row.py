"""One tidy row per run: the record that compare, bench and stress produce and every report reads.

The field names are a stable interface (they are the columns of ``results.csv``). Fields that
hold several values (``solver_params``, ``iterations``, ``coords``) are dicts in Python and JSON
text in CSV. Anything else a producer wants to keep (``scene_*`` parameters, ``reason``, ...)
goes to :attr:`Row.extra` and is written as its own column.

Units: times in seconds (``*_s``), memory in MB (``peak_rss_mb``), errors relative (see
:mod:`dualfem.verify.grading` for the grading policy, :mod:`dualfem.core.evaluator` for residuals).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields
from typing import Any

from dualfem.core.evaluator import RESIDUALS
from dualfem.core.io import jsonable
from dualfem.verify.judge import Verdict, cert_facts, outcome


@dataclass
class Row:
    """One run (``kind``: run, reference, floor, stress, compare); see the module docstring."""

    run_id: str = ""
    kind: str = "run"
    spec: str | None = None
    scene: str | dict | None = None          # a scene name (bench, compare) or its parameters (stress)
    scene_key: str | None = None
    label: str | None = None
    n_unknowns: int | None = None
    n_constraints: int | None = None
    solver: str | None = None
    variant: str | None = None
    solver_params: dict = field(default_factory=dict)
    tier: str | None = None
    tol: float | None = None
    status: str | None = None
    claimed_status: str | None = None
    grade: str | None = None
    grades: str | None = None                # what the tier grades: "x" or "x,mu" (dualfem.verify.grading)
    grade_x: str | None = None               # the displacements' grade
    grade_mu: str | None = None              # the multipliers' grade
    message: str = ""
    iterations: dict = field(default_factory=dict)
    main_iterations: float | None = None
    repeats: int | None = None
    repeats_done: int = 0
    assembly_s: float | None = None
    setup_s: float | None = None
    solve_s: float | None = None
    total_s: float | None = None
    setup_s_all: str | None = None
    solve_s_all: str | None = None
    time_limit: float | None = None
    cold_setup: bool | None = None
    peak_rss_mb: float | None = None
    kkt_error: float | None = None
    stationarity: float | None = None
    primal: float | None = None
    dual: float | None = None
    complementarity: float | None = None
    within_tol: bool | None = None
    err_x_energy: float | None = None
    err_x_max: float | None = None
    err_multipliers: float | None = None
    err_energy: float | None = None
    cert_x: float | None = None              # the runner's certified energy-norm error bound of x
    cert_mu: float | None = None             # its certified multiplier error, beyond the rounding floor of mu*
    contact_mismatch: int | None = None
    ref_solver: str | None = None
    ref_kkt: float | None = None
    ref_bound: float | None = None
    axis: str | None = None
    coords: dict = field(default_factory=dict)
    exact: bool | None = None
    third_party: bool | None = None
    started_utc: str | None = None
    loadavg: float | None = None
    cpu: str | None = None
    cores: int | None = None
    affinity: int | None = None
    threads: str | None = None
    python: str | None = None
    platform: str | None = None
    versions: str | None = None
    git: str | None = None
    extra: dict = field(default_factory=dict)

    # -------------------------------------------------------- dict-style access
    def __getitem__(self, key: str) -> Any:
        if key in _NAMES:
            return getattr(self, key)
        return self.extra[key]

    def __setitem__(self, key: str, value: Any) -> None:
        if key in _NAMES:
            setattr(self, key, value)
        else:
            self.extra[key] = value

    def get(self, key: str, default: Any = None) -> Any:
        """Like ``dict.get`` over the fields and ``extra``."""
        try:
            v = self[key]
        except KeyError:
            return default
        return default if v is None else v

    def update(self, values: dict | None = None, **kw: Any) -> None:
        """Set several fields (unknown names go to ``extra``)."""
        for k, v in {**(values or {}), **kw}.items():
            self[k] = v

    # ----------------------------------------------------------------- grading
    def set_residuals(self, res: dict | None, tol: float | None) -> None:
        """Copy the evaluator's residuals; ``within_tol`` = KKT error <= ``tol``."""
        if not res or not res.get("finite", True):
            self.kkt_error, self.within_tol = None, False
            return
        for k in RESIDUALS:
            self[k] = res[k]
        self.kkt_error = max(res[k] for k in RESIDUALS)
        self.within_tol = bool(tol is not None and math.isfinite(tol) and self.kkt_error <= tol)

    def regrade(self) -> str:
        """Set :attr:`grade_x`, :attr:`grade_mu` and :attr:`grade` (returned) from the row's status, claim,
        errors, certificates, KKT error and tolerance: the one judge's grading of facts,
        :func:`dualfem.verify.judge.outcome` (a stored row has no QP to re-judge).

        ``grades`` None (compare, stress: runs certified at the declared tolerance, x and multipliers
        both): the grade of the certified status and x's error, as before grades were separated. Under
        ``"x,mu"`` a run the runner demoted for its multipliers alone keeps a ``grade_x`` of its x.
        """
        self.grade, self.grade_x, self.grade_mu = outcome(
            self.status or "error", self.tol, self.kkt_error, self.err_x_energy, self.err_multipliers,
            self.ref_bound, self.cert_x, self.cert_mu, self.claimed_status, self.grades)
        return self.grade

    def facts(self) -> Verdict:
        """The row's facts as a :class:`dualfem.verify.Verdict` (status, claim, tolerance, KKT error,
        certificates, grades), to be judged against a reference (:func:`dualfem.verify.against`)."""
        return Verdict(outcome=self.grade or "", status=self.status or "error", claim=self.claimed_status or "",
                       tol=self.tol if self.tol is not None else float("nan"), kkt=self.kkt_error,
                       cert_x=self.cert_x, cert_mu=self.cert_mu)

    def take(self, v: Verdict) -> str:
        """Copy a judged verdict's measurements against its reference (``err_*``, ``contact_mismatch``,
        ``ref_solver``, ``ref_bound``; only when it was measured) and its grades; returns the grade."""
        if v.diff is not None:
            d = v.diff
            self.update(err_x_energy=d["x_energy"], err_x_max=d["x_max"], err_multipliers=d["multipliers"],
                        err_energy=d["energy"], contact_mismatch=d["contact_mismatch"], ref_solver=v.ref_solver,
                        ref_bound=v.ref_bound)
        self.grade, self.grade_x, self.grade_mu = v.outcome, v.grade_x, v.grade_mu
        return self.grade

    def set_certificate(self, cert: dict | None) -> None:
        """Copy the runner's certificate (``Solution.info["certificate"]``): ``cert_x`` its energy-norm
        bound, ``cert_mu`` its multiplier error beyond the rounding floor of mu* (None when absent;
        :func:`dualfem.verify.judge.cert_facts`)."""
        self.cert_x, self.cert_mu = cert_facts(cert)

    # ----------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """Flat JSON-safe dict (``extra`` merged in; non-finite floats as None)."""
        out = {f: jsonable(getattr(self, f)) for f in _NAMES}
        out.update({k: jsonable(v) for k, v in self.extra.items()})
        return out

    def csv_record(self) -> dict:
        """Flat dict for CSV: dicts and lists as JSON text."""
        return {k: (json.dumps(v, sort_keys=True) if isinstance(v, (dict, list)) else v)
                for k, v in self.to_dict().items()}

    @classmethod
    def from_dict(cls, d: dict) -> Row:
        """A row from a dict (e.g. a CSV or JSON record); JSON text of dict fields, of ``scene`` and of
        extra keys (``{...}``, ``[...]``) is parsed."""
        row = cls()
        for k, v in d.items():
            if k in _DICT_FIELDS and isinstance(v, str):
                try:
                    v = json.loads(v) if v else {}
                except ValueError:
                    v = {"text": v}
            elif (k == "scene" or k not in _NAMES) and isinstance(v, str) and v[:1] in ("{", "["):
                try:        # a dict or list (a stress scene's parameters, an extra) written to CSV as JSON text
                    v = json.loads(v)
                except ValueError:
                    pass
            row[k] = v
        return row


_NAMES = tuple(f.name for f in fields(Row) if f.name != "extra")
_DICT_FIELDS = {"solver_params", "iterations", "coords"}
#: the columns of results.csv, in order (a row's ``extra`` keys follow, sorted)
COLUMNS = list(_NAMES)
