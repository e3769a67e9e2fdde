"""One plotting style for every figure of dualfem: colour-blind-safe series, solver families, field maps.

* :data:`PALETTE`: the Okabe-Ito palette (Okabe & Ito 2008, "Color Universal Design"), eight colours
  distinguishable with the common colour-vision deficiencies, in the order series use them (the light
  yellow last: it is drawn with a darker marker edge, see :meth:`Style.kwargs`).
* :func:`family`: the solver family of a registered solver name (or of a variant of one): what its
  class declares (``Solver.family``, one of :data:`FAMILIES`: ``dual``, ``interior point``,
  ``first-order``, ``active set``, ``other``; a variant's family is ``Solver.variant_family``, which a
  solver whose parameter changes its method overrides); ``other`` for a name that is not registered or a
  declaration outside the list. No solver is named here: every family is a plugin's declaration.
* :func:`style` / :func:`styles`: a deterministic (colour, marker, line style) per solver. Each family
  owns its markers (dual: circles, interior point: squares, first-order: triangles, active set:
  diamonds, other: stars) and line style (solid, dashed, dash-dot, dotted). The registered solvers of
  a family take the palette's colours from the family's offset (:data:`FAMILY_OFFSET`) in the order
  of :func:`registered_order`: dualfem's own solvers by name, then third-party ones by name, so
  installing a plug-in never changes a built-in solver's look, and two registered solvers never share
  both colour and marker, in any figure. A name not registered (a labelled variant) gets, in
  :func:`styles`, the first (colour, marker) pair of its family's markers not taken by the other names
  of the same call: distinct within one figure, the same for the same set of names.
* :data:`FIELD_CMAP` (``"viridis"``, perceptually uniform, colour-blind safe, legible in grey) for
  fields of one sign (von Mises stress, magnitudes, log errors); :data:`DIVERGING_CMAP` (``"RdBu_r"``,
  red positive, blue negative, centred on 0 by the caller) only for signed quantities whose sign is the
  point (none of the built-in figures draws one today).
* :data:`MAX_SERIES`: above this many series a panel is split into one facet per family.

This module draws nothing and imports no plotting library: the names are plain strings a
matplotlib (or plotly) caller passes on.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from dualfem.core.solver import SOLVER_FAMILIES

#: Okabe-Ito colours (blue, vermillion, bluish green, reddish purple, black, orange, sky blue, yellow):
#: the pairs easiest to confuse (blue / sky blue, vermillion / orange) are far apart in this order;
#: the light yellow is used only by the 8th solver of a family
PALETTE: tuple[str, ...] = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#000000", "#E69F00", "#56B4E9",
                            "#F0E442")
#: colours too light on white to carry a marker alone: drawn with this marker edge colour
_LIGHT = {"#F0E442": "#8C8100", "#56B4E9": "#1F6F9E"}

#: colormap of fields of one sign (von Mises stress, magnitudes, log10 errors)
FIELD_CMAP = "viridis"
#: colormap of signed fields where the sign matters (centre it on 0: vmin = -vmax)
DIVERGING_CMAP = "RdBu_r"
#: most series one panel carries before a figure is faceted by family
MAX_SERIES = 10

#: the families, in the order facets are drawn (``Solver.family`` declares one of them)
FAMILIES: tuple[str, ...] = SOLVER_FAMILIES
#: markers of each family: the first for its first eight solvers, the next for the following eight
FAMILY_MARKERS: dict[str, tuple[str, ...]] = {
    "dual": ("o", "h"), "interior point": ("s", "P"), "first-order": ("^", "v"),
    "active set": ("D", "X"), "other": ("*", "p"),
}
#: line style of each family (curves and lines through tier points)
FAMILY_LINESTYLE: dict[str, str] = {"dual": "-", "interior point": "--", "first-order": "-.",
                                    "active set": ":", "other": "--"}
#: where each family starts in the first seven colours (so that the first solvers of different
#: families differ in colour too)
FAMILY_OFFSET: dict[str, int] = {"dual": 0, "interior point": 6, "first-order": 5, "active set": 2, "other": 3}
_SEPARATORS = "[(:_-@ ,"


@dataclass(frozen=True)
class Style:
    """How one series is drawn: ``color`` (hex), matplotlib ``marker`` and ``linestyle``."""

    color: str
    marker: str
    linestyle: str

    def kwargs(self) -> dict[str, str]:
        """matplotlib line properties (``color``, ``marker``, ``linestyle``, ``markeredgecolor``)."""
        return {"color": self.color, "marker": self.marker, "linestyle": self.linestyle,
                "markeredgecolor": _LIGHT.get(self.color, self.color)}

    def plotly(self) -> dict[str, str]:
        """The same look for plotly: ``color``, marker ``symbol``, line ``dash`` and the marker's
        ``edge`` colour (e.g. ``marker=dict(color=c, symbol=s, line=dict(color=edge))``)."""
        return {"color": self.color, "symbol": _PLOTLY_SYMBOL[self.marker], "dash": _PLOTLY_DASH[self.linestyle],
                "edge": _LIGHT.get(self.color, self.color)}


#: matplotlib marker -> plotly marker symbol, line style -> plotly dash, for every marker and style used
_PLOTLY_SYMBOL = {"o": "circle", "h": "hexagon", "s": "square", "P": "cross", "^": "triangle-up",
                  "v": "triangle-down", "D": "diamond", "X": "x", "*": "star", "p": "pentagon"}
_PLOTLY_DASH = {"-": "solid", "--": "dash", "-.": "dashdot", ":": "dot"}


def _declared(cls) -> str:
    fam = getattr(cls, "family", "other")
    return fam if isinstance(fam, str) and fam in FAMILIES else "other"


def _registered() -> dict:
    from dualfem.core.registry import solvers

    return solvers()


def registered_order() -> dict[str, list[str]]:
    """The registered solvers of each family (``Solver.family``) in the order they take the
    family's slots: dualfem's own solvers by name, then the third-party ones by name."""
    from dualfem.core.registry import builtin_names, solvers

    reg, own = solvers(), builtin_names("solver")
    out: dict[str, list[str]] = {f: [] for f in FAMILIES}
    for name in sorted(reg, key=lambda n: (n not in own, n)):
        out[_declared(reg[name])].append(name)
    return out


def _known() -> dict[str, str]:
    return {name: fam for fam, names in registered_order().items() for name in names}


def _capacity(fam: str) -> int:
    return len(PALETTE) * len(FAMILY_MARKERS[fam])


def _fixed() -> dict[str, Style]:
    """The fixed style of every registered solver: the i-th of a family takes the family's slot i; one
    beyond the family's slots (more than 16 solvers in one family) the first pair no solver before it took."""
    out: dict[str, Style] = {}
    late: list[tuple[str, str]] = []
    for fam, names in registered_order().items():
        for i, name in enumerate(names):
            if i < _capacity(fam):
                out[name] = _slot(fam, i)
            else:
                late.append((fam, name))
    taken = {(s.color, s.marker) for s in out.values()}
    for fam, name in late:
        out[name] = _free(fam, taken, len(out))
        taken.add((out[name].color, out[name].marker))
    return out


