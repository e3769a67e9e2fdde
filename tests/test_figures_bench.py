"""The bench figures: median convergence curves and bands (numbers), faceting by family above 10
solvers, legends outside the panels, distinct styles per panel, and the field colormap."""
from __future__ import annotations

import math
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from dualfem.core.errors import InputError  # noqa: E402
from dualfem.post import style as S  # noqa: E402
from dualfem.reports import _bench_plots as P  # noqa: E402
from dualfem.reports._bench_curves import CURVE_COLUMNS, curves_from_table, median_curve  # noqa: E402

pd = pytest.importorskip("pandas")

TIERS = {"low": 1e-3, "mid": 1e-6, "high": 1e-9}


def _table(samples: list[tuple]) -> pd.DataFrame:
    return pd.DataFrame(samples, columns=list(CURVE_COLUMNS))


def _power_law_table(cs=(1.0, 2.0, 4.0), times=(0.01, 0.1, 1.0)) -> pd.DataFrame:
    """Three runs of one (solver, scene, tier) with error c / t at the same times."""
    rows = []
    for i, c in enumerate(cs):
        for k, t in enumerate(times):
            rows.append((f"r{i}", "uzawa", "high", "sk", k, t, c / t, "reference"))
    return _table(rows)


def test_median_and_band_on_a_known_table():
    curves = curves_from_table(_power_law_table())
    assert [c.run_id for c in curves] == ["r0", "r1", "r2"]
    m = median_curve(curves, n_grid=21)
    assert m.n_curves == 3 and np.all(m.n_defined == 3)
    assert m.time_s[0] == pytest.approx(0.01) and m.time_s[-1] == pytest.approx(1.0)
    # log-log interpolation of c / t is exact; quantiles of log10 error: 25 % of (0, log 2, log 4) = log sqrt 2
    assert np.allclose(m.median, 2.0 / m.time_s, rtol=1e-12)
    assert np.allclose(m.low, np.sqrt(2.0) / m.time_s, rtol=1e-12)
    assert np.allclose(m.high, np.sqrt(8.0) / m.time_s, rtol=1e-12)
    m = median_curve(curves, quantiles=(0.0, 1.0), n_grid=5)
    assert np.allclose(m.low, 1.0 / m.time_s) and np.allclose(m.high, 4.0 / m.time_s)


def test_median_curve_before_start_and_after_end():
    rows = [("a", "pdas", "high", "sk", k, t, e, "reference") for k, (t, e) in enumerate([(1.0, 1e-2), (10.0, 1e-6)])]
    rows += [("b", "pdas", "high", "sk", k, t, e, "reference") for k, (t, e) in enumerate([(0.1, 1e-1), (1.0, 1e-3)])]
    m = median_curve(curves_from_table(_table(rows)), n_grid=3)          # grid 0.1, 1, 10
    assert np.allclose(m.time_s, [0.1, 1.0, 10.0])
    assert list(m.n_defined) == [1, 2, 2]                                # a starts at 1 s
    assert m.median[0] == pytest.approx(1e-1)                            # only b
    assert m.median[1] == pytest.approx(math.sqrt(1e-2 * 1e-3))          # geometric median of two
    assert m.median[2] == pytest.approx(math.sqrt(1e-6 * 1e-3))          # b holds its last error
    # a run's samples are sorted by time; NaN errors and negative times dropped; zero error floored
    rows = [("c", "x", "t", "s", 2, 2.0, 0.0, "reference"), ("c", "x", "t", "s", 1, 1.0, 1e-3, "reference"),
            ("c", "x", "t", "s", 3, 3.0, float("nan"), "reference"), ("c", "x", "t", "s", 0, -1.0, 1.0, "kkt")]
    (c,) = curves_from_table(_table(rows))
    assert list(c.time_s) == [1.0, 2.0] and list(c.iteration) == [1, 2]
    assert median_curve([c], n_grid=2).median[-1] == pytest.approx(1e-16)


