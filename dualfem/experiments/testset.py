"""A public test set of contact QPs for qpbenchmark: the declared scenes, their certified references.

``dualfem testset --out DIR`` (:func:`write_testset`) builds every declared scene (:data:`DECLARED`) of
the chosen size classes (:data:`SIZES`), certifies a reference solution of each with the reference
policy ``dualfem compare`` and ``dualfem bench`` use (:func:`dualfem.experiments.reference.compute`,
tightened to :data:`REF_BOUND_MAX`; its certificate by :func:`dualfem.numerics.certify.certified_error`),
and writes, in the formats of :mod:`dualfem.experiments.testset_files`:

* ``DIR/qp/NAME.npz``: the QP in qpsolvers' convention ``min 1/2 x'Px + q'x  s.t.  G x <= h`` with
  ``P = K``, ``q = -F``, ``G = -B``, ``h = 0`` (dualfem's ``B x >= 0`` turned round);
* ``DIR/reference/NAME.npz``: x, the multipliers ``z = mu >= 0`` (qpsolvers' z of ``G x <= h``:
  ``P x + q + G'z = 0``), the objective ``1/2 x'Px + q'x`` and the certificate;
* ``DIR/dualfem_contact.py``: a qpbenchmark ``TestSet`` (class ``DualfemContact``) that loads them;
* ``DIR/manifest.json`` and ``DIR/README.md``: sizes, conventions, units, provenance;
* ``DIR/friction/``: the frictional problems of the chosen classes (Tresca and Coulomb, 2D and 3D: not QPs of
  qpsolvers' form, so outside the qpbenchmark TestSet), with certified references and FCLIB files for Coulomb
  (:mod:`dualfem.experiments.testset_friction`; ``friction=False`` leaves them out).

Adding a scene is one line of :data:`DECLARED` (a scene of ``dualfem list``, a scene of the library or
a ``.toml`` file, with overrides). Problem names are the declared names: never renamed.

Units (the scenes' own): lengths in mm, E in MPa, so x in mm, P in MPa (force per mm of thickness per mm of
displacement), q and z in N per mm of thickness (MPa.mm), the objective in N.mm per mm of thickness (N).
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_write_text, dumps
from dualfem.core.qp import QP
from dualfem.experiments import testset_files as files
from dualfem.experiments import testset_render as render

#: the size classes, smallest first, and the most unknowns a scene of each class may have (checked on the
#: scene's own estimate before anything is assembled)
SIZES: dict[str, int] = {"tiny": 1_000, "small": 20_000, "medium": 200_000, "large": 2_000_000}
#: the size classes ``dualfem testset`` writes when ``--sizes`` is not given
DEFAULT_SIZES = ("tiny", "small", "medium", "large")
#: the largest certified relative energy-norm error a reference may have (the policy's default, 1e-4, is
#: for grading solvers; a public reference must be far tighter than any tolerance it is used to check)
REF_BOUND_MAX = 1e-8
#: the largest evaluator KKT error a reference may have (the reference policy's default)
REF_KKT_MAX = 1e-8


@dataclass(frozen=True)
class Declared:
    """One problem of the test set: ``scene`` (a name of ``dualfem list``, a library scene or a ``.toml``
    path) with the scene-key overrides ``params``, in the size class ``size``, published as ``name``."""

    size: str
    name: str
    scene: str
    params: dict[str, Any] = field(default_factory=dict)


def _d(size: str, name: str, scene: str, **params: Any) -> Declared:
    return Declared(size, name, scene, params)


#: every problem of the test set, in publication order (one line per problem; names are stable)
DECLARED: tuple[Declared, ...] = (
    _d("tiny", "f1_N8_d1e-3", "f1", N=8, delta=1e-3),
    _d("tiny", "f2_N8_d1e-3", "f2", N=8, delta=1e-3),
    _d("tiny", "f3_N8_d1e-3", "f3", N=8, delta=1e-3),
    _d("tiny", "f2_N8_d1e-9", "f2", N=8, delta=1e-9),
    _d("small", "f1_N32_d1e-3", "f1", N=32, delta=1e-3),
    _d("small", "f2_N32_d1e-3", "f2", N=32, delta=1e-3),
    _d("small", "f2_N32_d1e-9", "f2", N=32, delta=1e-9),
    _d("small", "curved_d1e-3", "curved", delta=1e-3),
    _d("small", "inclined_d1e-9", "inclined", delta=1e-9),
    _d("small", "kinked_d1e-3", "kinked", delta=1e-3),
    _d("small", "near_boundary_d1e-5", "near_boundary", delta=1e-5),
    _d("small", "symmetric_d1e-3", "symmetric", delta=1e-3),
    _d("small", "two_defects_d1e-5", "two_defects", delta=1e-5),
    _d("medium", "f1_N128_d1e-5", "f1", N=128, delta=1e-5),
    _d("medium", "f2_N128_d1e-3", "f2", N=128, delta=1e-3),
    _d("medium", "f2_N128_d1e-9", "f2", N=128, delta=1e-9),
    _d("medium", "inclined_h0.01_d1e-5", "inclined", mesh_size=0.01, tip_size=0.0025, delta=1e-5),
    _d("medium", "symmetric_h0.01_d1e-9", "symmetric", mesh_size=0.01, tip_size=0.0025, delta=1e-9),
    _d("medium", "fractured_c50_d1e-3", "fractured", cracks=50, delta=1e-3),
    _d("large", "f2_N256_d1e-3", "f2", N=256, delta=1e-3),
    _d("large", "f2_N256_d1e-9", "f2", N=256, delta=1e-9),
    _d("large", "f1_N512_d1e-5", "f1", N=512, delta=1e-5),
    _d("large", "fractured_c100_h0.005_d1e-5", "fractured", cracks=100, mesh_size=0.005, tip_size=0.005, delta=1e-5),
    _d("large", "fractured_c400_h0.003_d1e-9", "fractured", cracks=400, mesh_size=0.003, tip_size=0.003, delta=1e-9),
)


@dataclass
class Entry:
    """What the manifest says about one written problem (sizes in unknowns, nonzeros and bytes)."""

    name: str
    size: str
    scene: str
    overrides: dict[str, Any]
    params: dict[str, Any]
    n: int
    m: int
    nnz_P: int
    nnz_G: int
    max_abs_P: float
    max_abs_q: float
    delta: float | None
    objective: float
    reference: dict[str, Any]
    bytes_qp: int
    bytes_reference: int
    seconds: float


def parse_sizes(text: str | None) -> tuple[str, ...]:
    """``--sizes tiny,small`` -> the size classes, in :data:`SIZES` order; InputError naming the allowed ones."""
    if text is None:
        return DEFAULT_SIZES
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise InputError(f"--sizes needs at least one of {', '.join(SIZES)}, got {text!r}")
    bad = [s for s in names if s not in SIZES]
    if bad:
        raise InputError(f"--sizes: unknown size class {bad[0]!r}; allowed: {', '.join(SIZES)}")
    return tuple(s for s in SIZES if s in names)


def select(sizes: tuple[str, ...], declared: tuple[Declared, ...] = DECLARED) -> list[Declared]:
    """The declared problems of the size classes ``sizes``; InputError for a repeated name or an unknown class."""
    seen: set[str] = set()
    for d in declared:
        if d.size not in SIZES:
            raise InputError(f"declared problem {d.name!r}: size class {d.size!r} is not one of {', '.join(SIZES)}")
        if d.name in seen:
            raise InputError(f"declared problem name {d.name!r} appears twice")
        files.check_name(d.name)
        seen.add(d.name)
    return [d for d in declared if d.size in sizes]


def check_out(out: Path, force: bool) -> None:
    """Refuse, before any work, an ``--out`` that is a file, cannot be written, or is a non-empty folder
    (unless ``force``: then the test set's files are written over, the problems a previous set listed and this
    one does not hold are removed, and nothing else is touched)."""
    from dualfem.core.io import check_output_path

    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} is a file; give a folder")
    if out.is_dir() and any(out.iterdir()) and not force:
        what = "a dualfem test set" if (out / files.MANIFEST).is_file() else "other files"
        raise InputError(f"--out {str(out)!r} is not empty (it holds {what}); give another --out, or --force to "
                         f"replace the test set's files in it")
    check_output_path(out / files.MANIFEST, "--out")


def check_sizes(chosen: list[Declared], max_bytes: float | None = None):
    """Load every chosen scene (validated, nothing assembled) and refuse one whose estimated unknowns exceed
    its size class's bound (:data:`SIZES`) or the memory available; returns the problem instances."""
    from dualfem.core.scene import load_scene
    from dualfem.numerics.memory import check_fits

    problems = []
    for d in chosen:
        try:
            problem = load_scene(d.scene, dict(d.params))
        except InputError as exc:
            raise InputError(f"declared problem {d.name!r}: {exc}") from None
        est = problem.size_estimate() if hasattr(problem, "size_estimate") else None
        if est is not None and est[0] > SIZES[d.size]:
            raise InputError(f"declared problem {d.name!r} ({est[1]}) has about {est[0]} unknowns; the size class "
                             f"{d.size!r} allows at most {SIZES[d.size]}")
        check_fits(problem, max_bytes)
        problems.append(problem)
    return problems


