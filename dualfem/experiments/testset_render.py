"""What a written test set says about itself (:mod:`dualfem.experiments.testset`): ``manifest.json``,
``README.md`` with its size table, and the qpbenchmark ``TestSet`` module (self-contained: it needs numpy,
scipy and qpbenchmark, not dualfem)."""
from __future__ import annotations

from dualfem.experiments.testset_files import (
    CONVENTION,
    FORMAT,
    MANIFEST,
    QP_DIR,
    REF_DIR,
    RUNTIME,
    TESTSET_CLASS,
    TESTSET_PY,
)


def size_table(problems: list[dict]) -> list[dict]:
    """One row per size class: problems, unknowns, constraints, nonzeros of P and G, bytes on disk."""
    rows = []
    for size in dict.fromkeys(p["size"] for p in problems):
        ps = [p for p in problems if p["size"] == size]
        rows.append({"size": size, "problems": len(ps),
                     "unknowns": [min(p["n"] for p in ps), max(p["n"] for p in ps)],
                     "constraints": [min(p["m"] for p in ps), max(p["m"] for p in ps)],
                     "nnz_P": [min(p["nnz_P"] for p in ps), max(p["nnz_P"] for p in ps)],
                     "nnz_G": [min(p["nnz_G"] for p in ps), max(p["nnz_G"] for p in ps)],
                     "bytes": sum(p["bytes_qp"] + p["bytes_reference"] for p in ps)})
    return rows