def test_curves_table_errors():
    with pytest.raises(InputError, match="error_kind"):
        curves_from_table(_power_law_table().drop(columns=["error_kind"]))
    with pytest.raises(InputError, match="at least one"):
        median_curve([])
    with pytest.raises(InputError, match="quantiles"):
        median_curve(curves_from_table(_power_law_table()), quantiles=(0.6, 0.9))
    assert curves_from_table(_table([])) == []


def _runs(variants, deltas=(1e-1, 1e-5), n=16) -> list[dict]:
    """Synthetic run rows: every variant, delta and tier; error and time depend on the variant."""
    rows = []
    for vi, v in enumerate(variants):
        for d in deltas:
            for ti, (tier, tol) in enumerate(TIERS.items()):
                rows.append({"run_id": f"{v}-{d:g}-{tier}", "kind": "run", "scene": "f2", "scene_key": f"f2-{d:g}",
                             "scene_N": n, "scene_delta": d, "variant": v, "solver": v, "tier": tier, "tol": tol,
                             "status": "solved" if ti < 2 else "inaccurate", "n_unknowns": 558,
                             "total_s": 0.01 * (1 + vi) * (1 + ti), "err_x_energy": tol * (1 + vi) / 10})
    return rows


def _capture(monkeypatch) -> list:
    """Figures saved by the bench plots, kept open for inspection (with a drawn canvas)."""
    figs = []

    def keep(fig, path, **kw):
        fig.canvas.draw()
        figs.append((Path(path).name, fig))
        return Path(path)

    monkeypatch.setattr(P, "atomic_savefig", keep)
    monkeypatch.setattr("matplotlib.pyplot.close", lambda *a, **k: None)
    return figs


def _point_series(ax) -> dict[str, tuple[str, str]]:
    """(colour, marker) of every point series (lines with a marker) of one panel, by colour+marker."""
    out = {}
    for ln in ax.get_lines():
        if ln.get_marker() not in (None, "None", "", " "):
            out[(matplotlib.colors.to_hex(ln.get_color()), ln.get_marker())] = True
    return out


def _no_legend_over_axes(fig) -> None:
    r = fig.canvas.get_renderer()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for leg in legends:
        lb = leg.get_window_extent(r)
        for ax in fig.axes:
            assert not lb.overlaps(ax.get_window_extent(r)), "a legend is drawn over a panel"


REGISTERED_25 = ["clarabel", "cvxpy", "dual_gradient", "mprgp", "osqp", "pdas", "penalty", "qp_clarabel",
                 "qp_cvxopt", "qp_daqp", "qp_ecos", "qp_highs", "qp_jaxopt_osqp", "qp_osqp", "qp_piqp", "qp_proxqp",
                 "qp_pyqpmad", "qp_qpalm", "qp_qpax", "qp_qtqp", "qp_quadprog", "qp_scs", "qp_sip", "uzawa",
                 "uzawa_auto"]


def test_more_than_ten_solvers_are_faceted_by_family(tmp_path, monkeypatch):
    figs = _capture(monkeypatch)
    runs = _runs(REGISTERED_25)
    wp, sc = P.plots(runs, [], tmp_path)
    assert [f.name for f in wp] == ["wp_f2_N16.png"] and sc == []
    (name, fig), = figs
    fams = S.group_by_family(REGISTERED_25)
    assert len(fams) == 4
    assert len(fig.axes) == 4 * 2           # one row per family, one column per delta
    for i, (fam, members) in enumerate(fams.items()):
        assert fig.axes[2 * i].get_ylabel().startswith(fam)
        for ax in fig.axes[2 * i: 2 * i + 2]:
            series = _point_series(ax)
            assert len(series) == len(members) <= S.MAX_SERIES       # distinct colour+marker per series
        legend = fig.axes[2 * i + 1].get_legend()
        assert [t.get_text() for t in legend.get_texts()][:len(members)] == members
    _no_legend_over_axes(fig)


