"""Constraint laws and blocks in the core (dualfem.core.laws, dualfem.core.constraints): today's QPs are one
Signorini block, the law's methods are exactly the formulas the evaluator and the certificate used, further
blocks are validated, stacked, hashed, guarded and fingerprinted, and a solver never runs on a law it does not
accept. The toy bilateral law through every solver: tests/plugin_laws."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core import constraints
from dualfem.core.errors import InputError
from dualfem.core.laws import SIGNORINI, Coulomb, Law, Signorini, Tresca
from dualfem.core.qp import QP
from dualfem.core.solver import Solver, unhandled_law
from dualfem.experiments.runner import fingerprint, guarded_view
from dualfem.laws import Constraint


class Glue(Law):
    name = "glue"

    def project(self, mu, weights=None, mus=()):
        return mu

    def primal(self, gap):
        return float(np.abs(gap).max(initial=0.0))

    def dual(self, mu, weights=None, mus=()):
        return 0.0

    def complementarity(self, mu_s, gap_s, weights=None, fs=1.0, mus=()):
        return np.zeros_like(mu_s)

    def support(self, mu, gap, weights=None, mus=()):
        return float(mu @ gap)

    def energy(self, gap, weights=None):
        return 0.0                      # a constraint: no term of the objective

    def complementary(self, mu, gap, weights=None, mus=()):
        return np.asarray(mu, float)    # an equality row: any force is complementary

    def face(self, mu, gap, c):
        return np.ones(mu.shape, bool)

    def conic(self):
        return "zero"


def _qp(blocks=()):
    K = sp.diags([2.0, 3.0, 4.0]).tocsc()
    return QP(K=K, F=np.array([1.0, -1.0, 2.0]), B=sp.csr_matrix([[1.0, 0, 0]]), weights=[0.5], blocks=blocks)


def test_a_qp_is_one_signorini_block_of_its_b_and_weights():
    qp = _qp()
    (block,) = qp.constraints
    assert block.G is qp.B and block.weights is qp.weights and block.law is SIGNORINI
    assert qp.G is qp.B and qp.m_total == qp.m == 1 and qp.blocks == ()


def test_signorini_is_exactly_the_formulas_it_replaced():
    rng = np.random.default_rng(3)
    mu, gap = rng.standard_normal(40), rng.standard_normal(40)
    law = Signorini()
    assert law.primal(gap) == max(0.0, -gap.min(initial=0.0)) and law.dual(mu) == max(0.0, -mu.min(initial=0.0))
    assert np.array_equal(law.project(mu), np.maximum(mu, 0.0))
    assert np.array_equal(law.complementarity(mu, gap), np.abs(mu * gap))
    assert law.support(mu, gap) == float(mu @ gap) and law.conic() == "nonneg"
    assert np.array_equal(law.face(mu, gap, 2.0), mu - 2.0 * gap > 0)
    assert law.face_holds(np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([True, False]), 0.5, 0.5)
    assert not law.face_holds(np.array([0.4, 0.0]), np.array([0.0, 1.0]), np.array([True, False]), 0.5, 0.5)
    assert law == SIGNORINI and law != Glue() and Tresca(0.5) == Tresca(0.5) != Tresca(1.0)
    per_node = Tresca(np.array([0.5, 1.0]))
    assert per_node == per_node and per_node != Tresca(np.array([0.5, 1.0]))


def test_further_blocks_are_stacked_split_and_projected():
    qp = _qp((Constraint.make(sp.csr_matrix([[0, 1.0, -1.0]]), None, Glue()),))
    assert qp.m == 1 and qp.m_total == 2 and [b.law.name for b in qp.constraints] == ["signorini", "glue"]
    assert np.array_equal(qp.G.toarray(), [[1, 0, 0], [0, 1, -1]])
    mu = np.array([-1.0, -2.0])
    assert np.array_equal(constraints.project(qp.constraints, mu), [0.0, -2.0])   # each law its own dual set
    assert [list(v) for v in constraints.split(qp.constraints, mu)] == [[-1.0], [-2.0]]
    assert constraints.conic_rows(qp.constraints) == [("nonneg", 1), ("zero", 1)]
    assert np.array_equal(constraints.upper_bounds(qp.constraints), [np.inf, 0.0])
    assert qp.key() != _qp().key()


def test_a_bad_block_is_refused_with_its_law_named():
    with pytest.raises(InputError, match="glue block's G must have 3 columns"):
        _qp((Constraint.make(sp.csr_matrix([[0, 1.0]]), None, Glue()),))
    with pytest.raises(InputError, match="glue block's weights must be > 0"):
        _qp((Constraint.make(sp.csr_matrix([[0, 1.0, 0]]), [-1.0], Glue()),))
    with pytest.raises(InputError, match="must be dualfem.core.constraints.Constraint"):
        _qp(("not a block",))


def test_a_law_without_a_conic_description_is_refused_by_a_conic_backend():
    class Friction(Glue):
        name = "friction"

        def conic(self):
            return None

    with pytest.raises(InputError, match="'friction' law of constraint block 1 has no conic description"):
        constraints.conic_rows(_qp((Constraint.make(sp.csr_matrix([[0, 1.0, 0]]), None, Friction()),)).constraints)


def test_the_runner_guards_and_fingerprints_further_blocks():
    qp = _qp((Constraint.make(sp.csr_matrix([[0, 1.0, -1.0]]), None, Glue()),))
    view = guarded_view(qp)
    with pytest.raises(ValueError, match="read-only"):
        view.blocks[0].G.data[0] = 5.0
    before = fingerprint(qp)
    assert "blocks" in before and "blocks" not in fingerprint(_qp())      # today's QPs: the same record as before
    qp.blocks[0].G.data[0] = 5.0
    assert fingerprint(qp)["blocks"] != before["blocks"]


def test_accepts_defaults_to_signorini_and_names_the_law():
    class Plain(Solver):
        name = "plain"

    class Both(Solver):
        name = "both"
        accepts = ("signorini", "glue")

    glued = _qp((Constraint.make(sp.csr_matrix([[0, 1.0, -1.0]]), None, Glue()),))
    assert Plain.accepts == ("signorini",) and unhandled_law(Plain, _qp()) is None
    why = unhandled_law(Plain, glued)
    assert "does not handle the 'glue' law of constraint block 1 (it accepts: 'signorini')" in why
    assert unhandled_law(Both, glued) is None


def _friction_qp(law, f: float = 3.0, p: float = 2.0) -> QP:
    """x = (x_n, x_t), K = I, F = (-p, f): pushed into contact (mu_n = p), pulled tangentially by f."""
    return QP(K=sp.identity(2, format="csc"), F=np.array([-p, f]), B=sp.csr_matrix([[1.0, 0.0]]), weights=[1.0],
              blocks=(Constraint.make(sp.csr_matrix([[0.0, 1.0]]), [1.0], law),))


@pytest.mark.parametrize("law", [Tresca(0.5), Coulomb(0.5)], ids=["tresca", "coulomb"])
def test_friction_laws_fit_the_interface_without_a_core_change(law):
    from dualfem.core import evaluator
    from dualfem.numerics.certify import certified_error

    qp = _friction_qp(law)          # sliding: |f| = 3 > bound (0.5 or 0.5 mu_n = 1): mu_t = -bound, x_t = f - bound
    bound = 0.5 if law.name == "tresca" else 1.0
    x, mu = np.array([0.0, 3.0 - bound]), np.array([2.0, -bound])
    assert evaluator.kkt_error(evaluator.residuals(qp, x, mu)) < 1e-15
    frictionless = evaluator.residuals(qp, np.array([0.0, 3.0]), np.array([2.0, 0.0]))
    assert frictionless["complementarity"] > 0.1 and frictionless["stationarity"] == 0.0
    assert evaluator.residuals(qp, x, np.array([2.0, -2 * bound]))["dual"] > 0.1
    if law.name == "tresca":
        assert evaluator.residuals(qp, x, mu)["energy"] == pytest.approx(0.5 * x @ x - qp.F @ x + 0.5 * x[1])
        xp = x + np.array([0.0, 1e-3])
        cert = certified_error(qp, xp, mu)            # the face step measures the error |xp - x|_K = 1e-3
        assert cert["active_set"] == pytest.approx(1e-3 / evaluator.size_energy(qp, xp), rel=1e-6)
        assert cert["bound"] >= cert["active_set"]
    assert f"does not handle the '{law.name}' law" in unhandled_law(Solver, qp)


def _disc_qp(law, f=(3.0, 4.0), p: float = 2.0) -> QP:
    """3D: x = (x_n, x_t1, x_t2), K = I, F = (-p, f1, f2): the tangential pull f is a vector of norm 5."""
    return QP(K=sp.identity(3, format="csc"), F=np.array([-p, *f]), B=sp.csr_matrix([[1.0, 0.0, 0.0]]), weights=[1.0],
              blocks=(Constraint.make(sp.csr_matrix([[0, 1.0, 0], [0, 0, 1.0]]), [1.0, 1.0], law),))


@pytest.mark.parametrize("law,radius", [(Tresca(0.5, components=2), 0.5), (Coulomb(0.5, components=2), 1.0),
                                        (Tresca(3.0, components=2), 3.0)], ids=["tresca", "coulomb", "tresca-big"])
def test_a_3d_friction_block_is_a_disc_not_a_box(law, radius):
    from dualfem.core import evaluator

    qp = _disc_qp(law)
    f = np.array([3.0, 4.0])
    slip = max(0.0, 5.0 - radius)                     # slides along f by |f| - r (r < 5); mu_t = -r f/|f|
    x = np.array([0.0, *(f / 5.0 * slip)])
    mu = np.array([2.0, *(-radius * f / 5.0)])
    assert evaluator.kkt_error(evaluator.residuals(qp, x, mu)) < 1e-14
    box = np.array([2.0, -radius, -radius])          # the box corner: inside the box, outside the disc
    assert evaluator.residuals(qp, x, box)["dual"] > 0.1 * radius / 5
    assert np.allclose(law.project(box[1:], np.ones(2), (np.array([2.0]), box[1:])),
                       -radius * np.ones(2) / np.sqrt(2))


def test_stick_inside_the_disc_and_slip_directions_are_checked():
    from dualfem.core import evaluator

    law = Tresca(6.0, components=2)                   # r = 6 > |f| = 5: stick, mu_t = -f, x_t = 0
    qp = _disc_qp(law)
    good = evaluator.residuals(qp, np.zeros(3), np.array([2.0, -3.0, -4.0]))
    assert evaluator.kkt_error(good) < 1e-14
    law = Tresca(0.5, components=2)
    qp = _disc_qp(law)
    wrong_way = np.array([0.0, 4.5 * 0.8, -4.5 * 0.6])    # slip of the right size, in a wrong direction
    r = evaluator.residuals(qp, wrong_way, np.array([2.0, -0.3, -0.4]))
    assert r["complementarity"] > 0.01 or r["stationarity"] > 0.01


def test_friction_law_parameters_enter_the_qp_key_and_are_validated():
    a, b = _disc_qp(Tresca(np.array([0.5]), components=2)), _disc_qp(Tresca(np.array([0.6]), components=2))
    assert a.key() != b.key() and a.key() == _disc_qp(Tresca(np.array([0.5]), components=2)).key()
    with pytest.raises(ValueError, match="bound"):
        Tresca(-1.0)
    with pytest.raises(ValueError, match="components"):
        Coulomb(0.3, components=3)


@pytest.mark.parametrize("law,radius", [(Tresca(0.5, components=2), 0.5), (Coulomb(0.5, components=2), 1.0)],
                         ids=["tresca", "coulomb"])
def test_an_infeasible_frictional_answer_gets_a_bound_above_its_error(law, radius):
    """certify.infeasible_bound with friction blocks: an answer penetrating by 1e-3 (beyond rounding: the
    duality-gap bound does not apply) is bounded, and the bound holds its true energy-norm error."""
    from dualfem.core import evaluator
    from dualfem.numerics.certify import certified_error

    qp = _disc_qp(law)
    f = np.array([3.0, 4.0])
    exact = np.array([0.0, *(f / 5.0 * (5.0 - radius))])
    mu = np.array([2.0, *(-radius * f / 5.0)])
    x = exact + np.array([-1e-3, 2e-4, -1e-4])
    cert = certified_error(qp, x, mu)
    d = x - exact
    true = np.sqrt(d @ (qp.K @ d)) / evaluator.size_energy(qp, x)
    assert np.isnan(cert["bound"]) and np.isfinite(cert["infeasible"])
    assert true <= cert["infeasible"] * (1 + 1e-12) and cert["infeasible"] < 20 * true     # K = I: tight


def _stuck_nodes(k: int, c: float = 1e-4, r: float = 1.0, f: float = 0.4):
    """k independent 2D nodes (x_n, u+, u-), K = I, a common displacement c of both faces, a tangential pull f < 2 r:
    every node sticks, x = (0, c, c), mu = (p, -f / 2)."""
    import scipy.sparse as sps

    K = sps.identity(3 * k, format="csc")
    F = np.tile([-1.0, c + f / 2, c - f / 2], k)
    B = sps.kron(sps.identity(k), sps.csr_matrix([[1.0, 0, 0]]), format="csr")
    G = sps.kron(sps.identity(k), sps.csr_matrix([[0, 1.0, -1.0]]), format="csr")
    qp = QP(K=K, F=F, B=B, weights=np.ones(k), blocks=(Constraint.make(G, np.ones(k), Tresca(r)),))
    x, mu = np.tile([0.0, c, c], k), np.r_[np.ones(k), np.full(k, -f / 2)]
    return qp, x, mu


def test_a_stuck_answer_exact_to_rounding_keeps_a_rounding_bound():
    """The duality-gap bound of a frictional QP has a rounding floor: stick nodes whose slip u+ - u- is one ulp of
    the faces' displacement (what an exact solver leaves) are not charged sqrt(ulp) (1.7e-10 here without the floor;
    1.3e-8 on a 400-crack Coulomb body, which demoted pdas's exact answer above the face step's size limit); a slip
    of 1e-9 still is."""
    from dualfem.numerics.certify import error_bound

    qp, x, mu = _stuck_nodes(50)
    ulp = x.copy()
    ulp[2::3] = np.nextafter(ulp[2::3], 1.0)            # u- one ulp above u+: slip -1.4e-20
    assert error_bound(qp, ulp, mu) < 1e-12
    off = x.copy()
    off[2::3] += 1e-9
    assert error_bound(qp, off, mu) > 1e-5                # a real slip of 1e-9 keeps its (square-root) charge