def qpsolvers_form(qp: QP) -> tuple[sp.csc_matrix, np.ndarray, sp.csc_matrix, np.ndarray]:
    """(P, q, G, h) of ``qp`` in qpsolvers' convention ``min 1/2 x'Px + q'x s.t. G x <= h``: ``P = K``,
    ``q = -F``, ``G = -B``, ``h = 0``. A shifted QP (``B x >= h`` with h != 0 in the user's unknowns) and a
    QP without constraints are refused: the test set holds contact problems through the origin."""
    if qp.shift is not None:
        raise InputError(f"QP {qp.name!r} is shifted (its constraints are B x >= h with h != 0): the test set "
                         f"takes only unshifted contact QPs")
    if qp.m == 0:
        raise InputError(f"QP {qp.name!r} has no constraint: not a contact problem")
    return sp.csc_matrix(qp.K), -qp.F.copy(), sp.csc_matrix(-qp.B), np.zeros(qp.m)


def certified_reference(qp: QP, name: str):
    """(x, z, certificate dict, solver name, kkt) of the reference of ``qp`` (see the module docstring);
    InputError naming ``name`` and what was tried when no reference solver certifies it."""
    from dualfem.experiments import reference
    from dualfem.numerics.certify import certified_error

    ref, tried = reference.compute(qp, kkt_max=REF_KKT_MAX, bound_max=REF_BOUND_MAX)
    if ref is None:
        raise InputError(f"no certified reference for {name!r} (certified error <= {REF_BOUND_MAX:g} and KKT "
                         f"error <= {REF_KKT_MAX:g} needed): {'; '.join(tried)}")
    cert = {k: float(v) for k, v in certified_error(qp, ref.x, ref.multipliers).items()}
    return np.asarray(ref.x, float), np.asarray(ref.multipliers, float), cert, ref.solver, float(ref.kkt)


