"""dualfem.post.style: deterministic, distinct, colour-blind-safe series styles and solver families."""
from __future__ import annotations

from dualfem.core.registry import solvers
from dualfem.post import style as S


def test_every_registered_solver_has_a_family():
    names = list(solvers())
    assert names
    unknown = [n for n in names if S.family(n) == "other"]
    assert not unknown, f"registered solvers without a family in dualfem.post.style.FAMILIES: {unknown}"
    assert S.family("uzawa") == "dual" and S.family("qp_scs") == "first-order"
    assert S.family("clarabel") == "interior point" and S.family("qp_daqp") == "active set"
    assert S.family("cvxpy:OSQP") == "first-order" and S.family("cvxpy") == "interior point"
    assert S.family("uzawa[r=10]") == "dual" and S.family("my_plugin") == "other"
    assert S.family("uzawax") == "other"     # a prefix without a separator is another name


def test_registered_styles_distinct_and_deterministic():
    names = sorted(solvers())
    a, b = S.styles(names), S.styles(list(reversed(names)))
    assert a == b
    pairs = [(s.color, s.marker) for s in a.values()]
    assert len(set(pairs)) == len(pairs)
    # the fixed style of a registered name does not depend on the other names of the figure
    assert all(S.style(n) == a[n] == S.styles([n, "zzz_plugin"])[n] for n in names)
    # the three solvers the old tab10 figure drew in one blue
    assert len({(a[n].color, a[n].marker) for n in ("clarabel", "qp_daqp", "qp_scs")}) == 3
    assert all(s.color in S.PALETTE for s in a.values())


def test_unknown_names_take_free_slots():
    names = ["uzawa", "uzawa[r=10]", "uzawa[r=1]", "plugin_a", "plugin_b"] + [f"p{i}" for i in range(30)]
    st = S.styles(names)
    pairs = [(s.color, s.marker) for s in st.values()]
    assert len(set(pairs)) == len(pairs) == len(names)
    assert st["uzawa"] == S.style("uzawa")
    assert st["uzawa[r=10]"].marker in S.FAMILY_MARKERS["dual"]
    assert st == S.styles(reversed(names))


def test_palette_is_okabe_ito_and_field_maps():
    assert set(S.PALETTE) == {"#000000", "#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00",
                              "#CC79A7"}
    assert S.FIELD_CMAP in ("viridis", "cividis")
    import matplotlib

    matplotlib.colormaps[S.FIELD_CMAP]
    matplotlib.colormaps[S.DIVERGING_CMAP]


def test_group_by_family_order():
    g = S.group_by_family(["qp_daqp", "pdas", "osqp", "clarabel", "x_plugin", "uzawa"])
    assert list(g) == ["dual", "interior point", "first-order", "active set", "other"]
    assert g["dual"] == ["pdas", "uzawa"]


def test_plotly_equivalents_cover_every_style():
    markers = {m for ms in S.FAMILY_MARKERS.values() for m in ms}
    for m in markers:
        for ls in set(S.FAMILY_LINESTYLE.values()):
            p = S.Style("#0072B2", m, ls).plotly()
            assert p["symbol"] and p["dash"] in ("solid", "dash", "dashdot", "dot")
    assert S.style("uzawa").plotly() == {"color": "#0072B2", "symbol": "circle", "dash": "solid", "edge": "#0072B2"}
