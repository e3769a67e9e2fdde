"""The paper's method: accuracy, identical fast/full iterates, shortcut, regression counts."""
from __future__ import annotations

import numpy as np
import pytest

from dualfem.core import evaluator
from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.core.solution import Status
from dualfem.experiments.runner import make_solver, run


@pytest.fixture(scope="module")
def references():
    """Certified references: Clarabel's contact set, then the exact KKT solve for that set."""
    cache = {}

    def get(scene, name, delta):
        key = (name, delta)
        if key not in cache:
            _, qp = scene(name, 16, delta)
            clar = run("clarabel", qp)
            # at delta = 1e-9 Clarabel's x is within its 1e-5 but its contact forces are 1e-3 off: certified
            # since issue 26 (`inaccurate`, "multiplier"); its contact set is still right
            assert clar.ok or (delta <= 1e-9 and "multiplier" in clar.message), clar.message
            xs, mus, ok = evaluator.certify(qp, clar.x)
            assert ok, "Clarabel's contact set does not certify"
            cache[key] = (clar, xs, mus)
        return cache[key]
    return get


@pytest.mark.parametrize("name", ["f1", "f2", "f3"])
@pytest.mark.parametrize("delta", [1e-1, 1e-5, 1e-9])
def test_agrees_with_certified_reference(scene, references, name, delta):
    _, qp = scene(name, 16, delta)
    _, xs, mus = references(scene, name, delta)
    auto = run("uzawa_auto", qp)
    assert auto.ok, auto.message
    d = evaluator.compare(qp, auto.x, auto.multipliers, xs, mus)
    assert d["x_energy"] < 1e-8 and d["contact_mismatch"] == 0 and d["multipliers"] < 1e-6
    paper = run("uzawa", qp)
    d = evaluator.compare(qp, paper.x, paper.multipliers, xs, mus)
    if paper.ok:
        assert d["x_energy"] < 1e-7 and d["contact_mismatch"] == 0
        assert evaluator.kkt_error(paper.residuals) < 1e-6
    else:  # delta = 1e-9: the paper's stop test fires while the dual error is still ~1e-3
        assert delta == 1e-9 and paper.status.value == "inaccurate"
        assert "rate 0.99" in paper.message and "compliance" in paper.message
        assert d["x_energy"] < 1e-5


@pytest.mark.parametrize("name", ["f1", "f2", "f3"])
@pytest.mark.parametrize("delta", [1e-1, 1e-5, 1e-9])
def test_agrees_with_clarabel(scene, references, name, delta):
    """Uzawa vs Clarabel directly. At delta = 1e-9 Clarabel itself is only ~5e-6 accurate
    (measured against the certified reference), so the bound there is Clarabel's error."""
    _, qp = scene(name, 16, delta)
    clar, xs, mus = references(scene, name, delta)
    sol = run("uzawa" if delta > 1e-9 else "uzawa_auto", qp)
    d = evaluator.compare(qp, sol.x, sol.multipliers, clar.x, clar.multipliers)
    clar_err = evaluator.compare(qp, clar.x, clar.multipliers, xs, mus)["x_energy"]
    assert d["x_energy"] < max(1e-7, 2 * clar_err)
    assert d["contact_mismatch"] == 0


@pytest.mark.parametrize("name, delta, N", [("f1", 1e-1, 16), ("f2", 1e-5, 16), ("f2", 1e-1, 16),
                                             ("f2", 1e-7, 16), ("f2", 1e-9, 8), ("f3", 1e-5, 16)])
def test_fast_and_full_paths_identical(scene, name, delta, N):
    _, qp = scene(name, N, delta)
    fast = run("uzawa", qp)
    full = run("uzawa", qp, {"linalg": "full"})
    assert fast.status == full.status
    assert fast.iterations == full.iterations
    assert [h["inner_steps"] for h in fast.history] == [h["inner_steps"] for h in full.history]
    assert [h["steps"] for h in fast.history] == [h["steps"] for h in full.history]
    assert np.abs(fast.x - full.x).max() <= 1e-10 * np.abs(full.x).max()
    assert np.abs(fast.multipliers - full.multipliers).max() <= 1e-10 * max(np.abs(full.multipliers).max(), 1e-300) \
        or np.abs(full.multipliers).max() == 0


