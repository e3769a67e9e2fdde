"""The ``qp_file`` problem (problems/generic_qp.py): any QP in qpsolvers' convention min 1/2 x'Px + q'x
s.t. Gx <= h (Ax = b, lb <= x <= ub), or in dualfem's own min 1/2 x'Kx - F'x s.t. Bx >= Bx_min."""
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
    """(P, q, G, h) of qpsolvers' ``min 1/2 x'Px + q'x s.t. G x <= h``."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    return P, rng.standard_normal(n), rng.standard_normal((m, n)), rng.standard_normal(m)


def kkt_original(P, q, G, h, x, z):
    """KKT residuals of the file's QP (G x <= h, multipliers z >= 0) in its own variables."""
    return (np.abs(P @ x + q + G.T @ z).max() / max(np.abs(q).max(), 1e-300),
            max(0.0, (G @ x - h).max()),
            max(0.0, -z.min()),
            np.abs(z * (G @ x - h)).max())


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
    np.testing.assert_allclose(qp.B.toarray(), -G, rtol=1e-15)         # G x <= h is -G x >= -h
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
    c = -G @ Pi @ q - h                 # dual: min 1/2 z'D z - c'z, z >= 0
    R = np.linalg.cholesky(D).T
    z, _ = nnls(R, np.linalg.solve(R.T, c))
    np.testing.assert_allclose(sol.multipliers, z, atol=1e-7 * np.abs(z).max())
    np.testing.assert_allclose(x, -Pi @ (G.T @ z + q), atol=1e-7 * np.abs(x).max())


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
    assert "node_dofs" in qp.maps and qp.params["convention"] == "dualfem"


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
    ("box", "not in the range"),
    ("no_G", "holds 'h' but not the matrix 'G'"),
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


# ------------------------------------------------------------------ the two conventions (issue 33, item 4)
def _qpsolvers_solve(P, q, G=None, h=None, A=None, b=None, lb=None, ub=None):
    """The file's QP solved by qpsolvers itself (an exact dense active-set backend): independent of dualfem."""
    qpsolvers = pytest.importorskip("qpsolvers")
    backend = next((s for s in ("quadprog", "daqp", "pyqpmad") if s in qpsolvers.available_solvers), None)
    if backend is None:
        pytest.skip("no exact dense qpsolvers backend installed")

    def big(v):             # quadprog takes no infinite bound
        return None if v is None else np.where(np.isinf(v), np.sign(v) * 1e30, v)

    res = qpsolvers.solve_problem(qpsolvers.Problem(P, q, G, big(h), A, b, big(lb), big(ub)), solver=backend)
    assert res.found
    return res


def _small(seed=0, n=6, m=3):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((n, n))
    return M @ M.T + n * np.eye(n), 5 * rng.standard_normal(n), rng.standard_normal((m, n)), rng.standard_normal(m)


def test_a_qpsolvers_users_file_means_G_x_le_h(tmp_path):
    """P, q, G, h are qpsolvers' G x <= h: the answer is qpsolvers' own (was: the mirrored G x >= h, `solved`,
    off by about 1 in x on this 6-variable QP)."""
    from dualfem.problems.generic_qp import qpsolvers_duals

    P, q, G, h = _small()
    f = tmp_path / "user.npz"
    np.savez(f, P=P, q=q, G=G, h=h)
    res = _qpsolvers_solve(P, q, G, h)
    mirrored = _qpsolvers_solve(P, q, -G, -h)
    assert np.abs(mirrored.x - res.x).max() > 0.1          # the two readings differ: the test can tell
    qp = load_scene(str(f)).build()
    assert qp.params["convention"] == "qpsolvers"
    for name in ("pdas", "clarabel"):
        sol = run(name, qp)
        assert sol.status == Status.SOLVED, (name, sol.message)
        np.testing.assert_allclose(original_x(qp, sol.x), res.x, atol=1e-7 * np.abs(res.x).max())
        np.testing.assert_allclose(qpsolvers_duals(qp, sol.multipliers)["z"], res.z, atol=1e-6 * np.abs(res.z).max())
        assert original_objective(qp, sol.x) == pytest.approx(res.obj, rel=1e-9)


def test_equalities_and_bounds_in_qpsolvers_convention(tmp_path):
    """A x = b, lb <= x <= ub (infinite entries: no bound) as qpsolvers reads them, multipliers in its signs."""
    from dualfem.problems.generic_qp import qpsolvers_duals

    P, q, G, _ = _small(seed=1, m=2)
    h = np.array([0.3, np.inf])
    A, b = np.random.default_rng(2).standard_normal((1, 6)), np.array([0.7])
    lb, ub = np.full(6, -np.inf), np.full(6, np.inf)
    lb[0], ub[3] = 0.1, 0.2
    f = tmp_path / "eq.npz"
    np.savez(f, P=P, q=q, G=G, h=h, A=A, b=b, lb=lb, ub=ub)
    res = _qpsolvers_solve(P, q, G, h, A, b, lb, ub)
    qp = load_scene(str(f)).build()
    sol = run("clarabel", qp)
    assert sol.status == Status.SOLVED, sol.message
    np.testing.assert_allclose(original_x(qp, sol.x), res.x, atol=1e-7 * np.abs(res.x).max())
    duals = qpsolvers_duals(qp, sol.multipliers)
    scale = np.abs(q).max()
    for k in ("z", "y", "z_box"):
        np.testing.assert_allclose(duals[k], getattr(res, k), atol=1e-6 * scale)


