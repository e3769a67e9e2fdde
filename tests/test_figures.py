"""Figures drawn from the library API (Agg), the history plot on a fake Solution, and the two
report generators on tiny meshes."""
from __future__ import annotations

import json
import re

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from dualfem.core.errors import InputError  # noqa: E402
from dualfem.core.registry import solvers  # noqa: E402
from dualfem.core.scene import load_scene  # noqa: E402
from dualfem.core.solution import Solution, Status  # noqa: E402
from dualfem.experiments.runner import run  # noqa: E402
from dualfem.post import figures as F  # noqa: E402
from dualfem.post.fields import Post  # noqa: E402


@pytest.fixture(scope="module")
def cases():
    out = []
    for d in (1e-1, 1e-7):
        qp = load_scene("f2", {"N": 16, "delta": d}).build()
        out.append((f"delta = {d:g}", qp, run(F.pick_solver(), qp)))
    return out


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def test_pick_solver():
    name = F.pick_solver()
    assert name in solvers() and solvers()[name].exact
    assert F.pick_solver(order=("no-such-solver", "clarabel")) == "clarabel"
    with pytest.raises(InputError, match="none of the solvers"):
        F.pick_solver(order=("no-such-solver",))
    with pytest.raises(InputError, match="unknown solver"):
        F.pick_solver("no-such-solver")


def test_plot_deformed(cases):
    _, qp, sol = cases[0]
    ax = F.plot_deformed(qp, sol, scale=300.0)
    p = Post(qp, sol)
    coll = ax.collections[0]
    assert np.allclose(coll.get_array(), p.von_mises)
    # the drawn triangles sit at X + 300 u
    xy = p.deformed(300.0)
    tri0 = coll.get_paths()[0].vertices[:3]
    assert np.allclose(tri0, xy[:, qp.geometry.cells[:, 0]].T)
    cbar_ax = [a for a in ax.figure.axes if a is not ax]
    assert cbar_ax and "MPa" in cbar_ax[0].get_ylabel() and "von Mises" in cbar_ax[0].get_ylabel()
    assert coll.get_clim() == (0.0, pytest.approx(p.von_mises.max()))


def test_plot_jump_faces_pressure(cases):
    ax = F.plot_jump(cases, unit=1e-5)
    lines = [ln for ln in ax.get_lines() if ln.get_label().startswith("delta")]
    assert len(lines) == 2
    for ln, (_, qp, sol) in zip(lines, cases, strict=True):
        d = Post(qp, sol).defect
        assert np.allclose(ln.get_xdata(), d["X"][0])
        assert np.allclose(ln.get_ydata(), d["jump_normal"] / 1e-5)
    assert ax.get_xlabel() == "x1"
    ax = F.plot_jump(cases, log=True, floor=1e-16)
    assert ax.get_yscale() == "log"
    d = Post(cases[0][1], cases[0][2]).defect
    assert np.allclose(ax.get_lines()[0].get_ydata(), np.maximum(np.abs(d["jump_normal"]), 1e-16))

    _, qp, sol = cases[0]
    ax = F.plot_faces(qp, sol, scale=100.0)
    d = Post(qp, sol).defect
    up, lo, ref = ax.get_lines()[:3]
    assert np.allclose(up.get_ydata(), d["X"][1] + 100.0 * d["u_upper"][:, 1])
    assert np.allclose(lo.get_xdata(), d["X"][0] + 100.0 * d["u_lower"][:, 0])
    assert np.allclose(ref.get_ydata(), 0.5)

    ax = F.plot_pressure(cases)
    ln = ax.get_lines()[0]
    assert np.allclose(ln.get_ydata()[1:-1], qp.pressure(sol.multipliers))
    assert "MPa" in ax.get_ylabel()
    with pytest.raises(InputError, match="component"):
        F.plot_jump(cases, component="shear")