def test_f3_shortcut(scene):
    _, qp = scene("f3", 16, 1e-5)
    sol = run("uzawa", qp)
    assert sol.ok and sol.iterations == {"outer": 1, "inner": 1}
    assert np.all(sol.multipliers == 0) and np.all(qp.B @ sol.x >= 0)
    slow = run("uzawa", qp, {"shortcut": False})
    assert slow.ok and slow.iterations["outer"] == 1
    assert np.abs(slow.x - sol.x).max() <= 1e-12 * np.abs(sol.x).max()
    # no shortcut when contact is needed
    _, qp2 = scene("f2", 16, 1e-5)
    assert run("uzawa", qp2).iterations["outer"] > 1


def test_history_and_counts_consistent(scene):
    _, qp = scene("f2", 16, 1e-5)
    sol = run("uzawa", qp)
    h = sol.history
    assert len(h) == sol.iterations["outer"]
    assert sum(e["inner_steps"] for e in h) == sol.iterations["inner"]
    assert h[-1]["dual_change"] <= 1e-5 < h[0]["dual_change"]
    assert all(0 < s <= 1 for e in h for s in e["steps"])
    assert h[-1]["active"] == evaluator.contact_set(qp, sol.x).sum()


# regression values: N = 16, plane strain, the paper's settings (r = 1e7, absolute outer tol 1e-5 MPa,
# inner 1e-7, step / 2)
PAPER_OUTER = {"tol_mode": "absolute", "tol": 1e-5}
PINNED = {("f1", 1e-1): (5, 10), ("f2", 1e-5): (6, 11), ("f2", 1e-9): (876, 1403), ("f3", 1e-5): (1, 1)}


@pytest.mark.parametrize("key", sorted(PINNED))
def test_iteration_counts_pinned(scene, key):
    name, delta = key
    _, qp = scene(name, 16, delta)
    sol = run("uzawa", qp, PAPER_OUTER)
    assert (sol.iterations["outer"], sol.iterations["inner"]) == PINNED[key]


def test_step_factor_changes_line_search_only(scene):
    _, qp = scene("f2", 16, 1e-1)
    a = run("uzawa", qp)
    b = run("uzawa", qp, {"step_factor": 1.1})
    assert b.ok
    assert np.abs(a.x - b.x).max() < 1e-6 * np.abs(a.x).max()


def test_max_iter_reported_honestly(scene):
    _, qp = scene("f2", 16, 1e-9)
    sol = run("uzawa", qp, {"max_iter": 10})
    assert sol.status.value == "max_iter" and sol.iterations["outer"] == 10
    assert "max_iter" in sol.message


@pytest.mark.parametrize("params, words", [
    ({"r": 0}, "'r'"), ({"tol": -1}, "tol"), ({"step_factor": 1.0}, "step_factor"),
    ({"armijo_c": 1.5}, "armijo_c"), ({"linalg": "dense"}, "linalg"), ({"l0": -1}, "l0"),
    ({"inner_norm": "euclidean"}, "inner_norm"), ({"max_iter": 2.5}, "max_iter"),
    ({"r_rule": "magic"}, "r_rule"), ({"error_factor": 0}, "error_factor"),
])
def test_bad_parameters(params, words):
    with pytest.raises(InputError, match=words):
        make_solver("uzawa", params)


def test_euclidean_inner_norm_on_full_path(scene):
    _, qp = scene("f2", 16, 1e-5)
    sol = run("uzawa", qp, {"linalg": "full", "inner_norm": "euclidean"})
    ref = run("uzawa", qp)
    assert sol.ok
    assert evaluator.compare(qp, sol.x, sol.multipliers, ref.x, ref.multipliers)["x_energy"] < 1e-7


def test_auto_r_is_scale_invariant_and_delta_aware(scene):
    """r_rule='auto': r ~ 100/delta at small delta, and the same r*compliance in other units."""
    from dualfem.core.scene import load_scene

    r = {}
    for d in (1e-5, 1e-9):
        _, qp = scene("f2", 16, d)
        r[d] = run("uzawa_auto", qp).info["r"]
    assert 50 / 1e-9 < r[1e-9] < 200 / 1e-9 and r[1e-5] < 1e9
    # MPa/mm -> Pa/m: E x 1e6, lengths x 1e-3, traction x 1e6: same iterates, x scaled by 1e-3
    base = run("uzawa_auto", load_scene("f2", {"N": 16, "delta": 1e-5}).build())
    qp_si = load_scene("f2", {"N": 16, "delta": 1e-5 * 1e-3 / 1e6, "E": 69000e6, "width": 1e-3,
                              "height": 1e-3, "defect": [[0.25e-3, 0.5e-3], [0.75e-3, 0.5e-3]],
                              "load_scale": 1e6}).build()
    si = run("uzawa_auto", qp_si)
    assert si.ok and si.iterations == base.iterations
    assert np.abs(si.x - 1e-3 * base.x).max() < 1e-8 * 1e-3 * np.abs(base.x).max()


