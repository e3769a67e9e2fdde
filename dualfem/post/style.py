"""One plotting style for every figure of dualfem: colour-blind-safe series, solver families, field maps.

* :data:`PALETTE`: the Okabe-Ito palette (Okabe & Ito 2008, "Color Universal Design"), eight colours
  distinguishable with the common colour-vision deficiencies, in the order series use them (the light
  yellow last: it is drawn with a darker marker edge, see :meth:`Style.kwargs`).
* :func:`family`: the solver family of a registered solver name (or of a variant of one): ``dual``
  (dualfem's own solvers on the dual), ``interior point`` (interior point / conic), ``first-order``
  (ADMM, proximal and augmented-Lagrangian methods), ``active set``, and ``other`` for a name it does not
  know (a plug-in).
* :func:`style` / :func:`styles`: a deterministic (colour, marker, line style) per solver. Each family
  owns its markers (dual: circles, interior point: squares, first-order: triangles, active set:
  diamonds, other: stars) and line style (solid, dashed, dash-dot, dotted), and the solvers of a family
  take the palette's colours in their order of :data:`FAMILIES` from the family's offset
  (:data:`FAMILY_OFFSET`): two known solvers never share both colour and marker, in any figure. A name not
  listed (a plug-in, a labelled variant) gets, in :func:`styles`, the first (colour, marker) pair of its
  family's markers not taken by the other names of the same call: distinct within one figure, the same
  for the same set of names.
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

#: the families, in the order facets are drawn, with the registered solvers each holds (in the
#: order they take the palette's colours). Names are those of ``dualfem list``.
FAMILIES: dict[str, tuple[str, ...]] = {
    "dual": ("uzawa", "uzawa_auto", "pdas", "mprgp", "penalty", "dual_gradient", "newton_amg"),
    "interior point": ("clarabel", "qp_clarabel", "cvxpy", "qp_piqp", "qp_ecos", "qp_cvxopt", "qp_sip",
                       "qp_qtqp", "qp_qpax", "qp_kvxopt", "qp_hpipm", "qp_qpswift", "qp_mosek", "qp_gurobi",
                       "qp_copt"),
    "first-order": ("osqp", "qp_osqp", "qp_scs", "qp_proxqp", "qp_qpalm", "qp_jaxopt_osqp", "qp_pdhcg"),
    "active set": ("qp_daqp", "qp_quadprog", "qp_pyqpmad", "qp_highs", "qp_qpoases", "qp_nppro"),
    "other": (),
}
#: markers of each family: the first for its first eight solvers, the next for the following eight
FAMILY_MARKERS: dict[str, tuple[str, ...]] = {
    "dual": ("o", "h"), "interior point": ("s", "P"), "first-order": ("^", "v"),
    "active set": ("D", "X"), "other": ("*", "p"),
}
#: line style of each family (curves and lines through tier points)
FAMILY_LINESTYLE: dict[str, str] = {"dual": "-", "interior point": "--", "first-order": "-.",
                                    "active set": ":", "other": "--"}
#: where each family starts in the first seven colours, chosen so that the solvers most often drawn
#: together differ in colour too: dual uzawa blue, uzawa_auto vermillion, pdas green, mprgp purple,
#: penalty black, dual_gradient orange; clarabel sky blue; osqp orange; qp_daqp green
FAMILY_OFFSET: dict[str, int] = {"dual": 0, "interior point": 6, "first-order": 5, "active set": 2, "other": 3}
#: cvxpy backends that are first-order methods (a cvxpy variant naming one is of that family)
_CVXPY_FIRST_ORDER = ("OSQP", "SCS", "PIQP_ADMM")
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


def _known() -> dict[str, tuple[str, int]]:
    return {name: (fam, i) for fam, names in FAMILIES.items() for i, name in enumerate(names)}


def base_solver(name: str) -> str | None:
    """The registered solver a series name stands for: ``name`` itself when listed in
    :data:`FAMILIES`, else the longest listed name it starts with followed by a separator
    (``uzawa[r=10]`` -> ``uzawa``, ``cvxpy:OSQP`` -> ``cvxpy``); None when there is none."""
    known = _known()
    if name in known:
        return name
    hits = [k for k in known if name.startswith(k) and name[len(k)] in _SEPARATORS]
    return max(hits, key=len) if hits else None


def family(name: str) -> str:
    """Family of a solver or variant name (a key of :data:`FAMILIES`; ``other`` when unknown).
    A cvxpy variant naming a first-order backend (OSQP, SCS) is ``first-order``."""
    base = base_solver(name)
    if base is None:
        return "other"
    if base == "cvxpy" and any(b in name[len(base):].upper() for b in _CVXPY_FIRST_ORDER):
        return "first-order"
    return _known()[base][0]


def _slot(fam: str, i: int) -> Style:
    """Style of the i-th slot of a family: in each round of eight, the first seven colours from the
    family's offset, then yellow; the round picks the marker."""
    rnd, j = divmod(i, len(PALETTE))
    n = len(PALETTE) - 1
    color = PALETTE[(FAMILY_OFFSET[fam] + j) % n] if j < n else PALETTE[n]
    markers = FAMILY_MARKERS[fam]
    return Style(color, markers[rnd % len(markers)], FAMILY_LINESTYLE[fam])


def style(name: str) -> Style:
    """The fixed style of a name listed in :data:`FAMILIES` (the same in every figure); for any
    other name the style :func:`styles` gives it alone (its family's first slot)."""
    known = _known()
    if name in known:
        return _slot(*known[name])
    return styles([name])[name]


def styles(names: Iterable[str]) -> dict[str, Style]:
    """A style per name, no two sharing both colour and marker: listed names keep their fixed
    style; the others (sorted, those of a known family first) take the first free (colour, marker)
    pair of their family's slots, then of the other families' slots. Deterministic: the same
    names give the same styles."""
    names = sorted(set(names))
    known = _known()
    out = {n: _slot(*known[n]) for n in names if n in known}
    taken = {(s.color, s.marker) for s in out.values()}
    order = list(FAMILY_MARKERS)
    for n in sorted((n for n in names if n not in known), key=lambda n: (family(n) == "other", n)):
        fam = family(n)
        for f in [fam] + [f for f in order if f != fam]:
            slots = len(PALETTE) * len(FAMILY_MARKERS[f])
            pick = next((s for s in map(lambda i, f=f: _slot(f, i), range(slots))
                         if (s.color, s.marker) not in taken), None)
            if pick is not None:
                break
        else:     # more than 80 unknown names in one figure: colours repeat, markers still cycle
            pick = _slot(fam, len(out))
        out[n] = pick
        taken.add((pick.color, pick.marker))
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
