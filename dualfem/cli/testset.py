"""``dualfem testset --out DIR [--sizes tiny,small,medium,large] [--force] [--no-friction]``: a public test set.

Writes the declared contact QPs (:data:`dualfem.experiments.testset.DECLARED`) of the chosen size classes in
qpsolvers' convention ``G x <= h``, each with its certified reference, the qpbenchmark ``TestSet`` module,
``manifest.json`` and ``README.md`` (see :mod:`dualfem.experiments.testset`), and, unless ``--no-friction``, the
frictional problems of those classes under ``friction/`` (:mod:`dualfem.experiments.testset_friction`).
Everything is validated before anything is written; a non-empty ``DIR`` is refused unless ``--force``. One
progress line per problem on stderr once the command has run longer than 2 s (``--quiet`` silences them).
"""
from __future__ import annotations

import sys

from dualfem.cli.main import MAX_MEMORY_GB, add_factor_arg, apply_factor, command
from dualfem.cli.options import float_in
from dualfem.cli.stages import Stages
from dualfem.core.errors import InputError


def _cfg(p):
    from dualfem.experiments.testset import DEFAULT_SIZES, SIZES

    p.add_argument("--out", required=True, metavar="DIR", help="folder to write the test set into")
    p.add_argument("--sizes", default=None, metavar="A,B,...",
                   help=f"size classes to write, of {', '.join(SIZES)} (default: {','.join(DEFAULT_SIZES)})")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out: the test set's files are written over, the problems of a "
                        "previous set that this one lacks removed, nothing else touched")
    p.add_argument("--max-memory", type=float_in(0, MAX_MEMORY_GB, "GB"), default=None, metavar="GB",
                   help="memory a scene may use (default: what the machine has available)")
    p.add_argument("--no-friction", action="store_true",
                   help="leave out the frictional problems (friction/: Tresca, Coulomb, 2D, 3D; small, medium)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    add_factor_arg(p)


@command("testset", "write a qpbenchmark test set of contact QPs with certified references")(_cfg)
def cmd_testset(args) -> int:
    from dualfem.core.quiet import c_stdout_to_stderr
    from dualfem.experiments.testset import parse_sizes, write_testset
    from dualfem.experiments.testset_files import MANIFEST, TESTSET_PY
    from dualfem.experiments.testset_render import size_markdown

    sizes = parse_sizes(args.sizes)
    mm = args.max_memory
    if mm is not None and not (mm > 0 and mm <= MAX_MEMORY_GB):
        raise InputError(f"--max-memory must be a number of GB in (0, {MAX_MEMORY_GB:g}], got {mm!r}")
    apply_factor(args)
    stages = Stages("testset", quiet=args.quiet)
    with c_stdout_to_stderr():
        man = write_testset(args.out, sizes, force=args.force, max_bytes=None if mm is None else mm * 1e9,
                            progress=stages, friction=not args.no_friction)
    print(size_markdown(man))
    nf = len(man.get("friction", {}).get("problems", []))
    print(f"wrote {len(man['problems'])} problems{f' and {nf} frictional ones (friction/)' if nf else ''} to "
          f"{args.out} ({TESTSET_PY}, {MANIFEST}, README.md); run: "
          f"python {args.out}/{TESTSET_PY} run --solver clarabel --author NAME",
          file=sys.stderr)
    return 0
