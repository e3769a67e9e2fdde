"""One figure of a solution, for ``dualfem solve --figure FILE``: in 2D the deformed body coloured by
the von Mises stress beside the jump along the defects; in 3D the maps of opening, slip and contact
pressure over each defect surface and a cut through the body (:mod:`dualfem.post.figures3d`)."""
from __future__ import annotations

from pathlib import Path

from dualfem.core.errors import InputError
from dualfem.core.io import atomic_savefig, check_output_path

FORMATS = (".png", ".pdf", ".svg")


def check_figure_path(path: str) -> Path:
    """Refuse, before any work, a figure path of another format or that cannot be written."""
    p = Path(path)
    if p.suffix.lower() not in FORMATS:
        raise InputError(f"--figure must name a {', '.join(FORMATS)} file, got {path!r}")
    return check_output_path(p, "--figure")


def check_figure_qp(qp) -> None:
    """Refuse (InputError), before anything is solved or written, a QP the figure cannot draw: a 3D scene
    without defects (``defects = []``), whose figure would be the defects' maps and a cut across one."""
    g = getattr(qp, "geometry", None)
    if g is not None and g.dim == 3 and qp.m == 0:
        raise InputError("--figure draws the defects' opening and contact maps and a cut across the first "
                         "defect; this 3D scene has none (defects = []): write the fields with --vtk or --xdmf")


def solution_figure(qp, sol):
    """The matplotlib figure described in the module docstring."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    g = getattr(qp, "geometry", None)
    if g is None:
        raise InputError("--figure needs the mesh of the QP (a scene, or a QP file with its map_ arrays)")
    if sol.x is None:
        raise InputError(f"no solution to draw (status {sol.status})")
    if g.dim == 3:
        from dualfem.post.figures3d import plot_cut, plot_defect_maps

        check_figure_qp(qp)
        fig = plot_defect_maps(qp, sol)
        cut = plt.figure(figsize=(5, 4.4), layout="constrained")
        plot_cut(qp, sol, ax=cut.add_subplot())
        return [fig, cut]
    from dualfem.post.figures import plot_deformed, plot_jump

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), layout="constrained")
    plot_deformed(qp, sol, ax=axes[0], contact=True)
    if qp.interface is not None:
        plot_jump([(sol.solver or "solution", qp, sol)], ax=axes[1])
    else:
        axes[1].set_axis_off()
    return [fig]


def write_solution_figure(path: str, qp, sol) -> list[Path]:
    """Write the figure(s): ``path``, and in 3D the cut as ``<stem>_cut<suffix>`` beside it."""
    p = check_figure_path(path)
    figs = solution_figure(qp, sol)
    out = [atomic_savefig(figs[0], p, format=p.suffix[1:].lower(), dpi=150)]
    if len(figs) > 1:
        q = p.with_name(f"{p.stem}_cut{p.suffix}")
        out.append(atomic_savefig(figs[1], q, format=p.suffix[1:].lower(), dpi=150))
    import matplotlib.pyplot as plt

    for f in figs:
        plt.close(f)
    return out