def test_plot_history_fake_solution():
    vals = [1.0, 0.1, 1e-3, 1e-6]
    fake = Solution(solver="uzawa", status=Status.SOLVED,
                    history=[{"k": k + 1, "dual_change": v, "inner_steps": 1} for k, v in enumerate(vals)])
    other = Solution(solver="pdas", status=Status.SOLVED, history=[{"iter": 1, "residual": 1e-16}])
    ax = F.plot_history([("delta = 1e-5", fake), ("no history", other)], key="dual_change", logx=True)
    (ln,) = ax.get_lines()
    assert np.allclose(ln.get_xdata(), [1, 2, 3, 4]) and np.allclose(ln.get_ydata(), vals)
    assert ax.get_yscale() == "log" and ax.get_xscale() == "log"
    assert "no history" in ax.get_legend().get_title().get_text()
    with pytest.raises(InputError, match="dual_change"):
        F.plot_history([("x", other)], key="dual_change")
    assert F.history_series(other, "residual")[1][0] == 1e-16
    # a sequence of keys: each run draws the first it has; per-run line styles are applied
    ax = F.plot_history([("u", fake, {"color": "red", "ls": "--"}), ("p", other)], key=("dual_change", "residual"))
    l1, l2 = ax.get_lines()
    assert l1.get_color() == "red" and l1.get_linestyle() == "--" and "dual_change" in l1.get_label()
    assert np.allclose(l2.get_ydata(), [1e-16]) and "residual" in l2.get_label()


@pytest.mark.skipif("uzawa" not in solvers(), reason="the uzawa solver is not registered")
def test_report_figures_small(tmp_path):
    from dualfem.cli.reports.figures import generate
    from dualfem.core.scene import library

    text = generate(tmp_path, N=8, sweep=(1e-1, 1e-5), dpi=40, history_solvers=["pdas"] if "pdas" in solvers() else [],
                    progress=lambda m: None, scene_overrides={"mesh_size": 0.1})
    images = re.findall(r"\(figures/([^)]+\.png)\)", text)
    # deformed bodies, jump/faces/pressure, the scene library, three histories
    assert len(images) == 5 + 3 + len(library(dim=2)) + 3 and sum(n.startswith("scene_") for n in images) \
        == len(library(dim=2))
    for name in images:
        assert (tmp_path / "figures" / name).stat().st_size > 1000
    assert "| f2 |" in text and "Agreement of the Uzawa solutions" in text


def test_report_convergence_small(tmp_path):
    from dualfem.cli.reports.convergence import run as report

    assert report(["--deltas", "0.1", "--N", "8,16", "--ref-N", "32", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "convergence.json").read_text())
    lv = res["deltas"]["0.1"]["levels"]
    assert [x["N"] for x in lv] == [8, 16]
    assert lv[1]["energy_norm"] < lv[0]["energy_norm"]
    # the energy-norm order on a cracked body lies between the h^(1/2) of the tip singularity and the
    # h^1 of P1 elements for a smooth solution (a reference only 2x finer inflates it: allow up to 1.5)
    assert 0.4 < lv[1]["rate_energy_norm"] < 1.5
    md = (tmp_path / "convergence.md").read_text()
    assert "| 16 |" in md and "h^(1/2)" in md
    # the triple-wise order 8-16-32 (the reference closes the triple) is rendered
    assert "| 8-16-32 |" in md and "triple-wise energy-norm order" in md
    for name in ("convergence_errors.png", "convergence_quantities.png"):
        assert (tmp_path / "figures" / name).stat().st_size > 1000
    # re-render from the JSON
    (tmp_path / "convergence.md").unlink()
    assert report(["--from-json", str(tmp_path / "convergence.json"), "--out", str(tmp_path)]) == 0
    assert (tmp_path / "convergence.md").read_text() == md
    with pytest.raises(InputError, match="ref-N"):
        report(["--N", "8,12", "--ref-N", "32", "--out", str(tmp_path)])


@pytest.mark.parametrize("p", [0.5, 0.72, 1.0])
def test_convergence_rates_known_answer(p):
    """rates / triple_rates / fit_rate recover the order of synthetic errors built with a known order."""
    from dualfem.experiments.convergence import fit_rate, rates, triple_rates

    Ns, ref_N, C = [16, 32, 64, 128], 256, 3.0
    h, h_ref = np.array([1.0 / n for n in Ns]), 1.0 / ref_N
    # plain C h^p: every successive rate is p
    assert rates(list(C * h ** p))[1:] == pytest.approx([p] * 3)
    # errors against a discrete reference under Galerkin orthogonality: |u_ref - u_N|^2 = C^2 (h^2p - h_ref^2p)
    measured = C * np.sqrt(h ** (2 * p) - h_ref ** (2 * p))
    plain = rates(list(measured))[1:]
    assert plain[-1] > p + 0.02  # the naive rate is inflated by the reference's own error ...
    assert triple_rates(list(measured)) == pytest.approx([p] * 3)  # ... the triple-wise order is not
    assert triple_rates(list(measured), with_reference=False) == pytest.approx([p] * 2)
    fit = fit_rate(h, measured, h_ref)
    assert fit[0] == pytest.approx(p, abs=2e-3) and fit[1] == pytest.approx(C, rel=1e-2)
    # a smooth part of order 0.8 plus a singular part of order 0.5 (squared errors add): the triple-wise
    # order falls from near 0.8 toward 0.5 as h decreases, as the singular part takes over
    hh = 1.0 / 2.0 ** np.arange(4, 12)
    tr = triple_rates(list(np.sqrt(hh ** 1.6 + 1e-2 * hh ** 1.0)), with_reference=False)
    assert all(0.5 < b < a < 0.8 for a, b in zip(tr, tr[1:], strict=False))
    assert triple_rates([1.0, 1.0, 0.5], with_reference=False) == [None]  # no decrease: undefined, not a number


