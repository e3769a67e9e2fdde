"""The frictional problems of the public test set (``dualfem testset``): 2D and 3D, Tresca and Coulomb, small and
medium, each with a certified reference; their files, and the scoring of an answer by dualfem's one judge.

A frictional problem is not a QP of qpsolvers' form ``G x <= h`` (3D Tresca has second-order cones, Coulomb is
quasi-variational), so it is not part of the qpbenchmark ``TestSet``: it is written in dualfem's own convention,
and the Coulomb problems also in FCLIB's global format (the frictional contact benchmark format). Under
``DIR/friction/``:

* ``qp/NAME.npz`` (:func:`write_problem`): ``K``, ``B`` and every friction block's ``G`` as CSC arrays
  (``M_data``, ``M_indices``, ``M_indptr``, ``M_shape``), ``F``, ``weights`` (normal rows), and per friction block k
  (``blocks`` of them, in the QP's order): ``b{k}_G_*``, ``b{k}_weights`` (per row), ``b{k}_law`` (``tresca`` |
  ``coulomb``), ``b{k}_components`` (1: 2D, 2: 3D; rows node-major), ``b{k}_value`` (per friction node: Tresca's
  threshold g, stress units, or Coulomb's coefficient mu_f), ``b{k}_normal_rows`` (Coulomb: the normal row of each
  friction node); ``name``, ``convention`` (:data:`CONVENTION`). :func:`read_problem` gives the dualfem QP back.
* ``reference/NAME.npz`` (:func:`write_reference`): ``x``, ``mu`` (every block's multipliers stacked: normal forces
  first, then the friction forces; ``K x - F = G' mu``), ``certified_error``, ``kkt_error``, ``solver``, ``name``.
* ``fclib/NAME.hdf5`` (Coulomb only): FCLIB's global problem (:func:`dualfem.core.fclib.fclib_global`) and, in its
  ``/solution`` group as ``fclib_write_solution`` lays it out, the reference: ``v = x``, ``r`` (per contact: the
  normal force, then the friction forces), ``u = H'v + w``.

The references come from the same policy as the QPs' (:func:`dualfem.experiments.testset.certified_reference`:
an exact solver's answer with certified error and KKT error <= 1e-8; pdas's monolithic semismooth Newton here).
For Coulomb the certificate is that of the Tresca problem whose threshold is the answer's own ``mu_f lambda``
(Coulomb has no duality gap of its own: docs/friction.md). :func:`score` judges any answer (x, mu) with
:func:`dualfem.verify.judge.judge`, the judge of ``dualfem solve`` and ``compare``: the laws' residuals, the
certificate and the distance to the reference.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualfem.core.constraints import Constraint
from dualfem.core.errors import InputError
from dualfem.core.laws import Coulomb, Friction, Tresca
from dualfem.core.qp import QP
from dualfem.experiments import testset_files as files

FRICTION_DIR = "friction"
FCLIB_DIR = "fclib"
CONVENTION = ("dualfem: minimize 1/2 x'Kx - F'x + sum_j r_j ||s_j|| subject to B x >= 0, s = G_k x the tangential "
              "jumps of friction block k (r_j = g_j w_j Tresca; Coulomb: r_j = mu_f,j max(lambda_j, 0), a "
              "quasi-variational problem); multipliers mu = (lambda, friction forces) with K x - F = B'lambda + "
              "sum_k G_k' mu_k, lambda >= 0, ||mu_j|| <= r_j, mu_j = -r_j s_j / ||s_j|| where s_j != 0")
LAWS = {"tresca": Tresca, "coulomb": Coulomb}

#: the 2D inclined closed crack of reports/friction.md: a crack of half-length 0.05 at 30 degrees through the
#: centre of the unit square, compression 1 across y and 0.2 across x (E = 1000, nu = 0.3, delta = 1e3)
_TH = np.radians(30.0)
_D = 0.05 * np.array([np.cos(_TH), np.sin(_TH)])
INCLINED = {"mesh": "gmsh", "mesh_size": 0.01, "tip_size": 0.002, "E": 1000.0, "nu": 0.3, "delta": 1e3,
            "remote_stress": [[-0.2, 0.0], [0.0, -1.0]],
            "defects": [{"points": [[float(v) for v in 0.5 - _D], [float(v) for v in 0.5 + _D]]}]}
#: the penny of reports/friction.md under compression 1 and shear 0.5 on its plane
PENNY = {"E": 1000.0, "nu": 0.3, "delta": 1e3, "remote_stress": [[0.0, 0.0, 0.5], [0.0, 0.0, 0.0], [0.5, 0.0, -1.0]]}


def _tresca(g: float) -> dict:
    return {"friction": "tresca", "friction_bound": g}


def _coulomb(mu_f: float) -> dict:
    return {"friction": "coulomb", "friction_coefficient": mu_f}


def declared() -> tuple:
    """Every frictional problem of the test set, in publication order (names are stable)."""
    from dualfem.experiments.testset import Declared

    def d(size, name, scene, **params):
        return Declared(size, name, scene, params)

    return (
        d("small", "f2_N32_tresca_g0.2", "f2", N=32, **_tresca(0.2)),
        d("small", "f2_N32_coulomb_mu0.3", "f2", N=32, **_coulomb(0.3)),
        d("small", "three_d_N6_tresca_g0.05", "three_d", N=6, **_tresca(0.05)),
        d("small", "three_d_N6_coulomb_mu0.3", "three_d", N=6, **_coulomb(0.3)),
        d("small", "penny_h1_tresca_g0.2", "penny", mesh_size=1.0, tip_size=0.25, **PENNY, **_tresca(0.2)),
        d("small", "penny_h1_coulomb_mu0.2", "penny", mesh_size=1.0, tip_size=0.25, **PENNY, **_coulomb(0.2)),
        d("medium", "inclined30_h0.01_tresca_g0.1", "f2", **INCLINED, **_tresca(0.1)),
        d("medium", "inclined30_h0.01_coulomb_mu0.2", "f2", **INCLINED, **_coulomb(0.2)),
        d("medium", "fractured_c50_coulomb_mu0.3", "fractured", cracks=50,
          remote_stress=[[-1.0, 0.4], [0.4, -1.0]], **_coulomb(0.3)),
        d("medium", "penny_h0.5_tresca_g0.2", "penny", mesh_size=0.5, tip_size=0.2, **PENNY, **_tresca(0.2)),
        d("medium", "penny_h0.5_coulomb_mu0.2", "penny", mesh_size=0.5, tip_size=0.2, **PENNY, **_coulomb(0.2)),
    )


@dataclass
class FrictionEntry:
    """What the manifest says about one frictional problem (sizes in unknowns, rows and bytes)."""

    name: str
    size: str
    scene: str
    overrides: dict[str, Any]
    dim: int
    law: str
    n: int
    m: int
    m_friction: int
    friction_nodes: int
    slipping_nodes: int
    reference: dict[str, Any]
    files: dict[str, str]
    bytes: int
    seconds: float
    values: list[float] = field(default_factory=list)


def friction_blocks(qp: QP) -> list[Constraint]:
    """The QP's friction blocks; InputError for a shifted QP, one without friction, or another law."""
    if qp.shift is not None:
        raise InputError(f"QP {qp.name!r} is shifted: the test set takes only unshifted contact problems")
    blocks = list(qp.blocks)
    if not blocks or not all(isinstance(b.law, (Tresca, Coulomb)) for b in blocks):
        raise InputError(f"QP {qp.name!r} is not a frictional problem (its extra blocks: "
                         f"{', '.join(b.law.name for b in blocks) or 'none'}); set friction = 'tresca' or 'coulomb'")
    return blocks


