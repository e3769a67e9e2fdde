"""dualfem.post.style: deterministic, distinct, colour-blind-safe series styles and solver families."""
from __future__ import annotations

from pathlib import Path

import pytest

from dualfem.core.registry import _SOLVERS as REGISTRY
from dualfem.core.registry import builtin_names, register_solver, solvers
from dualfem.post import style as S
from dualfem.solver import Solver


def test_every_builtin_solver_declares_a_family():
    reg = solvers()
    own = builtin_names("solver")
    assert own
    bad = [n for n in own if reg[n].family not in S.FAMILIES or reg[n].family == "other"]
    assert not bad, f"built-in solvers without a declared Solver.family: {bad}"
    assert all(S.family(n) == reg[n].family for n in own)
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
    first = S.registered_order()["dual"][0]
    assert S.style(first).plotly() == {"color": "#0072B2", "symbol": "circle", "dash": "solid", "edge": "#0072B2"}


@pytest.fixture
def third_party():
    """Two third-party solvers registered as a plug-in would be (one declaring its family, one not),
    removed afterwards."""
    solvers()          # the built-ins first, as the registry loads them

    class Fista(Solver):
        name, family, description = "zz_fista_plugin", "dual", "third-party test solver"

    class Anon(Solver):
        name, description = "aa_anon_plugin", "third-party test solver without a family"

    before = S.styles(sorted(solvers()))
    for cls in (Fista, Anon):
        register_solver(cls)
    yield before
    for cls in (Fista, Anon):
        REGISTRY.pop(cls.name, None)


def test_a_plugin_declares_its_family_and_changes_no_builtin_style(third_party):
    assert S.family("zz_fista_plugin") == "dual" and S.family("aa_anon_plugin") == "other"
    assert S.family("zz_fista_plugin[tol=1e-3]") == "dual"
    names = sorted(solvers())
    a = S.styles(names)
    own = builtin_names("solver")
    assert own <= set(third_party) and all(a[n] == third_party[n] for n in own)    # built-ins keep their look
    pairs = [(s.color, s.marker) for s in a.values()]
    assert len(set(pairs)) == len(pairs)
    assert a["zz_fista_plugin"].marker in S.FAMILY_MARKERS["dual"]
    assert a["aa_anon_plugin"].marker in S.FAMILY_MARKERS["other"]
    assert S.style("zz_fista_plugin") == a["zz_fista_plugin"] == S.styles(["zz_fista_plugin", "q"])["zz_fista_plugin"]


def test_a_family_beyond_its_slots_stays_distinct():
    solvers()
    extra = []
    for i in range(20):         # 15 built-in interior point solvers + 20: beyond the family's 16 slots
        extra.append(register_solver(type(f"IP{i}", (Solver,), {"name": f"zz_ip_{i:02d}", "family": "interior point",
                                                               "__module__": __name__})))
    try:
        a = S.styles(sorted(solvers()))
        pairs = [(s.color, s.marker) for s in a.values()]
        assert len(set(pairs)) == len(pairs)
    finally:
        for cls in extra:
            REGISTRY.pop(cls.name, None)


def test_a_variant_family_is_the_plugins_declaration():
    """post/ knows no solver: a plugin whose parameter changes its method declares its variants' family
    (``Solver.variant_family``), as cvxpy does for its first-order backends; a failing or out-of-list
    declaration falls back to the class's family or ``other``."""
    solvers()

    class Modes(Solver):
        name, family, description = "zz_modes_plugin", "interior point", "third-party test solver"

        @classmethod
        def variant_family(cls, variant):
            return "first-order" if "admm" in variant else ("bogus" if "bad" in variant else cls.family)

    class Broken(Solver):
        name, family, description = "zz_broken_plugin", "dual", "third-party test solver"

        @classmethod
        def variant_family(cls, variant):
            raise RuntimeError("broken declaration")

    for cls in (Modes, Broken):
        register_solver(cls)
    try:
        assert S.family("zz_modes_plugin[mode=admm]") == "first-order"
        assert S.family("zz_modes_plugin[mode=ipm]") == S.family("zz_modes_plugin") == "interior point"
        assert S.family("zz_modes_plugin:bad") == "other"
        assert S.family("zz_broken_plugin[x=1]") == "dual"
    finally:
        for cls in (Modes, Broken):
            REGISTRY.pop(cls.name, None)
    cvxpy = solvers()["cvxpy"]
    assert cvxpy.variant_family("[solver=scs]") == "first-order" == S.family("cvxpy[solver=SCS]")
    src = Path(S.__file__).read_text()
    assert "SCS" not in src and "PIQP" not in src          # no backend knowledge left in post/


def test_post_names_no_plugin():
    """No plugin knowledge in post/: no registered solver or problem name appears there as a string
    literal (every family, colour and marker comes from the plugins' declarations)."""
    import ast

    names = set(solvers())
    from dualfem.core.registry import problems

    names |= set(problems())
    root = Path(S.__file__).parent
    bad = [f"{f.name}:{n.lineno}: {n.value!r}" for f in sorted(root.rglob("*.py"))
           for n in ast.walk(ast.parse(f.read_text())) if isinstance(n, ast.Constant) and n.value in names]
    assert not bad, "\n".join(bad)