@pytest.mark.skipif("uzawa" not in solvers(), reason="the uzawa solver is not registered")
def test_report_paper_small(tmp_path, monkeypatch):
    """Run, store the data, re-render from it without solving; the inner stop test study is consistent."""
    import dualfem.experiments.runner as runner
    from dualfem.cli.reports.paper import report_paper
    from dualfem.experiments.paper import INNER_VARIANTS

    md = tmp_path / "paper.md"
    assert report_paper(["--N", "8,12", "--inner-N", "8", "--out", str(md)]) == 0
    data = json.loads((tmp_path / "paper.json").read_text())
    text = md.read_text()
    assert "| **paper** | 18 / 24 |" in text and "Closest: **N=" in text
    runs = data["inner"]["runs"]
    assert {r["variant"] for r in runs} == set(INNER_VARIANTS) and len(runs) == 9 * len(INNER_VARIANTS)
    # the inner test changes m only: the same k in every variant, and the default variant is Table 1's run
    for load in ("f1", "f2", "f3"):
        for d in (1e-7, 1e-5, 1e-1):
            cell = [r for r in runs if r["load"] == load and r["delta"] == d]
            assert len({r["k"] for r in cell}) == 1
            (t1,) = [r for r in data["tables"] if (r["N"], r["plane"], r["load"], r["delta"], r["factor"])
                     == (8, data["inner"]["plane"], load, d, 2.0)]
            assert (t1["k"], t1["m"]) == next((r["k"], r["m"]) for r in cell if r["variant"] == "energy")
            # a weaker (squared) test never needs more Newton steps than the plain one of the same norm
            m = {r["variant"]: r["m"] for r in cell}
            assert m["energy_sq"] <= m["energy"] and m["euclidean_sq"] <= m["euclidean"]
    md.unlink()

    def no_solver(*a, **k):
        raise AssertionError("render-only ran a solver")

    monkeypatch.setattr(runner, "run", no_solver)
    assert report_paper(["--render-only", "--out", str(md)]) == 0
    assert md.read_text() == text


@pytest.fixture(scope="module")
def two_defects():
    pytest.importorskip("gmsh")
    qp = load_scene("two_defects", {"mesh_size": 0.1, "tip_size": 0.05}).build()
    return qp, run("pdas", qp)


def test_plot_deformed_draws_every_defect(two_defects):
    """Each defect on its own (both faces, tips included; no line joins two defects), its undeformed
    line, its number, and the closed nodes (evaluator contact set) at their deformed positions."""
    from dualfem.core import evaluator

    qp, sol = two_defects
    ax = F.plot_deformed(qp, sol, scale=300.0, reference=True, contact=True, labels=True)
    xy = Post(qp, sol).deformed(300.0)
    X = qp.geometry.nodes
    tips, ids = qp.interface.front.reshape(-1, 2), qp.interface.defect_id
    white = [ln for ln in ax.get_lines() if ln.get_color() == "w"]
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert len(white) == 4 and len(dashed) == 2
    for k in range(2):
        rows = np.flatnonzero(ids == k)
        for ln, copies in zip(white[2 * k: 2 * k + 2], (qp.interface.upper, qp.interface.lower), strict=True):
            nodes = np.r_[tips[k, 0], copies[rows], tips[k, 1]]
            np.testing.assert_allclose(np.vstack([ln.get_xdata(), ln.get_ydata()]), xy[:, nodes])
        ref = np.r_[tips[k, 0], qp.interface.lower[rows], tips[k, 1]]
        np.testing.assert_allclose(np.vstack([dashed[k].get_xdata(), dashed[k].get_ydata()]), X[:, ref])
    closed = evaluator.contact_set(qp, sol.x)
    assert 0 < closed.sum() < closed.size
    (marks,) = [ln for ln in ax.get_lines() if ln.get_marker() == "o"]
    np.testing.assert_allclose(np.vstack([marks.get_xdata(), marks.get_ydata()]),
                               xy[:, qp.interface.lower[closed]])
    assert sorted(t.get_text() for t in ax.texts) == ["0", "1"]
    # the jump: one curve per defect, from 0 at its first tip to 0 at its last
    ax = F.plot_jump([("j", qp, sol)], unit=1.0)
    lines = [ln for ln in ax.get_lines() if ln.get_label().startswith("j, defect")]
    assert [ln.get_label() for ln in lines] == ["j, defect 0", "j, defect 1"]
    for k, ln in enumerate(lines):
        y = ln.get_ydata()
        assert y[0] == 0 and y[-1] == 0 and np.allclose(y[1:-1], (qp.B @ sol.x)[ids == k])
        assert ln.get_xdata()[0] == 0 and np.all(np.diff(ln.get_xdata()) > 0)


