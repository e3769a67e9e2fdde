"""``dualfem export SCENE --format fclib``: a 3D Coulomb scene in FCLIB's global format, checked against the
library's layout (fclib.h / fclib_write_global: groups, datasets, shapes, dtypes, compressed-column storage),
read back to the same problem, and a certified Coulomb answer of the QP solving FCLIB's equations (M v = H r + f,
r in the Coulomb cones, the friction force opposing the slip)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.fclib import fclib_global, read_fclib
from dualfem.core.laws import Tresca
from dualfem.scene import load_scene

h5py = pytest.importorskip("h5py")
pytest.importorskip("gmsh")

KEYS = {"N": 6, "friction": "coulomb", "friction_coefficient": 0.3}
ARGS = ["three_d", "--set", "N=6", "--set", "friction=coulomb", "--set", "friction_coefficient=0.3"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    path = tmp_path_factory.mktemp("fclib") / "p.hdf5"
    assert main(["export", *ARGS, "--format", "fclib", "-o", str(path)]) == 0
    return path, load_scene("three_d", KEYS).build()


def test_the_file_has_fclibs_global_layout(exported):
    path, qp = exported
    with h5py.File(path, "r") as fh:
        g = fh["fclib_global"]
        assert set(g) == {"spacedim", "M", "H", "vectors", "info"}
        assert g["spacedim"].shape == (1,) and g["spacedim"].dtype == np.int32 and g["spacedim"][0] == 3
        for name, (rows, cols) in (("M", (qp.n, qp.n)), ("H", (qp.n, 3 * qp.m))):
            mat = g[name]
            assert set(mat) == {"nzmax", "m", "n", "nz", "p", "i", "x"}
            for k in ("nzmax", "m", "n", "nz"):
                assert mat[k].shape == (1,) and mat[k].dtype == np.int32
            assert (mat["m"][0], mat["n"][0], mat["nz"][0]) == (rows, cols, -1)       # compressed columns
            nnz = mat["nzmax"][0]
            assert mat["p"].shape == (cols + 1,) and mat["p"][0] == 0 and mat["p"][-1] == nnz
            assert mat["i"].shape == (nnz,) and mat["x"].shape == (nnz,) and mat["x"].dtype == np.float64
            assert np.all(np.diff(mat["p"][()]) >= 0) and mat["i"][()].min() >= 0 and mat["i"][()].max() < rows
        v = g["vectors"]
        assert v["f"].shape == (qp.n,) and v["w"].shape == (3 * qp.m,) and v["mu"].shape == (qp.m,)
        assert g["info"]["title"][()].decode() == qp.name


def test_read_back_is_the_same_problem(exported):
    path, qp = exported
    prob = read_fclib(str(path))
    assert prob.spacedim == 3 and abs(prob.M - qp.K).max() == 0 and np.array_equal(prob.f, qp.F)
    assert np.array_equal(prob.mu, np.full(qp.m, 0.3)) and not prob.w.any()
    H = prob.H.toarray()
    assert np.array_equal(H[:, 0::3].T, qp.B.toarray())                       # each contact's normal first
    T = qp.blocks[0].G.toarray()
    assert np.array_equal(H[:, 1::3].T, T[0::2]) and np.array_equal(H[:, 2::3].T, T[1::2])


def test_a_coulomb_answer_solves_fclibs_equations():
    pytest.importorskip("clarabel")
    from dualfem.experiments.runner import run

    qp = load_scene("three_d", KEYS).build()
    b = qp.blocks[0]
    lam = np.zeros(qp.m)
    for _ in range(60):                 # the test's own fixed point g <- mu_f lambda / w over clarabel's Tresca
        g = 0.3 * np.maximum(lam, 0.0) / b.weights[::2]
        sol = run("clarabel", dataclasses.replace(qp, blocks=(dataclasses.replace(b, law=Tresca(g, 2)),),
                                                  store=None))
        done = np.abs(sol.multipliers[:qp.m] - lam).max() <= 1e-12 * np.abs(lam).max()
        lam = sol.multipliers[:qp.m]
        if done:
            break
    assert done and sol.status == "solved"
    prob = fclib_global(qp)
    mu_t = sol.multipliers[qp.m:].reshape(-1, 2)
    r = np.column_stack([lam, mu_t]).ravel()
    assert np.abs(prob.M @ sol.x - prob.H @ r - prob.f).max() < 1e-9 * np.abs(prob.f).max()
    u = (prob.H.T @ sol.x + prob.w).reshape(-1, 3)
    slip = np.linalg.norm(u[:, 1:], axis=1)
    assert np.all(np.linalg.norm(mu_t, axis=1) <= prob.mu * lam * (1 + 1e-8) + 1e-14)   # r in C_mu
    sliding = slip > 1e-8 * np.abs(sol.x).max()
    assert sliding.any()
    d = -u[sliding, 1:] / slip[sliding, None]                                    # the force opposes the slip
    assert np.allclose(mu_t[sliding], (prob.mu * lam)[sliding, None] * d, rtol=1e-6, atol=1e-12)


def test_refusals(tmp_path):
    from dualfem.core.errors import InputError

    with pytest.raises(InputError, match="FCLIB holds Coulomb"):
        fclib_global(load_scene("three_d", {"N": 4}).build())
    assert main(["export", *ARGS, "--format", "fclib", "-o", str(tmp_path / "p.npz")]) != 0
