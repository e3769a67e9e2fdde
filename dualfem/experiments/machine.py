"""Facts about the machine and process that ran an experiment (recorded with every row)."""
from __future__ import annotations

import functools
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

_MACHINE: dict | None = None


def machine_info() -> dict:
    """CPU, cores, thread settings and library versions of the process running the task."""
    global _MACHINE
    if _MACHINE is not None:
        return dict(_MACHINE)
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = os.cpu_count()
    threads = {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                           "RAYON_NUM_THREADS") if k in os.environ}
    vers = versions()
    git = ""
    try:
        here = Path(__file__).resolve().parents[2]
        if (here / ".git").exists():
            git = subprocess.run(["git", "-C", str(here), "rev-parse", "--short", "HEAD"], capture_output=True,
                                 text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    _MACHINE = {"cpu": cpu, "cores": os.cpu_count(), "affinity": affinity,
                "threads": json.dumps(threads, sort_keys=True) if threads else "unset",
                "python": platform.python_version(), "platform": platform.platform(terse=True),
                "versions": json.dumps(vers, sort_keys=True), "git": git}
    return dict(_MACHINE)


#: the distributions every run depends on (the solver plugins' own are found by :func:`plugin_packages`)
BASE_PACKAGES = ("numpy", "scipy", "scikit-fem")
#: distributions recorded when installed: the solver libraries, the factorization backends (PARDISO is
#: pypardiso on the ``mkl`` wheel; ``mkl-service`` where present), meshing, AMG, parallel sweeps
OPTIONAL_PACKAGES = ("dualfem", "osqp", "clarabel", "cvxpy", "qpsolvers", "pypardiso", "mkl", "mkl-service",
                     "scikit-sparse", "gmsh", "pyamg", "threadpoolctl", "joblib", "distributed")
#: modules a qpsolvers backend file imports that are not the backend itself
_NOT_BACKENDS = frozenset({"numpy", "scipy", "qpsolvers", "__future__"})


def versions() -> dict[str, str]:
    """Versions of every distribution a run may depend on, from the installed metadata only (nothing
    is imported for it): :data:`BASE_PACKAGES`, :data:`OPTIONAL_PACKAGES` and the registered solver
    plugins' packages (:func:`plugin_packages`) as ``{distribution: version}`` when installed; every
    installed qpsolvers backend as ``{"qpsolvers/<backend>": "<distribution> <version>"}``
    (:func:`qpsolvers_backends`); ``"mkl_rt"``: the library file ``PYPARDISO_MKL_RT`` names, when set
    (then the ``mkl`` distribution's version need not be the MKL PARDISO runs in)."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str] = {}
    for pkg in (*BASE_PACKAGES, *OPTIONAL_PACKAGES, *plugin_packages()):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    for backend, dists in qpsolvers_backends().items():
        out[f"qpsolvers/{backend}"] = ", ".join(f"{d} {v}" for d, v in dists.items())
    if os.environ.get("PYPARDISO_MKL_RT"):
        out["mkl_rt"] = os.environ["PYPARDISO_MKL_RT"]
    return out


def qpsolvers_backends(solvers_dir: Path | None = None) -> dict[str, dict[str, str]]:
    """Every qpsolvers backend whose library is installed: ``{backend: {distribution: version}}``.

    The backends are qpsolvers' own modules ``qpsolvers/solvers/<backend>_.py``, read from disk (not
    imported: importing qpsolvers imports every backend, seconds); a backend's library is what its module
    imports at top level besides numpy, scipy and qpsolvers, mapped to distributions by
    ``importlib.metadata.packages_distributions`` (else the distribution of the module's own name). A
    backend counts as installed when every such module is found (``importlib.util.find_spec``: what
    ``qpsolvers.available_solvers`` finds by importing them, unless an installed library fails to
    import). Empty without qpsolvers. ``solvers_dir``: another folder of such modules (tests).
    """
    import ast
    import importlib.util
    from importlib.metadata import PackageNotFoundError, version

    if solvers_dir is None:
        spec = importlib.util.find_spec("qpsolvers")
        if spec is None or not spec.submodule_search_locations:
            return {}
        folders = [Path(loc, "solvers") for loc in spec.submodule_search_locations]
    else:
        folders = [Path(solvers_dir)]
    dists = _packages_distributions()
    out: dict[str, dict[str, str]] = {}
    for folder in folders:
        for f in sorted(folder.glob("*_.py")):
            if f.name.startswith("_"):
                continue
            try:
                tree = ast.parse(f.read_text(encoding="utf-8"))
            except (OSError, SyntaxError, UnicodeDecodeError):
                continue
            mods = {a.name.split(".")[0] for n in tree.body if isinstance(n, ast.Import) for a in n.names}
            mods |= {n.module.split(".")[0] for n in tree.body
                     if isinstance(n, ast.ImportFrom) and n.module and not n.level}
            mods = {m for m in mods if m not in _NOT_BACKENDS and m not in sys.stdlib_module_names}
            if not mods or any(importlib.util.find_spec(m) is None for m in mods):
                continue                         # find_spec of a top-level name imports nothing
            found: dict[str, str] = {}
            for m in sorted(mods):
                for d in dists.get(m) or [m]:    # a module only in a .so or a .pth prefix: its own name
                    try:
                        found[d] = version(d)
                    except PackageNotFoundError:
                        pass
            out[f.name[:-4]] = found
    return dict(sorted(out.items()))


def plugin_packages() -> list[str]:
    """The distributions that provide the modules the registered solver plugins require
    (``Solver.requires``), sorted: their versions are recorded with the results, whoever the plugins are."""
    from dualfem.core.registry import solvers

    dists = _packages_distributions()
    mods = {m.split(".")[0] for cls in solvers().values() for m in getattr(cls, "requires", ())}
    return sorted({d for m in mods for d in dists.get(m, [])})


@functools.cache
def _packages_distributions() -> dict[str, list[str]]:
    """``importlib.metadata.packages_distributions()`` once per process (it reads every installed
    distribution's file list: slow, docs/measurements.md)."""
    from importlib.metadata import packages_distributions

    return packages_distributions()


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def loadavg() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def environment() -> dict:
    """Versions and machine facts recorded with the results."""
    return {"python": sys.version.split()[0], "platform": platform.platform(), "cpus": os.cpu_count(),
            "versions": versions()}