def test_report_scene_library_section(tmp_path):
    """Every library scene solved (coarse), pictured and tabled by the figures report."""
    pytest.importorskip("gmsh")
    from dualfem.core.scene import library
    from dualfem.experiments.figures import library_runs
    from dualfem.reports.figures import _scenes_section

    items = library_runs("pdas", lambda m: None, {"mesh_size": 0.1})
    assert [it["name"] for it in items] == list(library(dim=2))
    (tmp_path / "figures").mkdir()
    text = "\n".join(_scenes_section({"scenes": items, "exact": "pdas"}, tmp_path / "figures", 300.0, 40))
    images = re.findall(r"\(figures/([^)]+\.png)\)", text)
    assert images == [f"scene_{name}.png" for name in library(dim=2)]
    for name in images:
        assert (tmp_path / "figures" / name).stat().st_size > 1000
    two = next(it["row"] for it in items if it["name"] == "two_defects")
    assert two["defects"] == 2 and two["deltas"] == [1e-5, 1e-4] and sum(two["nodes_per_defect"]) == two["m"]
    assert "| two_defects |" in text and "(1e-05, 0.0001)" in text
    assert all(it["row"]["status"] == "solved" and it["row"]["kkt"] < 1e-8 for it in items)


def test_defect_fields_and_pressure_per_defect(two_defects):
    """defect_fields: each defect with its own tips and s from 0; forces and pressures on the right rows."""
    qp, sol = two_defects
    d = Post(qp, sol).defect
    ids = qp.interface.defect_id
    for k in range(2):
        idx = np.flatnonzero(d["defect_id"] == k)
        assert d["s"][idx][0] == 0 and np.all(np.diff(d["s"][idx]) > 0)
        assert list(d["upper"][idx][[0, -1]]) == list(qp.interface.front[2 * k: 2 * k + 2])
        rows = d["row"][idx][1:-1]
        assert np.array_equal(rows, np.flatnonzero(ids == k)) and np.all(d["row"][idx][[0, -1]] == -1)
        np.testing.assert_allclose(d["force"][idx][1:-1], sol.multipliers[rows])
        np.testing.assert_allclose(d["normal"][idx][1:-1], qp.interface.normals[rows])
    ax = F.plot_pressure([("p", qp, sol)])
    for k, ln in enumerate(ax.get_lines()[:2]):
        np.testing.assert_allclose(ln.get_ydata()[1:-1], qp.pressure(sol.multipliers)[ids == k])


def test_report_figures_renders_without_solving(tmp_path, monkeypatch):
    """The study's cases are frozen: the renderer looks every Solution up and cannot run a solver."""
    import dualfem.experiments.runner as runner
    from dualfem.experiments.figures import collect
    from dualfem.reports.figures import render

    data = collect(N=8, sweep=(1e-1, 1e-5), history_solvers=[], progress=lambda m: None, scenes=False)
    cases = data["cases"]
    assert cases.frozen
    with pytest.raises(RuntimeError, match="not among the study's results"):
        cases.solve(data["exact"], data["scene"], 1e-3)

    def no_solver(*a, **k):
        raise AssertionError("the renderer ran a solver")

    monkeypatch.setattr(runner, "run", no_solver)
    text = render(data, tmp_path, dpi=30)
    assert f"Solutions by the exact solver `{data['exact']}`" in text
