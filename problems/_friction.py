"""The friction block of a cut mesh: tangential jumps of the interface's node pairs with a friction law.

:func:`friction_block` builds the :class:`dualfem.core.constraints.Constraint` of Tresca or Coulomb friction
(:mod:`dualfem.core.laws`) on chosen node pairs of an :class:`dualfem.core.parts.InterfacePart`: rows
``j * (dim - 1) + k`` hold ``t_k . [u]`` of the j-th chosen pair (the interface's own tangent frame, length
units), every row of a pair weighted by the pair's nodal weight. :func:`with_friction` returns a QP with that
block added (the Signorini block, and so the normal multipliers a Coulomb law reads, stay block 0).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from dualfem.errors import InputError
from dualfem.laws import Constraint, Coulomb, Tresca
from dualfem.qp import QP, InterfacePart

KINDS = ("tresca", "coulomb")


def tangential_operator(part: InterfacePart, n: int, rows: np.ndarray) -> sp.csr_matrix:
    """The ((dim - 1) len(rows)) x n operator of the tangential jumps of the pairs ``rows``, node-major."""
    d, c = part.dim, part.dim - 1
    t = part.tangents[rows]                                     # (k, c, d)
    k = rows.size
    r = np.broadcast_to((np.arange(k)[:, None] * c + np.arange(c)[None, :])[:, :, None], (k, c, d))
    cp = np.broadcast_to(part.plus_dofs[rows][:, None, :], (k, c, d))
    cm = np.broadcast_to(part.minus_dofs[rows][:, None, :], (k, c, d))
    return sp.csr_matrix((np.r_[t.ravel(), -t.ravel()], (np.r_[r.ravel(), r.ravel()], np.r_[cp.ravel(), cm.ravel()])),
                         shape=(c * k, n))


def friction_block(part: InterfacePart, n: int, kind: str, value, rows=None) -> Constraint:
    """Tresca (``value`` = threshold g >= 0, stress units: a number or one per chosen pair) or Coulomb (``value`` =
    coefficient mu_f >= 0) friction on the pairs ``rows`` (indices into the interface's m pairs; None: all)."""
    if kind not in KINDS:
        raise InputError(f"friction must be one of {', '.join(KINDS)}, got {kind!r}")
    rows = np.arange(part.m) if rows is None else np.asarray(rows, dtype=np.int64).ravel()
    c = part.dim - 1
    v = np.asarray(value, dtype=float)
    if v.ndim == 1:
        if v.size == part.m and rows.size != part.m:
            v = v[rows]
        if v.size != rows.size:
            raise InputError(f"friction values: one per chosen node pair ({rows.size}), got {v.size}")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError(f"friction {'bound' if kind == 'tresca' else 'coefficient'} must be finite and >= 0")
    law = Tresca(v, components=c) if kind == "tresca" else Coulomb(v, components=c, normal_rows=rows)
    return Constraint.make(tangential_operator(part, n, rows), np.repeat(part.weights[rows], c), law)


def with_friction(qp: QP, kind: str, value, rows=None) -> QP:
    """``qp`` (with an interface part) plus a friction block on its node pairs ``rows`` (see :func:`friction_block`)."""
    if qp.interface is None:
        raise InputError(f"QP {qp.name!r} has no interface part: friction needs the defect's node pairs")
    block = friction_block(qp.interface, qp.n, kind, value, rows)
    return dataclasses.replace(qp, blocks=(*qp.blocks, block), store=None)