def _free(fam: str, taken: set, fallback: int) -> Style:
    """The first slot of ``fam``, then of the other families, whose (colour, marker) is not taken."""
    for f in [fam] + [f for f in FAMILIES if f != fam]:
        pick = next((s for s in map(lambda i, f=f: _slot(f, i), range(_capacity(f)))
                     if (s.color, s.marker) not in taken), None)
        if pick is not None:
            return pick
    return _slot(fam, fallback)       # every pair taken: colours repeat, markers still cycle


def base_solver(name: str) -> str | None:
    """The registered solver a series name stands for: ``name`` itself when registered, else the
    longest registered name it starts with followed by a separator (``uzawa[r=10]`` -> ``uzawa``,
    ``cvxpy:OSQP`` -> ``cvxpy``); None when there is none."""
    known = _known()
    if name in known:
        return name
    hits = [k for k in known if name.startswith(k) and name[len(k)] in _SEPARATORS]
    return max(hits, key=len) if hits else None


def family(name: str) -> str:
    """Family of a solver or variant name (one of :data:`FAMILIES`), as its solver class declares:
    ``Solver.variant_family(rest of the name)`` (a variant of cvxpy naming a first-order backend,
    ``cvxpy:OSQP``, is ``first-order``); ``other`` when not registered, when the declaration is outside
    :data:`FAMILIES` or when the plugin's ``variant_family`` fails."""
    base = base_solver(name)
    if base is None:
        return "other"
    cls = _registered()[base]
    if name == base:
        return _declared(cls)
    try:
        fam = cls.variant_family(name[len(base):])
    except Exception:                 # a third-party declaration that fails: the class's own family
        return _declared(cls)
    return fam if isinstance(fam, str) and fam in FAMILIES else "other"


def _slot(fam: str, i: int) -> Style:
    """Style of the i-th slot of a family: in each round of eight, the first seven colours from the
    family's offset, then yellow; the round picks the marker."""
    rnd, j = divmod(i, len(PALETTE))
    n = len(PALETTE) - 1
    color = PALETTE[(FAMILY_OFFSET[fam] + j) % n] if j < n else PALETTE[n]
    markers = FAMILY_MARKERS[fam]
    return Style(color, markers[rnd % len(markers)], FAMILY_LINESTYLE[fam])


def style(name: str) -> Style:
    """The fixed style of a registered solver name (the same in every figure); for any other name
    the style :func:`styles` gives it alone (its family's first slot)."""
    fixed = _fixed()
    if name in fixed:
        return fixed[name]
    return styles([name])[name]


def styles(names: Iterable[str]) -> dict[str, Style]:
    """A style per name, no two sharing both colour and marker: registered names keep their fixed
    style; the others (sorted, those of a known family first) take the first free (colour, marker)
    pair of their family's slots, then of the other families' slots. Deterministic: the same
    names give the same styles."""
    names = sorted(set(names))
    fixed = _fixed()
    out = {n: fixed[n] for n in names if n in fixed}
    taken = {(s.color, s.marker) for s in out.values()}
    for n in sorted((n for n in names if n not in fixed), key=lambda n: (family(n) == "other", n)):
        out[n] = _free(family(n), taken, len(out))
        taken.add((out[n].color, out[n].marker))
    return out


def group_by_family(names: Iterable[str]) -> dict[str, list[str]]:
    """The names (sorted) per family, families in the order of :data:`FAMILIES`, empty ones left out."""
    out: dict[str, list[str]] = {}
    names = set(names)
    for fam in FAMILIES:
        members = sorted(n for n in names if family(n) == fam)
        if members:
            out[fam] = members
    return out
