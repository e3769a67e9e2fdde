"""Render reports/sif.md and reports/sif/penny_front.png from benchmarks/sif.py's runs.jsonl rows."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

CASES_2D = {"griffith": "Griffith, tension (plane strain)", "griffith_stress": "Griffith, tension (plane stress)",
            "mixed30": "uniaxial at beta = 30 deg", "mixed60": "uniaxial at beta = 60 deg",
            "closed": "closed: compression -1 + shear 0.3 (K_I = 0)"}
CASES_3D = {"penny": ("penny, tension", ("K_I",)), "shear": ("penny, compression + shear (Kassir-Sih)",
                                                              ("K_I", "K_II", "K_III")),
            "ellipse": ("ellipse b/a = 0.5, tension (Irwin)", ("K_I",))}


def _pct(v, signed: bool = True) -> str:
    if v is None or not math.isfinite(v):
        return "-"
    return f"{100 * v:{'+' if signed else ''}.{2 if abs(v) < 10 else 0}f} %"


def _group(row: dict) -> str:
    return row.get("group") or ("centre" if row["dim"] == 2 else "three_d")


def _case_2d(row: dict) -> str:
    if row["case"].startswith("edge"):
        return f"edge crack a/b = {row['a_over_b']:g}"
    return CASES_2D[row["case"]]


def _table_2d(rows: list[dict], wall: str = "build + solve wall") -> list[str]:
    out = ["| case | mesh_size:tip_size | unknowns | interaction K_I | interaction K_II | fit K_I | fit K_II "
           f"| extrapolate K_I | extrapolate K_II | {wall} |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m = r["methods"]
        cells = [_pct(m.get(k, {}).get(f"{mode}_err")) for k in ("interaction", "fit", "extrapolate")
                 for mode in ("K_I", "K_II")]
        mesh = r.get("mesh") or f"{r['mesh_size']:g}:{r['tip_size']:g}"
        out.append(f"| {_case_2d(r)} | {mesh} | {r['unknowns']:,} | "
                   + " | ".join(cells) + f" | {r['wall_s']:.1f} s |")
    return out


def _table_rings(rows: list[dict]) -> list[str]:
    cases = list(dict.fromkeys(r["case"] for r in rows))
    out = ["| r_out / a | " + " | ".join(f"{CASES_2D[c]}: K_I | K_II" for c in cases) + " |",
           "|---|" + "---|---|" * len(cases)]
    for f in dict.fromkeys(r["r_out_over_a"] for r in rows):
        cells = []
        for c in cases:
            m = next(r for r in rows if r["case"] == c and r["r_out_over_a"] == f)["methods"]["interaction"]
            cells += [_pct(m["K_I_err"]), _pct(m["K_II_err"])]
        out.append(f"| {f:g} | " + " | ".join(cells) + " |")
    return out


def _sections_2d(rows: list[dict]) -> list[str]:
    """The edge crack, the adaptive meshes and the ring study, where they ran."""
    out = []
    edge = [r for r in rows if _group(r) == "edge"]
    if edge:
        out += ["## 2D: an edge crack in a strip against Tada", "",
                "Single edge crack of length a in a strip of width b = 1 and height 6 (a body from a file: "
                "examples/bodies/edge_crack.geo), tension 1 on both ends, plane strain; K_I against Tada's "
                "F(a/b) sigma sqrt(pi a) (accurate to 0.5 %), K_II against 0 (relative to sigma sqrt(pi a)). One tip: "
                "the mouth lies on the boundary and has no K. Tip-graded meshes (mesh_size:tip_size) and the adaptive "
                "loop's meshes from the coarsest (`refine = \"adaptive\"` of a geometry file; wall: the steps so "
                "far). benchmarks/sif_cases2d.py; 2 cores shared with other engineers' jobs.", "",
                *_table_2d(edge), ""]
    ad = [r for r in rows if _group(r) == "adaptive"]
    if ad:
        out += ["## 2D: the centre cracks on adaptive meshes", "",
                "The cases of the first table on the meshes of the adaptive loop (ZZ estimate, sizes that "
                "equidistribute the predicted error; docs/adaptive.md), from mesh_size 0.5, tip_size 0.005, each "
                "step at most 3 x the unknowns of the last. Wall: the steps so far.", "",
                *_table_2d(ad, "wall (steps so far)"), ""]
    rings = [r for r in rows if _group(r) == "rings"]
    if rings:
        r0 = rings[0]
        out += ["## 2D: the interaction integral's ring", "",
                f"One tip-graded mesh (mesh_size {r0['mesh_size']:g}, tip_size {r0['tip_size']:g}, "
                f"{r0['unknowns']:,} unknowns), r_out from a/2 (the default: a quarter of the crack's length) down to "
                "a/64, r_in = r_out / 2; signed error of the worse tip:", "", *_table_rings(rings), ""]
    return out


def _table_3d(rows: list[dict]) -> list[str]:
    out = ["| case | mode | mesh_size:tip_size | unknowns | interaction: amplitude | interaction: max | fit: amplitude "
           "| fit: max | extrapolate: amplitude | extrapolate: max | interaction time | build + solve wall |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        name, modes = CASES_3D[r["case"]]
        for mode in modes:
            m = r["methods"]
            cells = [_pct(m.get(k, {}).get(f"{mode}_{w}_err"), w == "mean")
                     for k in ("interaction", "fit", "extrapolate") for w in ("mean", "max")]
            t = m.get("interaction", {}).get("sif_s")
            out.append(f"| {name} | {mode} | {r['mesh_size']:g}:{r['tip_size']:g} | {r['unknowns']:,} | "
                       + " | ".join(cells) + f" | {'-' if t is None else f'{t:.1f} s'} | {r['wall_s']:.1f} s |")
    return out


def _figure(row: dict, path: Path) -> Path:
    """K_I, K_II, K_III along the penny's front (interaction integral: filled markers; displacement correlation: open)
    against Kassir and Sih (Okabe-Ito colours, one marker per mode)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dualfem.post.style import PALETTE

    t = np.linspace(0, 2 * np.pi, 361)
    amp, nu = 4 * 0.5 / np.sqrt(np.pi) / 1.7, 0.3
    exact = {"K_I": 0 * t, "K_II": amp * np.cos(t), "K_III": amp * (1 - nu) * np.sin(t)}
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    for (mode, ex), col, mk in zip(exact.items(), PALETTE, ("o", "s", "^")):
        ax.plot(np.degrees(t), ex, "-", color=col, lw=1.2, label=f"{mode} closed form")
        for method, fill in (("interaction", col), ("fit", "none")):
            f = row["methods"].get(method, {}).get("front")
            if not f:
                continue
            P = np.asarray(f["point"])
            th = np.arctan2(P[:, 1] - 5.0, P[:, 0] - 5.0) % (2 * np.pi)
            o = np.argsort(th)
            ax.plot(np.degrees(th[o]), np.asarray(f[mode])[o], mk, ms=3.5, color=col, mfc=fill,
                    label=f"{mode} {'interaction integral' if method == 'interaction' else 'displ. correlation'}")
    ax.set_xlabel("polar angle theta of the front node (degrees)")
    ax.set_ylabel("K (stress x sqrt(length))")
    ax.set_xlim(0, 360)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6.5, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.16))
    ax.set_title(f"penny under compression + shear, {row['unknowns']:,} unknowns (P1, mesh "
                 f"{row['mesh_size']:g}:{row['tip_size']:g})", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def _kept(command: str) -> str:
    if "--only" not in command:
        return ""
    return (" (the groups it does not name kept from the last full run, `python benchmarks/sif.py --out "
            "benchmarks/results/sif --report reports`)")


def render(rows: list[dict], report: Path, command: str) -> list[Path]:
    """Write REPORT/sif.md (and the figure when the shear case ran); the paths written."""
    written = []
    shear = [r for r in rows if r["case"] == "shear" and r["methods"].get("interaction", {}).get("front")]
    lines = ["# Stress intensity factors against closed forms", "",
             f"Generated by `{command}`{_kept(command)} (benchmarks/sif.py: the cases, closed forms and error "
             "measures; docs/sif.md: the conventions and methods). P1 elements, solver pdas, delta = 1e3.", "",
             "## 2D: crack of half-length a = 0.05 in a 5 x 5 square", "",
             "Signed relative error of the worse tip (a zero closed form: against |sigma| sqrt(pi a)).", "",
             *_table_2d([r for r in rows if _group(r) == "centre"]), "", *_sections_2d(rows),
             "## 3D: penny (radius 1) and ellipse (1 x 0.5) in a cube of side 10", "",
             "Amplitude: the least-squares multiple of the closed form's shape along the front, minus 1 (a zero "
             "closed form: the mean of abs(K) against |sigma| 2 sqrt(a/pi)); max: the largest pointwise error along "
             "the front relative to the closed form's largest value. The cube adds ~1-2 % (benchmarks/penny.py).", "",
             *_table_3d([r for r in rows if _group(r) == "three_d"]), ""]
    if shear:
        fig = _figure(shear[-1], report / "sif" / "penny_front.png")
        written.append(fig)
        lines += ["![K along the penny's front](sif/penny_front.png)", ""]
    path = report / "sif.md"
    path.write_text("\n".join(lines))
    return [path, *written]
