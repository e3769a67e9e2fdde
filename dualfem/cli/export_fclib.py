"""``dualfem export SCENE --format fclib -o p.hdf5``: a Coulomb-frictional scene as FCLIB's global problem
(:mod:`dualfem.core.fclib`; docs/friction.md)."""
from __future__ import annotations

import sys

from dualfem.core.errors import InputError


def export_fclib(args) -> int:
    """``export --format fclib``: the scene's Coulomb problem in FCLIB's global format (dualfem.core.fclib)."""
    import importlib.util
    from pathlib import Path

    from dualfem.cli.main import scene_from_args
    from dualfem.core.fclib import fclib_global, write_fclib
    from dualfem.core.io import check_output_path
    from dualfem.core.scene import build_qp

    if Path(args.output).suffix not in (".hdf5", ".h5"):
        raise InputError(f"-o must name a .hdf5 or .h5 file with --format fclib, got {args.output!r}")
    if importlib.util.find_spec("h5py") is None:
        raise InputError("--format fclib needs h5py: pip install 'dualfem[xdmf]'")
    check_output_path(args.output, "-o")
    prob = fclib_global(build_qp(scene_from_args(args)))
    write_fclib(args.output, prob)
    print(f"wrote {args.output}: FCLIB global problem, n={prob.M.shape[0]} unknowns, {prob.mu.size} contacts "
          f"(spacedim {prob.spacedim})", file=sys.stderr)
    return 0