def test_ten_solvers_or_fewer_share_one_row_and_legend_below(tmp_path, monkeypatch):
    figs = _capture(monkeypatch)
    few = ["uzawa", "pdas", "clarabel", "osqp", "qp_daqp", "qp_scs"]
    P.plots(_runs(few, deltas=(1e-1, 1e-5, 1e-9)), [], tmp_path)
    (_, fig), = figs
    assert len(fig.axes) == 3 and len(fig.legends) == 1
    for ax in fig.axes:
        assert len(_point_series(ax)) == len(few)
        assert ax.get_xscale() == "log" and ax.get_yscale() == "log" and ax.get_legend() is None
    _no_legend_over_axes(fig)
    # tolerance lines of the tiers with a tolerance > 0
    ys = sorted(ln.get_ydata()[0] for ln in fig.axes[0].get_lines()
                if ln.get_linestyle() == ":" and ln.get_color() == P.GUIDE)
    assert ys == pytest.approx(sorted(TIERS.values()))


def test_curves_drawn_as_their_median(tmp_path, monkeypatch):
    figs = _capture(monkeypatch)
    runs = _runs(["uzawa", "clarabel"], deltas=(1e-1,))
    rid = {r["tier"]: r["run_id"] for r in runs if r["variant"] == "uzawa"}
    samples = []
    for tier, c in (("high", 1.0), ("mid", 50.0)):       # the tightest tier's curve is the one drawn
        samples += [(rid[tier], "uzawa", tier, "f2-0.1", k, t, c * 1e-6 / t, "reference")
                    for k, t in enumerate((0.01, 0.02, 0.05))]
    samples.append(("nope", "clarabel", "high", "f2-0.1", 0, 0.1, 1e-3, "kkt"))    # another quantity: not drawn
    curves = curves_from_table(_table(samples))
    P.plots(runs, [], tmp_path, curves)
    (_, fig), = figs
    (ax,) = fig.axes
    uz = S.style("uzawa")
    drawn = [ln for ln in ax.get_lines() if ln.get_marker() in ("None", None, "")
             and matplotlib.colors.to_hex(ln.get_color()) == uz.color.lower() and len(ln.get_xdata()) > 3]
    assert len(drawn) == 1
    t, e = np.asarray(drawn[0].get_xdata()), np.asarray(drawn[0].get_ydata())
    assert t[0] == pytest.approx(0.01) and t[-1] == pytest.approx(0.05)
    assert np.allclose(e, 1e-6 / t, rtol=1e-9)
    labels = [tx.get_text() for tx in fig.legends[0].get_texts()]
    assert "uzawa (curve)" in labels and "clarabel" in labels


def test_field_figures_use_the_declared_colormap():
    from dualfem.core.scene import load_scene
    from dualfem.experiments.runner import run
    from dualfem.post import figures as F

    qp = load_scene("f2", {"N": 8, "delta": 1e-1}).build()
    ax = F.plot_deformed(qp, run(F.pick_solver(), qp))
    assert ax.collections[0].get_cmap().name == S.FIELD_CMAP
    matplotlib.pyplot.close("all")
    root = Path(F.__file__).resolve().parents[1]
    jet = [str(p.relative_to(root)) for p in root.rglob("*.py")
           if re.search(r"""["'](jet|rainbow|hsv|tab10)["']""", p.read_text(encoding="utf-8"))]
    assert not jet, f"modules still naming a non-colour-blind-safe map: {jet}"


