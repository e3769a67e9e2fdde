"""Facts about the machine and process that ran an experiment (recorded with every row)."""
from __future__ import annotations

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
    from importlib.metadata import PackageNotFoundError, version

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
    vers = {}
    for pkg in ("dualfem", *BASE_PACKAGES, "scikit-sparse", "joblib", "distributed", *plugin_packages()):
        try:
            vers[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
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


def plugin_packages() -> list[str]:
    """The distributions that provide the modules the registered solver plugins require
    (``Solver.requires``), sorted: their versions are recorded with the results, whoever the plugins are."""
    from importlib.metadata import packages_distributions

    from dualfem.core.registry import solvers

    dists = packages_distributions()
    mods = {m.split(".")[0] for cls in solvers().values() for m in getattr(cls, "requires", ())}
    return sorted({d for m in mods for d in dists.get(m, [])})


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def loadavg() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def environment() -> dict:
    """Versions and machine facts recorded with the results."""
    import importlib.metadata as md

    vers = {}
    for p in (*BASE_PACKAGES, *plugin_packages()):
        try:
            vers[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return {"python": sys.version.split()[0], "platform": platform.platform(), "cpus": os.cpu_count(),
            "versions": vers}

