"""The convergence report: render the mesh-convergence study (reports/convergence.md).

Render only: :func:`render` writes ``convergence.md`` plus two figures from the study's numbers
(:func:`dualfem.experiments.convergence.study`, what is measured and how is documented there, or
the ``convergence.json`` it was stored in). ``dualfem report convergence``
(:mod:`dualfem.cli.reports.convergence`) runs the study and stores its numbers, or with
``--from-json FILE`` reads stored ones (the committed report is regenerated that way), then
calls :func:`render`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_savefig, atomic_write_text
from dualfem.experiments.convergence import fit_rate, triple_rates

# ----------------------------------------------------------------------------- stored numbers
_NUM = (int, float)
#: what :func:`render` reads from a stored study: key -> type (a tuple: one of), ``"num?"`` a number or null
_LEVEL = {k: "num?" for k in ("h", "energy", "contact_length", "total_force", "energy_norm", "K_norm", "L2",
                              "rate_energy_norm", "rate_K_norm", "rate_L2", "diff_energy", "rate_diff_energy",
                              "diff_contact_length", "rate_diff_contact_length", "diff_total_force",
                              "rate_diff_total_force")} | {"N": int, "ndof": int}
_REFERENCE = {"energy": _NUM, "contact_length": _NUM, "total_force": _NUM, "n_contact": int, "max_jump": _NUM,
              "ndof": int, "time_build_s": _NUM, "time_s": dict, "residuals": dict}
_STUDY = {"scene": str, "solver": str, "ref_N": int, "Ns": list, "deltas": dict, "time_s": _NUM}


def _require(d, schema: dict, where: str, src: str) -> None:
    if not isinstance(d, dict):
        raise InputError(f"{src}: {where or 'the file'} must be a JSON object, got {type(d).__name__}")
    for k, t in schema.items():
        v = d.get(k)
        ok = (v is None or (isinstance(v, _NUM) and not isinstance(v, bool))) if t == "num?" else \
            isinstance(v, t) and not isinstance(v, bool)
        if not ok:
            names = "/".join(x.__name__ for x in (t if isinstance(t, tuple) else (t,))) if t != "num?" else ""
            want = names or "a number or null"
            raise InputError(f"{src} is not a convergence.json written by 'dualfem report convergence': "
                             f"{where}{k!r} must be {want}, got {'nothing' if k not in d else type(v).__name__}")


def check_study(res, src: str, nested: str = "") -> None:
    """Refuse (InputError naming ``src`` and the key) a stored study that :func:`render` cannot draw: every
    key it reads present with its type, at least one delta, every delta with at least one level; the same
    for each entry of ``supplements``."""
    _require(res, _STUDY, nested, src)
    if not res["deltas"] or not all(isinstance(n, int) and n > 0 for n in res["Ns"]):
        raise InputError(f"{src}: {nested}'deltas' must name at least one delta and 'Ns' hold positive integers")
    if not isinstance(res["ref_N"], int) or res["ref_N"] <= 0:
        raise InputError(f"{src}: {nested}'ref_N' must be a positive integer, got {res['ref_N']!r}")
    for dl, d in res["deltas"].items():
        at = f"{nested}deltas[{dl!r}]"
        _require(d, {"reference": dict, "levels": list}, at + ".", src)
        _require(d["reference"], _REFERENCE, at + ".reference.", src)
        if not d["levels"]:
            raise InputError(f"{src}: {at}.levels is empty")
        for i, lv in enumerate(d["levels"]):
            _require(lv, _LEVEL, f"{at}.levels[{i}].", src)
    sups = res.get("supplements", [])
    if not isinstance(sups, list):
        raise InputError(f"{src}: {nested}'supplements' must be a list")
    for i, sup in enumerate(sups):
        check_study(sup, src, f"{nested}supplements[{i}].")


# ----------------------------------------------------------------------------- output
def _fmt(v, spec=".3e") -> str:
    return "–" if v is None else format(v, spec)


def _h_ticks(ax, res: dict) -> None:
    """x ticks at the mesh sizes, labelled 1/N."""
    from matplotlib.ticker import NullLocator

    ax.set_xticks([1.0 / n for n in res["Ns"]], [f"1/{n}" for n in res["Ns"]])
    ax.xaxis.set_minor_locator(NullLocator())



def _plot_errors(res: dict, outdir: Path) -> str:
    """convergence_errors.png: energy-norm and L2 errors against h, with reference slopes."""
    import matplotlib.pyplot as plt


    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, title in ((axes[0], "energy_norm", "energy-norm error sqrt(e'K_el e) (relative)"),
                           (axes[1], "L2", "L2 error (relative)")):
        for dl, d in res["deltas"].items():
            h = [lv["h"] for lv in d["levels"]]
            ax.loglog(h, [lv[key] for lv in d["levels"]], "o-", label=f"delta = {dl}")
        h = np.array([lv["h"] for lv in next(iter(res["deltas"].values()))["levels"]])
        first = max(d["levels"][0][key] for d in res["deltas"].values())
        ax.loglog(h, first * (h / h[0]) ** 0.5, "k--", lw=1, label="h^1/2 (Theorem 1)")
        ax.loglog(h, first * (h / h[0]) ** 1.0, "k:", lw=1, label="h^1")
        if key == "L2":
            ax.loglog(h, first * (h / h[0]) ** 2.0, "k-.", lw=1, label="h^2")
        ax.set_xlabel("h = 1/N")
        _h_ticks(ax, res)
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{res['scene']}: error against the N = {res['ref_N']} reference", fontsize=11)
    fig.tight_layout()
    atomic_savefig(fig, outdir / "convergence_errors.png", dpi=100)
    plt.close(fig)
    return "convergence_errors.png"


def _plot_quantities(res: dict, outdir: Path) -> str:
    """convergence_quantities.png: energy, contact-zone length and total force against h."""
    import matplotlib.pyplot as plt


    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (dl, d) in enumerate(res["deltas"].items()):
        h = [lv["h"] for lv in d["levels"]]
        ref = d["reference"]
        c = colors[i % len(colors)]
        for ax, key, scale in ((axes[0], "energy", abs(ref["energy"]) or 1.0),
                               (axes[2], "total_force", abs(ref["total_force"]) or 1.0)):
            vals = [lv[f"diff_{key}"] / scale for lv in d["levels"]]
            pos = [(a, v) for a, v in zip(h, vals) if v > 0]
            if pos:
                ax.loglog(*zip(*pos), "o-", color=c, label=f"delta = {dl}")
        axes[1].semilogx(h, [lv["contact_length"] for lv in d["levels"]], "o-", color=c, label=f"delta = {dl}")
        axes[1].axhline(ref["contact_length"], color=c, ls="--", lw=0.8)
    for ax, title in ((axes[0], "|Pi_N - Pi_ref| / |Pi_ref|"),
                      (axes[1], f"contact-zone length (dashed: N = {res['ref_N']})"),
                      (axes[2], "|total force_N - ref| / |ref|")):
        ax.set_xlabel("h = 1/N")
        _h_ticks(ax, res)
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_savefig(fig, outdir / "convergence_quantities.png", dpi=100)
    plt.close(fig)
    return "convergence_quantities.png"


def plot(res: dict, outdir: Path) -> list[str]:
    """convergence_errors.png and convergence_quantities.png; returns the file names."""
    import matplotlib

    matplotlib.use("Agg")
    return [_plot_errors(res, outdir), _plot_quantities(res, outdir)]


def _setup(res: dict) -> list[str]:
    L = ["## Setup\n"]
    ref_N = res["ref_N"]
    prm = res.get("params", {})
    desc = ", ".join(f"{k} = {prm[k]}" for k in ("E", "nu", "plane", "load", "load_scale", "defect", "width", "height")
                     if k in prm)
    L.append(f"- Scene `{res['scene']}` ({desc or 'parameters not recorded'}; clamped bottom, traction on the top), "
             "at delta in {" + ", ".join(res["deltas"]) + "}, on meshes N = "
             + ", ".join(str(n) for n in res["Ns"]) + " (h = 1/N: leg of the right triangles).")
    refs = [d["reference"] for d in res["deltas"].values()]
    if res.get("note"):
        L.append(f"- **Note on the reference mesh**: {res['note']}")
    L.append(f"- **Reference**: the same scene on the finest mesh N = {ref_N} ({refs[0]['ndof']} unknowns), "
             f"solved with the exact solver `{res['solver']}` (evaluator KKT residuals at most "
             f"{max(max(r['residuals'].values()) for r in refs):.1e}). It is a discrete solution, not the exact "
             f"one: errors at the finest coarse levels are underestimated (the reference's own error is not "
             f"included), so the last rate is the least reliable.")
    L.append("- **Comparison**: the meshes are nested (N divides the reference N, same diagonal direction), so "
             "every fine triangle lies inside one coarse triangle. A coarse P1 solution is interpolated onto the "
             "fine nodes triangle by triangle: the coarse triangle is found from the fine triangle's centroid, "
             "hence on the same side of the defect, and its P1 field is evaluated at the fine triangle's "
             "vertices; a fine node on the defect thus gets the coarse value of its own face (upper or lower "
             "copy). With e = x_ref - I x_N on the fine mesh:")
    L.append("  - energy-norm error ||e||_E = sqrt(e' K_el e) with K_el the elastic stiffness (no interface term): "
             "the H^1-type norm of Theorem 1 on the cut domain; `K-norm` adds the interface term (1/delta) "
             "int |[e]|^2;")
    L.append("  - L2 error from the exact P1 mass matrix of the fine mesh;")
    L.append("  - each divided by the same norm of the reference solution; rate = log2(e_N / e_2N).")
    L.append("- Contact zone: the defect nodes whose normal jump is <= 1e-6 |x|_inf (the evaluator's rule); its "
             "length is the total length of the defect edges with both ends closed (the P1 jump vanishes "
             "exactly there). Total contact force: sum of the nodal multipliers (force per unit thickness, "
             "MPa x length).\n")
    return L


def _quantity_tables(res: dict, pngs: list[str]) -> list[str]:
    L = ["## Energy, contact zone and total contact force\n"]
    L += [f"![quantities](figures/{p})\n" for p in pngs[1:2]]
    for dl, d in res["deltas"].items():
        ref = d["reference"]
        L.append(f"### delta = {dl}\n")
        L.append(f"Reference (N = {res['ref_N']}): energy {ref['energy']:.10e}, contact-zone length "
                 f"{ref['contact_length']:.6f} ({ref['n_contact']} closed nodes), total contact force "
                 f"{ref['total_force']:.6e}, max jump {ref['max_jump']:.4e}.\n")
        L.append("| N | energy Pi_N | Pi_N - Pi_ref | rate | ratio to 1/2 e'Ke | contact length | diff. | total force "
                 "| rel. diff. | rate |")
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for lv in d["levels"]:
            rel_f = lv["diff_total_force"] / abs(ref["total_force"]) if ref["total_force"] else None
            L.append(f"| {lv['N']} | {lv['energy']:.8e} | {lv['energy'] - ref['energy']:.3e} | "
                     f"{_fmt(lv['rate_diff_energy'], '.2f')} | {_fmt(_energy_ratio(lv, ref), '.3f')} | "
                     f"{lv['contact_length']:.5f} | "
                     f"{lv['diff_contact_length']:.5f} | {lv['total_force']:.5e} | {_fmt(rel_f)} | "
                     f"{_fmt(lv['rate_diff_total_force'], '.2f')} |")
        L.append("")
    return L


def _timing(res: dict) -> list[str]:
    L = ["## Timing of the reference solves\n", "| delta | unknowns | build (s) | solver setup (s) | solve (s) |",
         "|---|---|---|---|---|"]
    for dl, d in res["deltas"].items():
        r = d["reference"]
        L.append(f"| {dl} | {r['ndof']} | {r['time_build_s']:.1f} | {r['time_s']['setup']:.1f} | "
                 f"{r['time_s']['solve']:.2f} |")
    return L + [""]


def markdown(res: dict, pngs: list[str], cmdline: str) -> str:
    """The text of reports/convergence.md."""
    L = [f"# Mesh convergence of the thin-defect scene {res['scene']}\n",
         f"Generated by `{cmdline}` (solver `{res['solver']}`, wall time {res['time_s'] / 60:.1f} min). "
         f"Raw numbers: `convergence.json`.\n"]
    L += _setup(res)
    L.append("## Errors against the reference\n")
    L += [f"![errors](figures/{p})\n" for p in pngs[:1]]
    for dl, d in res["deltas"].items():
        L.append(f"### delta = {dl}\n")
        L.extend(_error_table(d))
    L += _quantity_tables(res, pngs) + _timing(res)
    L.append(_discussion(res))
    for sup in res.get("supplements", []):
        L.append("")
        L.append(_supplement(sup))
    return "\n".join(L) + "\n"


def _error_table(d: dict) -> list[str]:
    L = ["| N | unknowns | energy-norm error | rate | K-norm error | rate | L2 error | rate |",
         "|---|---|---|---|---|---|---|---|"]
    for lv in d["levels"]:
        L.append(f"| {lv['N']} | {lv['ndof']} | {_fmt(lv['energy_norm'])} | {_fmt(lv['rate_energy_norm'], '.2f')} | "
                 f"{_fmt(lv['K_norm'])} | {_fmt(lv['rate_K_norm'], '.2f')} | {_fmt(lv['L2'])} | "
                 f"{_fmt(lv['rate_L2'], '.2f')} |")
    L.append("")
    return L


def _supplement(sup: dict) -> str:
    """A second study (e.g. a finer reference for one delta), appended to the report."""
    L = [f"## Supplement: reference N = {sup['ref_N']} for delta = {', '.join(sup['deltas'])}\n"]
    L.append(f"Generated by `{sup.get('command', 'dualfem report convergence')}` (solver `{sup['solver']}`, wall time "
             f"{sup['time_s'] / 60:.1f} min); the same comparison as above, against this reference.\n")
    for dl, d in sup["deltas"].items():
        ref = d["reference"]
        L.append(f"### delta = {dl}\n")
        L.append(f"Reference: {ref['ndof']} unknowns, build {ref['time_build_s']:.0f} s, solver setup "
                 f"{ref['time_s']['setup']:.0f} s, solve {ref['time_s']['solve']:.1f} s; evaluator KKT residuals at "
                 f"most {max(ref['residuals'].values()):.1e}; energy {ref['energy']:.10e}, contact-zone length "
                 f"{ref['contact_length']:.6f}, total contact force {ref['total_force']:.6e}.\n")
        L.extend(_error_table(d))
        f = _fits(sup, d)
        L.append("Fitted orders (reference-corrected, see above): "
                 + ", ".join(f"{name} {_fmt(None if f[k] is None else f[k][0], '.2f')}"
                             for k, name in (("energy_norm", "energy norm"), ("K_norm", "K-norm"), ("L2", "L2")))
                 + ".\n")
    return "\n".join(L)


def _energy_ratio(lv: dict, ref: dict) -> float | None:
    """(Pi_N - Pi_ref) / (1/2 |e|_K^2): 1 for nested spaces without contact (Galerkin orthogonality).

    At a KKT point x'Kx = F'x + mu'Bx = F'x, so |x_ref|_K^2 = -2 Pi_ref and
    |e|_K^2 = K_norm^2 (-2 Pi_ref) from the stored relative K-norm error.
    """
    e2 = lv["K_norm"] ** 2 * (-2.0 * ref["energy"])
    return (lv["energy"] - ref["energy"]) / (0.5 * e2) if e2 > 0 else None


def _fits(res: dict, d: dict) -> dict:
    return {k: fit_rate([lv["h"] for lv in d["levels"]], [lv[k] for lv in d["levels"]], 1.0 / res["ref_N"])
            for k in ("energy_norm", "K_norm", "L2")}



def _mean_rate(levels: list[dict], key: str) -> float | None:
    """Mean observed rate over the halvings, the last one left out."""
    vals = [lv[key] for lv in levels[:-1] if lv[key] is not None]
    return sum(vals) / len(vals) if vals else None


def _rate_summary(res: dict) -> tuple[list[str], dict[str, float]]:
    """The raw / fitted order table; returns its lines and the fitted energy-norm order per delta."""
    Ns, ref_N = res["Ns"], res["ref_N"]
    L = ["## Observed rates and Theorem 1\n", "Two estimates of the convergence order p per quantity:\n",
         f"- *raw*: the mean of the observed rates log2(e_N / e_2N) over the halvings N = {Ns[0]} -> {Ns[-2]} "
         f"(the last halving, {Ns[-2]} -> {Ns[-1]}, is left out: its error is measured against a reference only "
         f"{ref_N // Ns[-1]} times finer and is underestimated the most, which inflates that rate);",
         "- *fitted*: the model |u_ref - u_N| = C sqrt(h_N^(2p) - h_ref^(2p)) fitted to all levels (least "
         "squares on the logarithms). If the true error is C h^p, Galerkin orthogonality in the energy inner "
         "product (nested spaces; exact without contact, approximate with it) gives exactly this form, so the "
         "fit corrects for the reference's own error. For the L2 error the form is only a model.\n",
         "| delta | energy norm: raw | fitted | K-norm: raw | fitted | L2: raw | fitted | energy difference: raw |",
         "|---|---|---|---|---|---|---|---|"]
    fitted = {}
    for dl, d in res["deltas"].items():
        lv = d["levels"]
        fp = {k: (None if v is None else v[0]) for k, v in _fits(res, d).items()}
        if fp["energy_norm"] is not None:
            fitted[dl] = fp["energy_norm"]
        L.append(f"| {dl} | {_fmt(_mean_rate(lv, 'rate_energy_norm'), '.2f')} | {_fmt(fp['energy_norm'], '.2f')} | "
                 f"{_fmt(_mean_rate(lv, 'rate_K_norm'), '.2f')} | {_fmt(fp['K_norm'], '.2f')} | "
                 f"{_fmt(_mean_rate(lv, 'rate_L2'), '.2f')} | {_fmt(fp['L2'], '.2f')} | "
                 f"{_fmt(_mean_rate(lv, 'rate_diff_energy'), '.2f')} |")
    return L + [""], fitted


def _triples(res: dict) -> tuple[list[str], dict[str, list[float | None]]]:
    """Triple-wise orders of the energy-norm and K-norm errors (:func:`triple_rates`) per delta."""
    Ns, ref_N = res["Ns"], res["ref_N"]
    with_ref = ref_N == 2 * Ns[-1]
    levels = [*Ns, ref_N] if with_ref else list(Ns)
    names = [f"{a}-{b}-{c}" for a, b, c in zip(levels, levels[1:], levels[2:])]
    L = ["### How the order changes with h: triple-wise orders\n",
         "A single order per delta hides a drift. For each three successive meshes N, 2N, 4N, the "
         "triple-wise order p = 1/2 log2((e_N^2 - e_2N^2) / (e_2N^2 - e_4N^2)) is the order of the true error "
         "(|u - u_N| ~ C h^p) on those meshes: by Galerkin orthogonality (as for the fitted order above) the "
         "differences of squared errors against the reference do not depend on the reference's own error."
         + (f" The last triple ends at the reference (N = {ref_N}, error 0 against itself)." if with_ref else "")
         + "\n", "| delta | norm | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    energy = {}
    for dl, d in res["deltas"].items():
        for key, label in (("energy_norm", "energy"), ("K_norm", "K")):
            p = triple_rates([lv[key] for lv in d["levels"]], with_reference=with_ref)
            if key == "energy_norm":
                energy[dl] = p
            L.append(f"| {dl} | {label} | " + " | ".join(_fmt(v, ".2f") for v in p) + " |")
    return L + [""], energy


def _drift(dl: str, p: list[float | None]) -> str:
    """One clause on the triple-wise energy-norm orders of one delta."""
    vals = [v for v in p if v is not None]
    if len(vals) < 2:
        return f"too few levels at delta = {dl}"
    first, last = vals[0], vals[-1]
    if abs(last - first) <= 0.03:
        return f"flat at {min(vals):.2f}-{max(vals):.2f} at delta = {dl}"
    trend = "falls" if last < first else "rises"
    mono = all(b < a for a, b in zip(vals, vals[1:])) or all(b > a for a, b in zip(vals, vals[1:]))
    return f"{trend} {'steadily ' if mono else ''}from {first:.2f} to {last:.2f} at delta = {dl}"


def _what(res: dict, fitted: dict[str, float], triples: dict[str, list[float | None]]) -> list[str]:
    facts = []
    if fitted:
        facts.append("Energy-norm order (fitted): " + ", ".join(f"{p:.2f} at delta = {dl}" for dl, p in fitted.items()))
        if min(fitted.values()) >= 0.45:
            facts.append("every one at least the h^(1/2) of Theorem 1")
        else:
            facts.append("below the h^(1/2) of Theorem 1 for delta = "
                         + ", ".join(dl for dl, p in fitted.items() if p < 0.45))
        order = [fitted[dl] for dl in sorted(fitted, key=float, reverse=True)]
        if all(a < b for a, b in zip(order[:-1], order[1:])):
            facts.append("and the order grows as delta decreases")
    falling = [dl for dl, p in triples.items() if "falls" in _drift(dl, p)]
    text = ("**What the numbers show.** " + "; ".join(facts) + ". The triple-wise energy-norm order "
            + "; ".join(_drift(dl, p) for dl, p in triples.items()) + ". ")
    if falling:
        text += ("So the fitted orders are averages over a drift: where the order falls (delta = "
                 + ", ".join(falling) + ") it moves toward the h^(1/2) of Theorem 1 as h decreases, and on these "
                 "meshes it has not reached it; a single order above 1/2 is therefore no evidence of a better "
                 "asymptotic rate.")
    else:
        text += "No delta shows a falling order on these meshes."
    return [text + "\n"]


def _why(res: dict) -> list[str]:
    return [
        "**Why.** Theorem 1 bounds the H^1 error by C h^(1/2) assuming u in H^2, an assumption that fails at the "
        "ends of the defect: where the faces are separated (large delta: a crack; f2 opens the right part of the "
        "defect, see the contact-zone lengths above) the displacement behaves like r^(1/2) near the tip "
        "(r = distance to the tip), which is in H^(3/2 - eps) but not in H^2, and on uniform meshes such a "
        "singularity limits the energy-norm error of P1 elements to O(h^(1/2)) as h -> 0 (and the L2 error to "
        "about O(h)). So h^(1/2) is the asymptotic rate to expect for a genuine crack, not only a bound. An "
        "order above 1/2 on moderate meshes reads as pre-asymptotic: the error of the singular part "
        "(proportional to the stress intensity at the tip) is still outweighed by the error of the smooth part, "
        "which decreases like h, so the measured order lies between the two and moves toward 1/2 as the "
        "singular part takes over - the falling triple-wise orders above. Other singular points - the "
        "corners where the clamped bottom meets the free sides, and the jump of the traction at the middle of "
        "the top side - are present for every delta and keep the order below 1 even when the faces are glued. "
        "As delta decreases, the interface term (1/delta) int |[u]|^2 glues the faces (max jump "
        + ", ".join(f"{d['reference']['max_jump']:.1e} at delta = {dl}" for dl, d in res["deltas"].items())
        + ") and the tip singularity fades, which is consistent with the higher and steadier order at small "
        "delta. The energy difference Pi_N - Pi_ref equals half the squared K-norm error up to the ratio shown "
        "in the energy tables (1 exactly for nested spaces without contact, by Galerkin orthogonality; the "
        "trapezoid rule of the interface term and the contact constraint make it differ), so its order is about "
        "twice the energy-norm order. The total contact force converges at a raw order of "
        + ", ".join(f"{_fmt(_mean_rate(d['levels'], 'rate_diff_total_force'), '.2f')} (delta = {dl})"
                    for dl, d in res["deltas"].items())
        + ", and the contact-zone length is resolved only to within one mesh edge: its error is O(h) at best "
        "and not monotone."]


def _discussion(res: dict) -> str:
    """Observed rates summarised; the prose states what the numbers show (computed, not typed in)."""
    summary, fitted = _rate_summary(res)
    triple_lines, triples = _triples(res)
    return "\n".join(summary + triple_lines + _what(res, fitted, triples) + _why(res))


def render(res: dict, out: Path, command: str | None = None) -> Path:
    """Draw the two figures into ``out/figures`` and write ``out/convergence.md`` from the study's
    result (:func:`dualfem.experiments.convergence.study`, or its stored ``convergence.json``);
    returns the Markdown path. Solves nothing."""

    pngs = plot(res, out / "figures")
    cmd = command or res.get("command", "dualfem report convergence")
    return atomic_write_text(out / "convergence.md", markdown(res, pngs, cmd))