def test_dualfems_own_names_mean_B_x_ge_Bx_min(tmp_path):
    """K, F, B, Bx_min: min 1/2 x'Kx - F'x s.t. B x >= Bx_min, the same QP as qpsolvers' (P, -F... ) mirror."""
    P, q, G, h = _small(seed=3)
    f = tmp_path / "own.npz"
    np.savez(f, K=P, F=-q, B=-G, Bx_min=-h)
    qp = load_scene(str(f)).build()
    assert qp.params["convention"] == "dualfem"
    res = _qpsolvers_solve(P, q, G, h)
    sol = run("pdas", qp)
    assert sol.status == Status.SOLVED, sol.message
    np.testing.assert_allclose(original_x(qp, sol.x), res.x, atol=1e-7 * np.abs(res.x).max())


@pytest.mark.parametrize("arrays, needle", [
    ({"P": 1, "q": 1, "G": 1, "h": 1, "B": 1}, r"both .*\(B\) and the arrays P, q, G, h of qpsolvers.*ambiguous"),
    ({"K": 1, "F": 1, "G": 1}, r"both .*\(K, F\) and the arrays G .*ambiguous.*G x <= h.*B x >= Bx_min"),
    ({"P": 1, "q": 1, "G": 1, "convention": "dualfem"}, r"convention = 'dualfem'.*qpsolvers' convention"),
    ({"x": 1}, r"holds no QP.*G x <= h.*B x >= Bx_min"),
])
def test_a_file_that_could_be_read_either_way_is_refused(tmp_path, arrays, needle):
    P, q, G, h = _small()
    full = {"P": P, "q": q, "G": G, "h": h, "K": P, "F": -q, "B": -G, "x": q}
    a = {k: (v if isinstance(v, str) else full[k]) for k, v in arrays.items()}
    with pytest.raises(InputError, match=needle):
        load_scene(_write(tmp_path, **a)).build()


def test_a_stated_convention_that_agrees_is_accepted(tmp_path):
    P, q, G, h = _small()
    qp = load_scene(_write(tmp_path, P=P, q=q, G=G, h=h, convention="qpsolvers: G x <= h")).build()
    assert qp.m == 3


@pytest.mark.parametrize("suffix", [".npz", ".mat"])
def test_export_in_qpsolvers_convention_is_the_same_qp(tmp_path, suffix):
    """``dualfem export --convention qpsolvers``: P, q, G, h that qpsolvers itself solves to dualfem's answer,
    and that dualfem reads back as the same QP."""
    f = tmp_path / f"f2{suffix}"
    assert main(["export", "f2", "--set", "N=8", "-o", str(f), "--convention", "qpsolvers"]) == 0
    if suffix == ".npz":
        d = dict(np.load(f))
        P, G = (sp.coo_matrix((d[f"{m}_data"], (d[f"{m}_row"], d[f"{m}_col"])), shape=tuple(d[f"{m}_shape"]))
                for m in ("P", "G"))
    else:
        d = scipy.io.loadmat(f)
        P, G = d["P"], d["G"]
    q, h = np.ravel(d["q"]), np.ravel(d["h"])
    direct = load_scene("f2", {"N": 8}).build()
    ref = run("pdas", direct)
    res = _qpsolvers_solve(P.toarray(), q, G.toarray(), h)
    np.testing.assert_allclose(res.x, ref.x, atol=1e-9 * np.abs(ref.x).max())
    np.testing.assert_allclose(res.z, ref.multipliers, atol=1e-7 * np.abs(ref.multipliers).max())
    back = load_scene(str(f)).build()
    assert back.params["convention"] == "qpsolvers"
    assert abs(back.K - direct.K).max() == 0 and np.array_equal(back.F, direct.F)
    assert abs(back.B - direct.B).max() == 0


def test_a_public_test_set_file_is_solved_as_it_is(tmp_path):
    """The test set's CSC files in qpsolvers' convention (dualfem.experiments.testset_files) are read by qp_file."""
    from dualfem.experiments.testset import qpsolvers_form
    from dualfem.experiments.testset_files import write_qp

    direct = load_scene("f2", {"N": 8}).build()
    f = write_qp(tmp_path / "f2.npz", "f2", *qpsolvers_form(direct))
    qp = load_scene(str(f)).build()
    assert abs(qp.K - direct.K).max() == 0 and abs(qp.B - direct.B).max() == 0 and np.array_equal(qp.F, direct.F)
    bad = dict(np.load(f))
    bad["G_indptr"] = bad["G_indptr"][:-1]
    with pytest.raises(InputError, match="G_indptr"):
        load_scene(_write(tmp_path, **bad)).build()


def test_bounds_alone_and_box_constraints(tmp_path):
    """lb alone is a cone after the shift (solved); lb and ub on the same unknowns are not (refused, saying so)."""
    P, q = np.eye(3), np.array([1.0, -2.0, 0.5])
    qp = load_scene(_write(tmp_path, P=P, q=q, lb=np.array([0.0, 0.0, -np.inf]))).build()
    sol = run("pdas", qp)
    assert sol.status == Status.SOLVED and np.allclose(original_x(qp, sol.x), [0.0, 2.0, -0.5], atol=1e-14)
    with pytest.raises(InputError, match="box constraints"):
        load_scene(_write(tmp_path, P=P, q=q, lb=np.zeros(3), ub=np.ones(3))).build()
    with pytest.raises(InputError, match=r"lb\[1\] = 2 > ub\[1\] = 1"):
        load_scene(_write(tmp_path, P=P, q=q, lb=np.array([0.0, 2.0, 0.0]), ub=np.ones(3))).build()