def test_report_reads_the_curves_of_the_rows_it_keeps(tmp_path):
    from dualfem.experiments.curves import COLUMNS
    from dualfem.reports.bench import load_curves

    lines = [",".join(COLUMNS)]
    lines += [f"{rid},uzawa,high,sk,{k},{t!r},{1e-3 / t!r},reference,1"
              for rid in ("kept", "replaced", "orphan") for k, t in enumerate((0.1, 0.2))]
    (tmp_path / "curves.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    runs = [{"run_id": "kept", "_source": 0}, {"run_id": "replaced", "_source": 1}]
    sources = [{"dir": tmp_path}, {"dir": tmp_path / "other"}]
    (c,) = load_curves(runs, sources)
    assert c.run_id == "kept" and list(c.time_s) == [0.1, 0.2] and np.allclose(c.error, [1e-2, 5e-3])


def _gmsh_runs(path: str = "benchmarks/scenes/plate.toml") -> list[dict]:
    """Rows of a scene file given by mesh_size (no N column at all), at two sizes, with their floors."""
    rows = []
    for h, n in ((0.04, 1800), (0.02, 6200)):
        for r in _runs(["pdas", "osqp"]):
            r = {k: v for k, v in r.items() if k != "scene_N"}
            r.update(scene=path, scene_key=f"{r['scene_key']}-{h}", scene_mesh_size=h, n_unknowns=n,
                     run_id=f"{r['run_id']}-{h}", scene_tip_size=0.01, ref_solver="pdas")
            rows.append(r)
    return rows


def test_a_scene_without_N_gets_its_figures(tmp_path, monkeypatch):
    figs = _capture(monkeypatch)
    floors = [{"kind": "floor", "status": "solved", "n_unknowns": n, "total_s": t, "solver": "floor_splu"}
              for n, t in ((1800, 0.004), (6200, 0.02))]
    wp, sc = P.plots(_gmsh_runs(), floors, tmp_path)
    assert [f.name for f in wp] == ["wp_plate_mesh_size0.04.png", "wp_plate_mesh_size0.02.png"]
    assert [f.name for f in sc] == ["scaling_plate.png"]
    titles = {name: fig._suptitle.get_text() for name, fig in figs}
    assert titles["wp_plate_mesh_size0.02.png"] == "work-precision: plate, mesh_size = 0.02 (6,200 unknowns)"
    # the floor of the figure is the floor of its size (dashed vertical line at 0.02 s)
    fig = dict(figs)["wp_plate_mesh_size0.02.png"]
    xs = {ln.get_xdata()[0] for ln in fig.axes[0].get_lines() if ln.get_linestyle() == "--"}
    assert xs == {0.02}
    # the reference solver (pdas) is no competitor: no point of it, a dash-dotted line at its median time
    pdas_t = sorted(r["total_s"] for r in _gmsh_runs() if r["solver"] == "pdas" and r["scene_mesh_size"] == 0.02
                    and r["scene_delta"] == 0.1)
    assert {ln.get_xdata()[0] for ln in fig.axes[0].get_lines() if ln.get_linestyle() == "-."} == {pdas_t[1]}
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert "osqp" in labels and "pdas" not in labels and "reference (pdas): its own runs' time" in labels


def test_scene_identity_names_only_what_varies():
    from dualfem.reports._bench_util import group_scenes

    runs = _gmsh_runs() + _runs(["pdas"]) + [dict(r, scene="curved") for r in _runs(["pdas"])]
    labels = [s.label for s in group_scenes(runs)]
    assert labels == ["curved, N = 16", "f2, N = 16", "plate, mesh_size = 0.04", "plate, mesh_size = 0.02"]


def test_targets_on_scenes_without_N_say_they_cannot_be_checked():
    from dualfem.reports._bench_targets import targets

    lines = targets(_gmsh_runs(), [], ["pdas"], 1e-8, 1.5, 10.0)
    assert len(lines) == 1 and "No scene of these results is given by N" in lines[0] and "{}" not in lines[0]


def test_fractured_figure_tags_points_with_crack_counts(tmp_path, monkeypatch):
    """benchmarks/fractured_report.py: every point of the work-precision figure says its crack count."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("fractured_report", Path(__file__).resolve().parents[1]
                                                  / "benchmarks" / "fractured_report.py")
    fr = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fr)
    assert [fr._short(x) for x in ("50 cracks", "2000 cracks", "one crack, N = 2048", "other")] == \
        ["50", "2000", "1", "other"]
    labels = ["50 cracks", "one crack, N = 2048"]
    floors = {lab: {"floor": 1.0} for lab in labels}
    table = {(lab, "pdas"): {"result": {"time_s": {"setup": 1.0, "solve": 1.0}, "certificate": {"value": 1e-12}}}
             for lab in labels}
    saved = []
    monkeypatch.setattr("matplotlib.figure.Figure.savefig", lambda fig, path, **kw: saved.append(fig))
    fr._figure(labels, floors, table, tmp_path / "wp.png")
    texts = sorted(t.get_text() for t in saved[0].axes[0].texts)
    assert texts == ["1", "50"]
