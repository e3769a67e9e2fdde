"""The ``qp_file`` problem (problems/generic_qp.py): any QP min 1/2 x'Px + q'x s.t. Gx >= h."""
import json

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp

from dualfem.cli.main import main
from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.registry import solvers
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import run
from dualfem.problems.generic_qp import original_objective, original_x


def random_qp(n=25, m=8, seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    return P, rng.standard_normal(n), rng.standard_normal((m, n)), rng.standard_normal(m)


def kkt_original(P, q, G, h, x, mu):
    """KKT residuals of the file's QP in its own variables (independent of the shift)."""
    return (np.abs(P @ x + q - G.T @ mu).max() / max(np.abs(q).max(), 1e-300),
            max(0.0, -(G @ x - h).min()),
            max(0.0, -mu.min()),
            np.abs(mu * (G @ x - h)).max())


def reference_name():
    reg = solvers()
    for n in ("pdas", "clarabel"):
        if n in reg and reg[n].missing() is None:
            return n
    pytest.skip("no exact reference solver installed")


@pytest.mark.parametrize("fmt", ["npz_dense", "npz_coo", "mat_sparse", "mat_dense"])
def test_formats_load_the_same_qp(tmp_path, fmt):
    P, q, G, h = random_qp()
    f = tmp_path / ("qp.npz" if fmt.startswith("npz") else "qp.mat")
    if fmt == "npz_dense":
        np.savez(f, P=P, q=q, G=G, h=h)
    elif fmt == "npz_coo":
        Pc, Gc = sp.coo_matrix(P), sp.coo_matrix(G)
        np.savez(f, P_data=Pc.data, P_row=Pc.row, P_col=Pc.col, P_shape=Pc.shape,
                 G_data=Gc.data, G_row=Gc.row, G_col=Gc.col, G_shape=Gc.shape, q=q, h=h)
    elif fmt == "mat_sparse":
        scipy.io.savemat(f, {"P": sp.csc_matrix(P), "q": q[:, None], "G": sp.csc_matrix(G), "h": h})
    else:
        scipy.io.savemat(f, {"P": P, "q": q, "G": G, "h": h[None, :]})
    qp = load_scene(str(f)).build()
    assert qp.n == 25 and qp.m == 8
    np.testing.assert_allclose(qp.K.toarray(), P, rtol=1e-15)
    np.testing.assert_allclose(qp.B.toarray(), G, rtol=1e-15)
    np.testing.assert_allclose(G @ qp.shift.x, h, atol=1e-12)


def test_nonzero_h_shift_solves_the_original_qp(tmp_path):
    P, q, G, h = random_qp(seed=3)
    f = tmp_path / "qp.npz"
    np.savez(f, P=P, q=q, G=G, h=h)
    qp = load_scene(str(f)).build()
    sol = run(reference_name(), qp)
    assert sol.status == Status.SOLVED
    x = original_x(qp, sol.x)
    stat, prim, dual, comp = kkt_original(P, q, G, h, x, sol.multipliers)
    assert max(stat, prim, dual, comp) < 1e-7
    assert 0 < evaluator.contact_set(qp, sol.x).sum() < qp.m      # some, not all, constraints active
    assert original_objective(qp, sol.x) == pytest.approx(0.5 * x @ P @ x + q @ x, rel=1e-12)
    # an independent dense check: the dual is a small NNLS problem
    from scipy.optimize import nnls

    Pi = np.linalg.inv(P)
    D = G @ Pi @ G.T
    c = G @ Pi @ q + h                  # dual: min 1/2 mu'D mu - c'mu, mu >= 0
    R = np.linalg.cholesky(D).T
    mu, _ = nnls(R, np.linalg.solve(R.T, c))
    np.testing.assert_allclose(sol.multipliers, mu, atol=1e-7 * np.abs(mu).max())
    np.testing.assert_allclose(x, Pi @ (G.T @ mu - q), atol=1e-7 * np.abs(x).max())


def test_every_exact_solver_agrees_on_a_file(tmp_path):
    P, q, G, h = random_qp(n=30, m=10, seed=5)
    f = tmp_path / "qp.mat"
    scipy.io.savemat(f, {"P": sp.csc_matrix(P), "q": q, "G": G, "h": h})
    qp = load_scene(str(f)).build()
    ref = run(reference_name(), qp)
    done = []
    for name, cls in sorted(solvers().items()):
        if not cls.exact or cls.missing():
            continue
        s = run(name, qp)
        if s.status == Status.SKIPPED or (s.status != Status.SOLVED and solvers()[name].requires):
            # a third-party library may fail honestly (its certified status says so)
            continue
        assert s.status == Status.SOLVED, (name, s.message)
        d = evaluator.compare(qp, s.x, s.multipliers, ref.x, ref.multipliers)
        assert d["x_energy"] < max(cls.tolerance, 1e-6), (name, d)
        done.append(name)
    assert "dual_gradient" in done and len(done) >= 2


def test_dualfem_export_file_round_trip(tmp_path):
    f = tmp_path / "f2.npz"
    assert main(["export", "f2", "--set", "N=8", "-o", str(f)]) == 0
    direct = load_scene("f2", {"N": 8}).build()
    qp = load_scene(str(f)).build()
    assert qp.key() == direct.key()
    assert "node_dofs" in qp.maps


def test_cli_solve_npz(tmp_path, capsys):
    P, q, G, h = random_qp(seed=1)
    f = tmp_path / "mine.npz"
    np.savez(f, P=P, q=q, G=G, h=h)
    assert main(["solve", str(f), "--solver", "dual_gradient", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["status"] == "solved" and rec["problem"] == "qp_file[mine]" and rec["ndof"] == 25


def test_upper_triangle_storage(tmp_path):
    P, q, G, h = random_qp()
    f = tmp_path / "u.npz"
    np.savez(f, P=np.triu(P), q=q, G=G, h=h)
    with pytest.raises(InputError, match="p_storage"):
        load_scene(str(f)).build()
    qp = load_scene(str(f), {"p_storage": "upper"}).build()
    np.testing.assert_allclose(qp.K.toarray(), P, rtol=1e-15)
    with pytest.raises(InputError, match="other triangle"):
        load_scene(str(f), {"p_storage": "lower"}).build()


def _write(tmp_path, **arrays):
    f = tmp_path / "bad.npz"
    np.savez(f, **arrays)
    return str(f)


@pytest.mark.parametrize("case,needle", [
    ("q_len", "'q'.*length 25"),
    ("G_cols", "G .*25 columns"),
    ("h_len", "'h'.*length 8"),
    ("nan", "NaN"),
    ("asym", "symmetric"),
    ("indefinite", "not positive definite"),
    ("neg_diag", "diagonal entry"),
    ("singular", "singular|not positive definite"),
    ("box", "not in the range of G"),
    ("no_G", "lacks the constraint matrix"),
    ("no_P", "lacks the matrix 'P'"),
    ("P_3d", "2-D"),
    ("coo_index", "outside"),
])
def test_validation(tmp_path, case, needle):
    P, q, G, h = random_qp()
    a = {"P": P, "q": q, "G": G, "h": h}
    if case == "q_len":
        a["q"] = q[:-1]
    elif case == "G_cols":
        a["G"] = G[:, :-1]
    elif case == "h_len":
        a["h"] = h[:-1]
    elif case == "nan":
        a["q"] = q.copy()
        a["q"][3] = np.nan
    elif case == "asym":
        a["P"] = P.copy()
        a["P"][0, 1] += 1.0
    elif case == "indefinite":
        w, V = np.linalg.eigh(P)
        w[0] = -1.0                      # one negative eigenvalue, diagonal still positive
        a["P"] = (V * w) @ V.T
        assert np.all(np.diag(a["P"]) > 0)
    elif case == "neg_diag":
        a["P"] = P.copy()
        a["P"][2, 2] = -1.0
    elif case == "singular":
        a["P"] = np.eye(25)
        a["P"][:2, :2] = 1.0             # exactly singular, positive diagonal
    elif case == "box":
        a["G"] = np.vstack([np.eye(25), -np.eye(25)])
        a["h"] = -np.ones(50)
    elif case == "no_G":
        del a["G"]
    elif case == "no_P":
        del a["P"]
    elif case == "P_3d":
        a["P"] = P[None]
    elif case == "coo_index":
        Pc = sp.coo_matrix(P)
        del a["P"]
        a.update(P_data=Pc.data, P_row=Pc.row + 1, P_col=Pc.col, P_shape=Pc.shape)
    with pytest.raises(InputError, match=needle):
        load_scene(_write(tmp_path, **a)).build()


def test_cli_refuses_with_one_line(tmp_path, capsys):
    P, q, G, h = random_qp()
    rc = main(["solve", _write(tmp_path, P=P + np.triu(np.ones_like(P), 1), q=q, G=G), "--solver", "clarabel"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "symmetric" in err[0]


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_scene(str(tmp_path / "nope.npz")).build()
    bad = tmp_path / "corrupt.mat"
    bad.write_bytes(b"not a mat file at all")
    with pytest.raises(InputError, match="cannot read"):
        load_scene(str(bad)).build()
    v73 = tmp_path / "v73.mat"               # MATLAB -v7.3 header (HDF5): scipy cannot read it
    hdr = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sun Nov 22 2026 HDF5 schema 1.00 ."
    v73.write_bytes(hdr.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM" + b"\x00" * 384)
    with pytest.raises(InputError, match="-v7"):
        load_scene(str(v73)).build()
    from dualfem.core.registry import get_problem

    with pytest.raises(InputError, match="path"):
        get_problem("qp_file")()
    with pytest.raises(InputError, match="path"):
        get_problem("qp_file")(path="qp.txt")