def _check_converted(name: str, P, q, G, x: np.ndarray, z: np.ndarray, res: dict[str, float]) -> None:
    """The certified (x, mu) of dualfem's QP must be a KKT point of the converted QP too (a sign slip in the
    conversion would show here): stationarity and complementarity at rounding level of the forces, G x <= 0
    at rounding level of x, z >= 0. RuntimeError otherwise (a bug, not an input error)."""
    force = float(np.max(abs(P) @ np.abs(x) + np.abs(q) + abs(G.T) @ np.abs(z)))
    length = float(np.max(np.abs(x), initial=0.0))
    bad = [k for k, v, s in (("dual", res["dual"], force), ("primal", res["primal"], length),
                              ("sign", res["sign"], force), ("complementarity", res["complementarity"], force * length))
           if not v <= 1e-8 * s]
    if bad:
        raise RuntimeError(f"the reference of {name!r} is not a KKT point of G x <= h ({', '.join(bad)}: {res})")


def build_entry(d: Declared, problem, out: Path) -> Entry:
    """Assemble, certify and write one declared problem; its manifest entry."""
    from dualfem.core.scene import build_qp

    t0 = time.perf_counter()
    qp = build_qp(problem)
    P, q, G, h = qpsolvers_form(qp)
    x, z, cert, solver, kkt = certified_reference(qp, d.name)
    objective = float(0.5 * x @ (P @ x) + q @ x)
    res = files.kkt_residuals(P, q, G, h, x, z)
    _check_converted(d.name, P, q, G, x, z, res)
    qp_path = files.write_qp(out / files.QP_DIR / f"{d.name}.npz", d.name, P, q, G, h)
    ref_info = {"solver": solver, "certified_error": cert["value"], "duality_gap_bound": cert["bound"],
                "active_set_estimate": cert["active_set"], "multiplier_error": cert["multipliers"],
                "kkt_error": kkt, "residuals": res}
    ref_path = files.write_reference(out / files.REF_DIR / f"{d.name}.npz", d.name, x, z, objective, ref_info)
    delta = qp.params.get("delta")
    return Entry(name=d.name, size=d.size, scene=d.scene, overrides=dict(d.params),
                 params={k: v for k, v in qp.params.items() if isinstance(v, (int, float, str))},
                 n=qp.n, m=qp.m, nnz_P=int(P.nnz), nnz_G=int(G.nnz),
                 max_abs_P=float(abs(P).max()), max_abs_q=float(np.max(np.abs(q), initial=0.0)),
                 delta=float(delta) if isinstance(delta, (int, float)) else None, objective=objective,
                 reference=ref_info, bytes_qp=qp_path.stat().st_size, bytes_reference=ref_path.stat().st_size,
                 seconds=time.perf_counter() - t0)