def test_stdout_is_one_json_object_even_with_osqp(tmp_path):
    """OSQP prints notices from C on stdout; the CLI must keep --json output clean."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "dualfem", "solve", "f3", "--set", "N=8", "--solver", "osqp",
                          "--json"], capture_output=True, text=True, check=True).stdout
    assert len(out.strip().splitlines()) == 1 and json.loads(out)["status"] == "solved"


@pytest.mark.parametrize("r", [1.0, 1e3])
def test_no_false_convergence_after_one_outer_iteration(scene, r):
    """Tiny r at tiny delta with the paper's absolute outer test: r [u_nu] is below tol at once. The
    proximal-point bound change / (r mu_min) must flag it (found by the stress grid as a silent
    wrong answer)."""
    _, qp = scene("f2", 16, 1e-9)
    sol = run("uzawa", qp, {"r": r, **PAPER_OUTER})
    assert sol.iterations["outer"] == 1
    assert sol.status.value == "inaccurate" and "compliance" in sol.message


@pytest.mark.parametrize("solver", ["uzawa", "uzawa_auto"])
def test_stopping_test_is_scale_free(solver):
    """Scaling the load by 1e-12 .. 1e12 gives the same iterations, status and relative answer
    (the default outer test is relative; the paper's absolute one is tol_mode='absolute')."""
    base = run(solver, load_scene("f2", {"N": 16}).build())
    for s in (1e-12, 1e-6, 1e6, 1e12):
        sol = run(solver, load_scene("f2", {"N": 16, "load_scale": s}).build())
        assert sol.status == base.status == Status.SOLVED
        assert sol.iterations == base.iterations
        assert np.abs(sol.x / s - base.x).max() <= 1e-8 * np.abs(base.x).max()



def _solve_extended(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """H^-1 g by Gaussian elimination with partial pivoting in extended precision (a reference)."""
    H, g = H.astype(np.longdouble), g.astype(np.longdouble)
    for k in range(g.size):
        p = k + int(np.argmax(np.abs(H[k:, k])))
        H[[k, p]], g[[k, p]] = H[[p, k]], g[[p, k]]
        f = H[k + 1:, k] / H[k, k]
        H[k + 1:, k:] -= f[:, None] * H[k, k:]
        g[k + 1:] -= f * g[k]
    x = np.zeros(g.size, np.longdouble)
    for k in range(g.size - 1, -1, -1):
        x[k] = (g[k] - H[k, k + 1:] @ x[k + 1:]) / H[k, k]
    return x


@pytest.mark.parametrize("name, delta", [("f2", 1e-5), ("f1", 1e-9)])
@pytest.mark.parametrize("penalty", [1e-2, 1e2, 1e8])
def test_newton_solve_without_the_newton_matrix(scene, name, delta, penalty):
    """The reduced space solves (Q + B_A' C_A B_A) d = g by Sherman-Morrison-Woodbury on the Delassus
    matrix. Against an extended-precision solve it is as accurate as a Cholesky factorization of the
    dense Newton matrix (the former method) for small penalties C_A (in units of 1 / min diag D, the
    scale of uzawa_auto's r) and far more accurate for huge ones (measured: 8.5e-12 against 4.4e-9
    on f2, 4.4e-9 against 1.1e-5 on f1 at delta = 1e-9, penalty 1e8)."""
    from dualfem.solvers.uzawa import _ReducedSpace

    _, qp = scene(name, 16, delta)
    space = _ReducedSpace(qp, "energy")
    rng = np.random.default_rng(1)
    A = rng.random(qp.m) < 0.6
    coef = np.where(A, penalty * rng.uniform(0.5, 2.0, qp.m) / np.diag(space.red.delassus()).min(), 0.0)
    g = rng.standard_normal(space.Q.shape[0])
    Q, B = space.Q.astype(np.longdouble), space.B.astype(np.longdouble)
    d_true = _solve_extended(Q + B.T @ (coef[:, None].astype(np.longdouble) * B), g)
    scale = float(np.abs(d_true).max())
    d_dense = np.linalg.solve(space.Q + space.B.T @ (coef[:, None] * space.B), g)   # the former method
    err_dense = float(np.abs(d_dense - d_true).max()) / scale
    err = float(np.abs(space.newton(coef, g) - d_true).max()) / scale
    assert err <= max(1e-11, 0.1 * err_dense), (err, err_dense)
    d0 = space.newton(np.zeros(qp.m), g)                  # no active set: Q^-1 g
    assert np.abs(space.Q @ d0 - g).max() <= 1e-10 * np.abs(g).max()
