"""The memory a new allocation may use now, and the size checks made before allocating.

:func:`available_bytes` is the smallest of

* the machine's ``MemAvailable`` (``/proc/meminfo``; else the total physical memory);
* the address space left under ``ulimit -v`` (``RLIMIT_AS`` minus the process's ``VmSize``);
* the room left in every memory cgroup of the process and its ancestors: cgroup v2
  ``memory.max - memory.current``, cgroup v1 ``memory.limit_in_bytes - memory.usage_in_bytes``
  ("max" and v1's huge "no limit" values mean no limit).

The file locations are module constants (``PROC``, ``CGROUP_ROOT``) so tests can point them at a
fake tree. :func:`check_alloc` refuses (InputError naming what asked for it) an allocation whose
declared size exceeds it: used by every loader before it trusts a declared shape.
"""
from __future__ import annotations

import os
from pathlib import Path

from dualfem.core.errors import InputError

PROC = Path("/proc")
CGROUP_ROOT = Path("/sys/fs/cgroup")
#: cgroup v1 writes a number near 2**63 for "no limit"
_V1_UNLIMITED = 2**60


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except (OSError, ValueError):
        return None
    if text == "max":
        return None
    try:
        v = int(text)
    except ValueError:
        return None
    return None if v >= _V1_UNLIMITED else v


def meminfo_bytes() -> int:
    """Linux ``MemAvailable`` (else the total physical memory)."""
    try:
        with open(PROC / "meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 2**62


def rlimit_bytes() -> int | None:
    """Address space left under ``ulimit -v`` (RLIMIT_AS soft limit minus VmSize), None without a limit."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):
        return None
    if soft in (resource.RLIM_INFINITY, -1) or soft < 0:
        return None
    used = 0
    try:
        for line in (PROC / "self" / "status").read_text().splitlines():
            if line.startswith("VmSize:"):
                used = int(line.split()[1]) * 1024
                break
    except (OSError, ValueError, IndexError):
        pass
    return max(int(soft) - used, 0)


def _cgroup_paths() -> list[tuple[str, str]]:
    """(version, path inside the hierarchy) of the process's memory cgroups: ("2", "/a/b"), ("1", "/x")."""
    try:
        lines = (PROC / "self" / "cgroup").read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        hid, controllers, path = parts
        if hid == "0" and controllers == "":
            out.append(("2", path))
        elif "memory" in controllers.split(","):
            out.append(("1", path))
    return out


def cgroup_bytes() -> int | None:
    """Room left in the tightest memory cgroup of the process or its ancestors, None without a limit."""
    best: int | None = None
    for version, path in _cgroup_paths():
        if version == "2":
            base, files = CGROUP_ROOT, ("memory.max", "memory.current")
            if not (base / "cgroup.controllers").exists() and (base / "unified").is_dir():
                base = base / "unified"
        else:
            base, files = CGROUP_ROOT / "memory", ("memory.limit_in_bytes", "memory.usage_in_bytes")
        rel = Path(path.lstrip("/"))
        chain = [rel, *rel.parents] if str(rel) not in ("", ".") else [Path(".")]
        for p in chain:
            d = base / p
            limit = _read_int(d / files[0])
            if limit is None:
                continue
            used = _read_int(d / files[1]) or 0
            room = max(limit - used, 0)
            best = room if best is None else min(best, room)
    return best


def available_bytes() -> int:
    """Memory a new allocation may use now: the smallest of MemAvailable, ``ulimit -v``, cgroup limits."""
    vals = [meminfo_bytes(), rlimit_bytes(), cgroup_bytes()]
    return int(min(v for v in vals if v is not None))


def check_alloc(nbytes: float, what: str, hint: str = "") -> None:
    """InputError naming ``what`` when ``nbytes`` exceeds :func:`available_bytes` (before allocating)."""
    have = available_bytes()
    if not nbytes <= have:
        raise InputError(f"{what} would need about {_gb(nbytes)} of memory, more than the {_gb(have)} "
                         f"available (machine, ulimit -v and cgroup limits){'; ' + hint if hint else ''}")


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB" if n < 1e15 else f"{n:.1e} bytes"