def _per_node(law: Friction, nodes: int, which: str) -> np.ndarray:
    return np.broadcast_to(np.asarray(getattr(law, which), float), (nodes,)).copy()


def write_problem(path: Path, name: str, qp: QP) -> Path:
    """Write the frictional QP ``qp`` (module docstring), atomically."""
    arrays: dict[str, np.ndarray] = {**files._csc_arrays("K", qp.K), "F": np.asarray(qp.F, float),
                                     **files._csc_arrays("B", qp.B), "weights": np.asarray(qp.constraints[0].weights),
                                     "name": np.array(name), "convention": np.array(CONVENTION)}
    blocks = friction_blocks(qp)
    arrays["blocks"] = np.array(len(blocks))
    for k, b in enumerate(blocks):
        law = b.law
        assert isinstance(law, (Tresca, Coulomb))
        nodes = b.m // law.components
        arrays.update({**files._csc_arrays(f"b{k}_G", b.G), f"b{k}_weights": np.asarray(b.weights, float),
                       f"b{k}_law": np.array(law.name), f"b{k}_components": np.array(law.components)})
        if isinstance(law, Tresca):
            arrays[f"b{k}_value"] = _per_node(law, nodes, "bound")
        else:
            if law.normal_block != 0:
                raise InputError(f"QP {name!r}: a Coulomb block reading another block's normals is not written")
            arrays[f"b{k}_value"] = _per_node(law, nodes, "coefficient")
            rows = np.arange(nodes) if law.normal_rows is None else law.normal_rows
            arrays[f"b{k}_normal_rows"] = np.asarray(rows, np.int64)
    return files._save(path, arrays)