def manifest(entries: list, sizes: tuple[str, ...], *, bound_max: float, kkt_max: float,
             friction: list | None = None) -> dict:
    """The manifest of a written test set (``entries``: :class:`dualfem.experiments.testset.Entry`; each
    reference's certified error was at most ``bound_max``, its evaluator KKT error at most ``kkt_max``;
    ``friction``: the :class:`dualfem.experiments.testset_friction.FrictionEntry` of its frictional problems)."""
    import dataclasses
    import time
    from importlib.metadata import PackageNotFoundError, version

    problems = []
    for e in entries:
        p = dataclasses.asdict(e)
        p["files"] = {"qp": f"{QP_DIR}/{e.name}.npz", "reference": f"{REF_DIR}/{e.name}.npz"}
        problems.append(p)
    vers = {}
    for pkg in ("dualfem", "numpy", "scipy", "scikit-fem", "gmsh", "qpsolvers", "qpbenchmark"):
        try:
            vers[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    largest = [s for s in RUNTIME if s in {e.size for e in entries}][-1]
    return {
        "format": FORMAT,
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "versions": vers,
        "sizes": list(sizes),
        "convention": CONVENTION,
        "dualfem_convention": "dualfem's QP: minimize 1/2 x'Kx - F'x subject to B x >= 0, multipliers mu >= 0 "
                              "with K x - F = B'mu; here P = K, q = -F, G = -B, h = 0, z = mu",
        "units": {"x": "mm (displacements of the unclamped nodes)",
                  "P": "MPa (force per mm of thickness per mm of displacement; E in MPa)",
                  "q": "N per mm of thickness",
                  "z": "N per mm of thickness (nodal contact forces, >= 0 in compression)",
                  "objective": "N.mm per mm of thickness"},
        "certification": "reference = dualfem.experiments.reference.compute (the reference policy of dualfem "
                         f"compare / bench): an exact solver's answer, its evaluator KKT error <= {kkt_max:g} and its "
                         "certified relative energy-norm error |x - x*|_K / |x*|_K (dualfem.numerics.certify."
                         "certified_error: the smaller of a duality-gap bound and the exact step onto the "
                         f"verified active set) <= {bound_max:g}",
        "testset": {"file": TESTSET_PY, "class": TESTSET_CLASS, "runtime_s": RUNTIME[largest]},
        "size_table": size_table(problems),
        "problems": problems,
        **({"friction": friction_manifest(friction, bound_max, kkt_max)} if friction else {}),
    }


def friction_manifest(entries: list, bound_max: float, kkt_max: float) -> dict:
    """The ``friction`` section of the manifest: the frictional problems' format, convention and entries."""
    import dataclasses

    from dualfem.experiments.testset_friction import CONVENTION as FRICTION_CONVENTION
    from dualfem.experiments.testset_friction import FRICTION_DIR

    return {"folder": FRICTION_DIR, "format": "dualfem-friction-testset/1", "convention": FRICTION_CONVENTION,
            "certification": f"as the QPs' (certified error <= {bound_max:g}, KKT error <= {kkt_max:g}); a Coulomb "
                             "answer is certified as the Tresca problem whose threshold is its own mu_f lambda",
            "fclib": "Coulomb problems also as FCLIB global problems (HDF5: /fclib_global M, H, f, w, mu), the "
                     "reference in /solution (v = x, u = H'v + w, r per contact: normal force, friction forces)",
            "problems": [dataclasses.asdict(e) for e in entries]}


def friction_markdown(man: dict) -> str:
    """One line per frictional problem: dimension, law, sizes, slipping nodes, the reference's certificate."""
    lines = ["| problem | size | scene | law | n | normal rows | friction nodes (slipping) | certified error | "
             "reference | files |", "|---|---|---|---|---|---|---|---|---|---|"]
    for p in man.get("friction", {}).get("problems", []):
        v = p["values"]
        value = f"{v[0]:g}" if v[0] == v[1] else f"{v[0]:g}-{v[1]:g}"
        what = f"{p['dim']}D {p['law']} ({'g' if p['law'] == 'tresca' else 'mu_f'} = {value})"
        lines.append(f"| {p['name']} | {p['size']} | {p['scene']} | {what} | {p['n']:,} | {p['m']:,} | "
                     f"{p['friction_nodes']:,} ({p['slipping_nodes']:,}) | {p['reference']['certified_error']:.1e} | "
                     f"{p['reference']['solver']} | {_mb(p['bytes'])} |")
    return "\n".join(lines)


def _mb(b: float) -> str:
    return f"{b / 1e6:.2f} MB" if b >= 1e5 else f"{b / 1e3:.1f} kB"


def _span(v: list) -> str:
    return f"{v[0]:,}" if v[0] == v[1] else f"{v[0]:,} - {v[1]:,}"


def size_markdown(man: dict) -> str:
    """The size table of a manifest, as Markdown."""
    lines = ["| size | problems | unknowns n | constraints m | nnz(P) | nnz(G) | files |",
             "|---|---|---|---|---|---|---|"]
    for r in man["size_table"]:
        lines.append(f"| {r['size']} | {r['problems']} | {_span(r['unknowns'])} | {_span(r['constraints'])} | "
                     f"{_span(r['nnz_P'])} | {_span(r['nnz_G'])} | {_mb(r['bytes'])} |")
    return "\n".join(lines)


def problems_markdown(man: dict) -> str:
    """One line per problem: scene, delta, sizes, objective, the reference's certificate, file sizes."""
    lines = ["| problem | size | scene | delta | n | m | nnz(P) | objective | certified error | reference | files |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for p in man["problems"]:
        over = ", ".join(f"{k}={v}" for k, v in p["overrides"].items() if k != "delta")
        lines.append(f"| {p['name']} | {p['size']} | {p['scene']}{f' ({over})' if over else ''} | "
                     f"{p['delta']:g} | {p['n']:,} | {p['m']:,} | {p['nnz_P']:,} | {p['objective']:.12g} | "
                     f"{p['reference']['certified_error']:.1e} | {p['reference']['solver']} | "
                     f"{_mb(p['bytes_qp'] + p['bytes_reference'])} |")
    return "\n".join(lines)


def _range(man: dict, key: str) -> str:
    vals = [p[key] for p in man["problems"]]
    return f"{min(vals):.2g} to {max(vals):.2g}"


def readme(man: dict) -> str:
    """The README of a written test set."""
    ts = man["testset"]
    return f"""# dualfem contact QPs: a qpbenchmark test set

Written by `dualfem testset` ({man['versions'].get('dualfem', '?')}) on {man['created']}; size classes:
{', '.join(man['sizes'])}. Each problem is the contact QP of a 2D elastic body with thin defects (cracks)
(Zhiltsov & Maksimova 2023; P1 elements, plane strain unless the scene says otherwise), with a certified
reference solution.

## Convention

    minimize 1/2 x'Px + q'x   subject to   G x <= h

qpsolvers' convention: P = K (stiffness + 1/delta interface term, SPD), q = -F (the load), G = -B
(B x = the normal jumps across the defects, >= 0: no interpenetration), h = 0. No A, b, lb, ub.
dualfem's own QP files read `B x >= h`; these files are not dualfem QP files. The multipliers z of
`G x <= h` are dualfem's contact forces mu >= 0: P x + q + G'z = 0, G x <= 0, z >= 0, z'(G x) = 0.

Units: {'; '.join(f'{k} in {v}' for k, v in man['units'].items())}. The residuals qpbenchmark
reports are absolute in these units. In this set max|P| is {_range(man, 'max_abs_P')} (the 1/delta
interface term: the small-delta problems are badly scaled on purpose), max|q| {_range(man, 'max_abs_q')},
|x| about 1e-5 mm, and the objectives {_range(man, 'objective')}: judge qpbenchmark's absolute
tolerances (1e-3 at low accuracy) against that scale.

## Files

* `{ts['file']}`: the qpbenchmark `TestSet` (class `{ts['class']}`, sparse solvers only, time limit
  {ts['runtime_s']:g} s per solve), loading the problems in the order of `manifest.json`.
* `{QP_DIR}/NAME.npz`: `P_data`, `P_indices`, `P_indptr`, `P_shape` (CSC, both triangles), `q`, `G_*` (CSC), `h`.
* `{REF_DIR}/NAME.npz`: `x`, `z`, `objective` (1/2 x'Px + q'x), `certified_error`, `solver`.
* `manifest.json`: every problem's scene parameters, sizes, objective, the reference's certificate and
  residuals, file sizes; versions of the generator.

## How the references were certified

{man['certification']}. Residuals of each reference in qpsolvers' terms are in `manifest.json`
(`reference.residuals`). To check a solver's (x, z) against a reference without choosing a tolerance, use
its own a-posteriori bounds: with r = P x + q + G'z (z >= 0) and s = max(G x - h, 0),
-z_ref's <= f(x) - f* <= x'Px + q'x + h'z - r'x + 1/2 r'P^-1 r, and |x - x*|_P^2 <= 2 (that upper bound +
z_ref's) (`dualfem.experiments.testset_files.agreement` does this, with the reference's own error and rounding).

## Run it

    pip install qpbenchmark
    python {ts['file']} run --solver clarabel --author NAME
    # or: qpbenchmark {ts['file']} --results-path results/dualfem_contact.csv run --author NAME

Results go to `results/dualfem_contact.csv` (one row per problem, solver and settings: runtime, found,
primal and dual residuals, duality gap) and the report to `results/dualfem_contact.md`. Run all four
settings (default, low/mid/high accuracy): qpbenchmark 2.7.1 writes the CSV of a `--settings` run too, but
its report then stops on the settings that were not run. Without `--solver`, every installed sparse
solver of qpsolvers runs.

## Sizes

{size_markdown(man)}

## Problems

{problems_markdown(man)}
{_friction_readme(man)}"""


def _friction_readme(man: dict) -> str:
    if "friction" not in man:
        return ""
    f = man["friction"]
    return f"""
## Frictional problems (`{f['folder']}/`, not part of the qpbenchmark TestSet)

{f['convention']}.

Files: `{f['folder']}/qp/NAME.npz` (K, F, B, weights and per friction block k `b{{k}}_G`, `b{{k}}_weights`,
`b{{k}}_law`, `b{{k}}_components`, `b{{k}}_value`, `b{{k}}_normal_rows`; read with
`dualfem.experiments.testset_friction.read_problem`), `{f['folder']}/reference/NAME.npz` (`x`, `mu`,
`certified_error`, `kkt_error`, `solver`), and for Coulomb `{f['folder']}/fclib/NAME.hdf5`: {f['fclib']}.
References: {f['certification']}. Score an answer with `dualfem.experiments.testset_friction.score` (the judge of
`dualfem solve`: the laws' residuals, the certificate, the distance to the reference).

{friction_markdown(man)}
"""


def testset_source(man: dict) -> str:
    """The qpbenchmark test-set module: self-contained (numpy, scipy, qpbenchmark), no dualfem needed."""
    ts = man["testset"]
    return f'''"""dualfem contact QPs: a qpbenchmark test set (written by `dualfem testset`; see README.md).

Problems: min 1/2 x'Px + q'x s.t. G x <= h (qpsolvers' convention), read from {QP_DIR}/NAME.npz in the
order of manifest.json. Run: python {ts['file']} run --solver clarabel --author NAME
"""

import json
import os
from pathlib import Path

import numpy as np
import scipy.sparse as spa
from qpbenchmark import Problem, TestSet

HERE = Path(__file__).resolve().parent


def _csc(d, prefix):
    shape = tuple(int(s) for s in d[prefix + "_shape"])
    return spa.csc_matrix((d[prefix + "_data"], d[prefix + "_indices"], d[prefix + "_indptr"]), shape=shape)


def load_problem(name):
    """The problem NAME as a qpbenchmark Problem (sparse P and G)."""
    with np.load(HERE / "{QP_DIR}" / (name + ".npz"), allow_pickle=False) as d:
        return Problem(_csc(d, "P"), np.array(d["q"]), _csc(d, "G"), np.array(d["h"]), None, None, None, None,
                       name=name)


class {ts['class']}(TestSet):
    """Contact problems of 2D elastic bodies with thin defects, with certified references."""

    @property
    def description(self) -> str:
        return ("Contact QPs of 2D elastic bodies with thin defects (cracks), from dualfem; "
                "certified reference solutions in {REF_DIR}/")

    @property
    def title(self) -> str:
        return "dualfem contact test set"

    @property
    def sparse_only(self) -> bool:
        return True

    def define_tolerances(self, runtime: float = {ts['runtime_s']!r}) -> None:
        super().define_tolerances(runtime=runtime)

    def __init__(self):
        manifest = json.loads((HERE / "{MANIFEST}").read_text(encoding="utf-8"))
        self.problem_names = [p["name"] for p in manifest["problems"]]
        super().__init__()

    def __iter__(self):
        for name in self.problem_names:
            yield load_problem(name)


if __name__ == "__main__":
    from qpbenchmark.benchmark import main

    os.makedirs(HERE / "results", exist_ok=True)
    main(test_set_path=os.path.abspath(__file__),
         results_path=str(HERE / "results" / "{TESTSET_PY.replace('.py', '.csv')}"))
'''
