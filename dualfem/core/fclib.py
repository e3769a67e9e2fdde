"""A Coulomb-frictional QP in FCLIB's global format (HDF5), for the frictional contact benchmark ecosystem.

FCLIB (Acary, Bremond, Koziara, Perignon: "FCLIB: a collection of discrete 3D frictional contact problems",
INRIA RT-0444, 2014; github.com/FrictionalContactLibrary/fclib, ``fclib.h``) stores the *global* problem: find
v, u, r with

    M v = H r + f,    u = H' v + w,    C*_mu  ∋  u + [mu_a ||u_T,a||, 0, 0]_a  ⟂  r  ∈  C_mu,

``C_mu = {r_a : ||r_T,a|| <= mu_a r_N,a}`` per contact a, each contact's ``spacedim`` components ordered
(normal, tangents). A dualfem QP with a Coulomb block maps one to one (quasi-static: v is the displacement):
``M = K``, ``f = F``, ``w = 0``, and contact a = row a of the Signorini block B: column block a of H holds B's
row a then the Coulomb block's tangential rows of that node (``t_k . [u]``); r_a = (lambda_a, mu_t,a), the
normal and friction forces (``K x - F = G' mu``, the QP's sign; FCLIB's r_T opposes the slip like ours).
A contact without Coulomb friction gets its tangential rows from ``qp.interface`` and ``mu_a = 0``.

Layout written (the library's own, ``fclib_write_global``): group ``/fclib_global`` with ``spacedim`` (int, 1),
groups ``M`` and ``H`` (a sparse matrix each: ints ``nzmax``, ``m``, ``n``, ``nz`` (shape (1,)); compressed
columns, ``nz = -1``: ``p`` (n + 1 ints), ``i`` (nzmax ints), ``x`` (nzmax doubles)), group ``vectors``
(``f`` (M.m), ``w`` (H.n), ``mu`` (H.n / spacedim)) and group ``info`` (strings ``title``, ``description``,
``math_info``). No ``G``/``b`` (dualfem's QP has no equality rows here). h5py is needed (the ``xdmf`` extra).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.core.laws import Coulomb, Friction
from dualfem.core.qp import QP


@dataclass
class FclibGlobal:
    """FCLIB's global problem (module docstring): ``M`` (n, n), ``H`` (n, spacedim nc), ``f`` (n,), ``w``
    (spacedim nc,), ``mu`` (nc,), ``spacedim`` and the ``info`` strings."""

    M: sp.csc_matrix
    H: sp.csc_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    spacedim: int
    info: dict = field(default_factory=dict)


def _tangential(qp: QP) -> sp.csr_matrix:
    """The interface's tangential jump rows of every Signorini row, node-major (as a friction block's)."""
    part = qp.interface
    if part is None:
        raise InputError(f"QP {qp.name!r} has no defect interface")
    m, c, d = part.m, part.dim - 1, part.dim
    t = part.tangents
    rows = np.broadcast_to((np.arange(m)[:, None] * c + np.arange(c)[None, :])[:, :, None], (m, c, d))
    cp = np.broadcast_to(part.plus_dofs[:, None, :], (m, c, d))
    cm = np.broadcast_to(part.minus_dofs[:, None, :], (m, c, d))
    return sp.csr_matrix((np.r_[t.ravel(), -t.ravel()], (np.r_[rows.ravel(), rows.ravel()], np.r_[cp.ravel(),
                                                                                           cm.ravel()])),
                         shape=(m * c, qp.n))


def fclib_global(qp: QP, title: str = "", description: str = "") -> FclibGlobal:
    """The FCLIB global problem of a QP whose friction blocks are Coulomb (InputError otherwise)."""
    blocks = [b for b in qp.blocks if isinstance(b.law, Friction)]
    if not any(isinstance(b.law, Coulomb) for b in blocks) or any(not isinstance(b.law, Coulomb) for b in blocks) \
            or len(blocks) != len(qp.blocks):
        raise InputError(f"FCLIB holds Coulomb friction problems: QP {qp.name!r} needs friction = 'coulomb' on its "
                         f"defects (its extra blocks: {', '.join(b.law.name for b in qp.blocks) or 'none'})")
    if qp.interface is None or qp.shift is not None:
        raise InputError(f"QP {qp.name!r}: the FCLIB export needs a defect interface and no shift")
    T = _tangential(qp).tolil()
    m, c = qp.m, T.shape[0] // max(qp.m, 1)
    mu = np.zeros(m)
    for b in blocks:
        law = b.law
        assert isinstance(law, Coulomb)
        nodes = np.arange(b.m // c) if law.normal_rows is None else law.normal_rows
        coef = np.broadcast_to(np.asarray(law.coefficient, float), nodes.shape)
        mu[nodes] = coef
        rows = (nodes[:, None] * c + np.arange(c)[None, :]).ravel()
        T[rows] = b.G
    # columns of H: contact a = [B row a, its c tangential rows]
    stacked = sp.vstack([qp.B, T.tocsr()], format="csr")
    order = np.column_stack([np.arange(m), m + np.arange(m * c).reshape(m, c)]).ravel()
    H = stacked[order].T.tocsc()
    d = c + 1
    info = {"title": title or qp.name, "description": description or
            f"dualfem {qp.name}: {qp.n} unknowns, {m} contacts (defect nodes), quasi-static (v: displacement)",
            "math_info": "M = K symmetric positive definite (elasticity + thin-layer term): at least one solution"}
    return FclibGlobal(qp.K.tocsc(), H, np.asarray(qp.F, float).copy(), np.zeros(d * m), mu, d, info)


def _write_matrix(group, A: sp.csc_matrix) -> None:
    A = sp.csc_matrix(A)
    A.sort_indices()
    i4 = np.int32
    for k, v in (("nzmax", A.nnz), ("m", A.shape[0]), ("n", A.shape[1]), ("nz", -1)):
        group.create_dataset(k, data=np.array([v], dtype=i4))
    group.create_dataset("p", data=A.indptr.astype(i4))
    group.create_dataset("i", data=A.indices.astype(i4))
    group.create_dataset("x", data=A.data.astype(np.float64))


def write_fclib(path: str, prob: FclibGlobal) -> None:
    """Write ``prob`` to ``path`` (a new HDF5 file) in FCLIB's global layout (module docstring)."""
    import h5py

    with h5py.File(path, "w") as fh:
        g = fh.create_group("fclib_global")
        g.create_dataset("spacedim", data=np.array([prob.spacedim], dtype=np.int32))
        _write_matrix(g.create_group("M"), prob.M)
        _write_matrix(g.create_group("H"), prob.H)
        v = g.create_group("vectors")
        v.create_dataset("f", data=np.asarray(prob.f, np.float64))
        v.create_dataset("w", data=np.asarray(prob.w, np.float64))
        v.create_dataset("mu", data=np.asarray(prob.mu, np.float64))
        info = g.create_group("info")
        for k in ("title", "description", "math_info"):
            if prob.info.get(k):
                info.create_dataset(k, data=np.bytes_(prob.info[k]))


def _read_matrix(group) -> sp.spmatrix:
    nz, m, n = int(group["nz"][0]), int(group["m"][0]), int(group["n"][0])
    p, i, x = group["p"][()], group["i"][()], group["x"][()]
    if nz == -1:
        return sp.csc_matrix((x, i, p), shape=(m, n))
    if nz == -2:
        return sp.csr_matrix((x, i, p), shape=(m, n)).tocsc()
    return sp.csc_matrix((x, (p, i)), shape=(m, n))      # triplet: p row indices, i column indices


def read_fclib(path: str) -> FclibGlobal:
    """Read an FCLIB global problem (any of the library's three sparse storages)."""
    import h5py

    with h5py.File(path, "r") as fh:
        if "fclib_global" not in fh:
            raise InputError(f"{path}: no /fclib_global group (not an FCLIB global problem)")
        g = fh["fclib_global"]
        v = g["vectors"]
        info = {k: g["info"][k][()].decode() for k in ("title", "description", "math_info")
                if "info" in g and k in g["info"]}
        return FclibGlobal(_read_matrix(g["M"]).tocsc(), _read_matrix(g["H"]).tocsc(), v["f"][()], v["w"][()],
                           v["mu"][()], int(g["spacedim"][0]), info)