def read_problem(path: str | Path) -> QP:
    """The dualfem QP of a file written by :func:`write_problem` (its friction blocks and laws rebuilt)."""
    with np.load(path, allow_pickle=False) as d:
        K, B = files._csc(d, "K"), files._csc(d, "B")
        blocks = []
        for k in range(int(d["blocks"])):
            law_name, c = str(d[f"b{k}_law"]), int(d[f"b{k}_components"])
            value = np.array(d[f"b{k}_value"])
            law = Tresca(value, components=c) if law_name == "tresca" else \
                Coulomb(value, components=c, normal_rows=np.array(d[f"b{k}_normal_rows"]))
            blocks.append(Constraint.make(files._csc(d, f"b{k}_G"), np.array(d[f"b{k}_weights"]), law))
        return QP(K=K.tocsc(), F=np.array(d["F"]), B=B.tocsr(), weights=np.array(d["weights"]), name=str(d["name"]),
                  blocks=tuple(blocks))


@dataclass
class FrictionReference:
    """A certified reference of one frictional problem (units of the scene; the QP's sign)."""

    x: np.ndarray
    mu: np.ndarray
    certified_error: float
    solver: str


def write_reference(path: Path, name: str, x: np.ndarray, mu: np.ndarray, info: dict[str, Any]) -> Path:
    """Write one reference (module docstring), atomically."""
    return files._save(path, {"x": np.asarray(x, float), "mu": np.asarray(mu, float),
                              "certified_error": np.array(info["certified_error"]),
                              "kkt_error": np.array(info["kkt_error"]), "solver": np.array(info["solver"]),
                              "name": np.array(name), "convention": np.array(CONVENTION)})


def read_reference(path: str | Path) -> FrictionReference:
    """The :class:`FrictionReference` of a file written by :func:`write_reference`."""
    with np.load(path, allow_pickle=False) as d:
        return FrictionReference(np.array(d["x"]), np.array(d["mu"]), float(d["certified_error"]), str(d["solver"]))


def fclib_solution(qp: QP, prob, x: np.ndarray, mu: np.ndarray) -> dict[str, np.ndarray]:
    """FCLIB's solution ``(v, u, r)`` of the global problem ``prob`` (:func:`dualfem.core.fclib.fclib_global` of
    ``qp``) for the answer (x, mu): ``v = x``, per contact a ``r_a = (lambda_a, friction forces of its node)`` (0
    where the contact has no Coulomb friction), ``u = H'v + w``; then ``M v = H r + f`` (the QP's stationarity)."""
    d, m = prob.spacedim, qp.m
    r = np.zeros(d * m)
    r[::d] = mu[:m]
    start = m
    for b in qp.blocks:
        law = b.law
        if isinstance(law, Coulomb):
            nodes = b.m // law.components
            rows = np.arange(nodes) if law.normal_rows is None else law.normal_rows
            force = mu[start:start + b.m].reshape(nodes, law.components)
            r.reshape(m, d)[rows, 1:] = force
        start += b.m
    return {"v": np.asarray(x, float), "u": prob.H.T @ x + prob.w, "r": r}


def write_fclib_with_solution(path: Path, qp: QP, name: str, x: np.ndarray, mu: np.ndarray) -> Path:
    """FCLIB's global problem of the Coulomb QP ``qp`` and its reference in ``/solution``, atomically."""
    import h5py

    from dualfem.core.fclib import fclib_global, write_fclib
    from dualfem.core.io import atomic_write

    prob = fclib_global(qp, title=name, description=f"dualfem test set problem {name}: {qp.n} unknowns, "
                                                    f"{qp.m} contacts; /solution holds the certified reference")
    sol = fclib_solution(qp, prob, x, mu)

    def write(tmp: str) -> None:
        write_fclib(tmp, prob)
        with h5py.File(tmp, "a") as fh:
            g = fh.create_group("solution")
            for key in ("v", "u", "r"):
                g.create_dataset(key, data=np.asarray(sol[key], np.float64))
    return atomic_write(path, write)


def _slipping(qp: QP, x: np.ndarray) -> tuple[int, int]:
    """(friction nodes, nodes whose tangential jump exceeds 1e-9 of the largest jump of the QP)."""
    total = slip = 0
    scale = float(np.abs(qp.G @ x).max(initial=0.0))
    for b in qp.blocks:
        s = np.linalg.norm(np.asarray(b.G @ x).reshape(-1, b.law.components), axis=1)
        total += s.size
        slip += int(np.count_nonzero(s > 1e-9 * scale))
    return total, slip