def write_testset(out: str | Path, sizes: tuple[str, ...] = DEFAULT_SIZES, *, force: bool = False,
                  declared: tuple[Declared, ...] = DECLARED, max_bytes: float | None = None,
                  progress: Callable[[str, float], None] | None = None, friction: bool = True,
                  declared_friction: tuple[Declared, ...] | None = None) -> dict:
    """Write the test set of the size classes ``sizes`` into ``out`` (see the module docstring); the manifest.

    Everything is validated first (the size classes, ``out``, every scene and its size); each file is
    written atomically and the manifest last, so a folder without ``manifest.json`` is an unfinished set.
    ``progress(stage, seconds)`` hears of each written problem. ``friction``: also write the frictional
    problems of those size classes (``declared_friction``, default
    :func:`dualfem.experiments.testset_friction.declared`) with their references (manifest ``friction``)."""
    from dualfem.experiments import testset_friction as fr

    out = Path(out)
    unknown = [s for s in sizes if s not in SIZES]
    if unknown:
        raise InputError(f"unknown size class {unknown[0]!r}; allowed: {', '.join(SIZES)}")
    chosen = select(sizes, declared)
    if not chosen:
        raise InputError(f"no declared problem in the size classes {', '.join(sizes)}")
    chosen_f = select(sizes, fr.declared() if declared_friction is None else declared_friction) if friction else []
    check_out(out, force)
    problems = check_sizes(chosen, max_bytes)
    problems_f = check_sizes(chosen_f, max_bytes)
    stale = _stale_files(out, {d.name for d in chosen}, {d.name for d in chosen_f}) if force else []
    (out / files.MANIFEST).unlink(missing_ok=True)     # the folder is an unfinished set until the new one is written
    entries, total = [], len(chosen) + len(chosen_f)
    for i, (d, problem) in enumerate(zip(chosen, problems)):
        e = build_entry(d, problem, out)
        entries.append(e)
        if progress:
            progress(f"[{i + 1}/{total}] {d.name} ({d.size}, n = {e.n}, m = {e.m}, certified error "
                     f"{e.reference['certified_error']:.1e})", e.seconds)
    entries_f = []
    for i, (d, problem) in enumerate(zip(chosen_f, problems_f)):
        f = fr.build_entry(d, problem, out)
        entries_f.append(f)
        if progress:
            progress(f"[{len(chosen) + i + 1}/{total}] {d.name} ({d.size}, {f.dim}D {f.law}, n = {f.n}, "
                     f"certified error {f.reference['certified_error']:.1e})", f.seconds)
    manifest = render.manifest(entries, sizes, bound_max=REF_BOUND_MAX, kkt_max=REF_KKT_MAX, friction=entries_f)
    atomic_write_text(out / files.TESTSET_PY, render.testset_source(manifest))
    atomic_write_text(out / files.README, render.readme(manifest))
    atomic_write_text(out / files.MANIFEST, json.dumps(json.loads(dumps(manifest)), indent=1) + "\n")
    for path in stale:                  # problems of the previous set that this one does not hold
        path.unlink(missing_ok=True)
    return manifest


def _stale_files(out: Path, names: set[str], friction_names: set[str] | frozenset[str] = frozenset()) -> list[Path]:
    """The problem and reference files a previous test set in ``out`` lists (its manifest) and the new one
    will not rewrite (frictional ones: ``friction_names``); nothing else in ``out`` is ever removed. An
    unreadable old manifest lists nothing."""
    from dualfem.experiments.testset_friction import stale_files

    try:
        old = json.loads((out / files.MANIFEST).read_text(encoding="utf-8"))
        listed = [p["name"] for p in old["problems"]]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [out / sub / f"{n}.npz" for n in listed if isinstance(n, str) and n not in names
            for sub in (files.QP_DIR, files.REF_DIR) if files.NAME_PATTERN.fullmatch(n)] + \
        stale_files(out, old, set(friction_names))