def build_entry(d, problem, out: Path) -> FrictionEntry:
    """Assemble, certify and write one declared frictional problem; its manifest entry."""
    from dualfem.core.scene import build_qp
    from dualfem.experiments.testset import certified_reference

    t0 = time.perf_counter()
    qp = build_qp(problem)
    blocks = friction_blocks(qp)
    x, mu, cert, solver, kkt = certified_reference(qp, d.name)
    law = "coulomb" if any(isinstance(b.law, Coulomb) for b in blocks) else "tresca"
    root = out / FRICTION_DIR
    paths = {"qp": root / files.QP_DIR / f"{d.name}.npz", "reference": root / files.REF_DIR / f"{d.name}.npz"}
    write_problem(paths["qp"], d.name, qp)
    info = {"solver": solver, "certified_error": cert["value"], "duality_gap_bound": cert["bound"],
            "face_step": cert["active_set"], "infeasible_bound": cert["infeasible"],
            "multiplier_error": cert["multipliers"], "kkt_error": kkt}
    write_reference(paths["reference"], d.name, x, mu, info)
    if law == "coulomb":
        paths["fclib"] = root / FCLIB_DIR / f"{d.name}.hdf5"
        write_fclib_with_solution(paths["fclib"], qp, d.name, x, mu)
    nodes, slip = _slipping(qp, x)
    vals = np.concatenate([np.atleast_1d(b.law.bound if isinstance(b.law, Tresca) else b.law.coefficient)
                           for b in blocks])
    return FrictionEntry(name=d.name, size=d.size, scene=d.scene, overrides=dict(d.params),
                         dim=3 if blocks[0].law.components == 2 else 2, law=law, n=qp.n, m=qp.m,
                         m_friction=sum(b.m for b in blocks), friction_nodes=nodes, slipping_nodes=slip,
                         reference=info, files={k: str(p.relative_to(out)) for k, p in paths.items()},
                         bytes=sum(p.stat().st_size for p in paths.values()), seconds=time.perf_counter() - t0,
                         values=[float(vals.min()), float(vals.max())])


def stale_files(out: Path, old: dict, names: set[str]) -> list[Path]:
    """The files of the frictional problems an old manifest (``old``) lists and the new set lacks."""
    try:
        listed = [p["name"] for p in old["friction"]["problems"]]
    except (KeyError, TypeError):
        return []
    root = out / FRICTION_DIR
    return [root / sub / f"{n}{ext}" for n in listed if isinstance(n, str) and n not in names
            and files.NAME_PATTERN.fullmatch(n)
            for sub, ext in ((files.QP_DIR, ".npz"), (files.REF_DIR, ".npz"), (FCLIB_DIR, ".hdf5"))]


@dataclass
class FrictionScore:
    """How an answer (x, mu) to a frictional problem is judged: the judge's certified ``status`` of a ``solved``
    claim at ``tol``, its ``outcome`` against the reference, the certified error bound ``cert_x``, the errors
    against the reference ``err_x`` (relative energy norm) and ``err_mu``, the evaluator's ``kkt`` and ``why``."""

    status: str
    outcome: str
    cert_x: float | None
    err_x: float | None
    err_mu: float | None
    kkt: float | None
    why: str


def score(problem: str | Path | QP, reference: str | Path | FrictionReference, x: np.ndarray, mu: np.ndarray,
          tol: float = 1e-6, exact: bool = True) -> FrictionScore:
    """Judge the answer (x, mu) to a frictional problem (a file of :func:`write_problem` or its QP) claimed
    ``solved`` at tolerance ``tol``, with :func:`dualfem.verify.judge.judge` (``exact``: the solver declares itself
    exact; an inexact one needs a finite bound) against the reference (a file or a :class:`FrictionReference`)."""
    from dualfem.core.evaluator import residuals
    from dualfem.core.solution import Solution, Status
    from dualfem.verify.judge import Answer, judge

    qp = problem if isinstance(problem, QP) else read_problem(problem)
    ref = reference if isinstance(reference, FrictionReference) else read_reference(reference)
    x, mu = np.asarray(x, float), np.asarray(mu, float)
    if x.shape != (qp.n,) or mu.shape != (qp.m_total,):
        raise InputError(f"an answer to {qp.name!r} needs x of length {qp.n} and mu of length {qp.m_total}")
    sol = Solution(solver="answer", status=Status.SOLVED, x=x, multipliers=mu)
    sol.residuals = residuals(qp, x, mu)
    v = judge(qp, sol, tol, exact=exact, reference=Answer(ref.solver, ref.x, ref.mu, ref.certified_error))
    return FrictionScore(v.status, v.outcome, v.cert_x, v.err_x, v.err_mu, v.kkt, v.why)
