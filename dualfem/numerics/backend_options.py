"""The settings of the wrapped QP libraries, read from the installed library (for Solver.backend_options).

Each reader returns ``{option: default}`` for the options whose default is a plain bool, int, float or
string (those a command line can give: ``-s 'osqp[rho=0.1]'``); enum- and list-valued settings are
left out. A library that is not installed gives ``{}``. Nothing is hard-coded: the names and defaults
are the installed library's own, so a new library version brings its new options.
"""
from __future__ import annotations

import importlib.util
from functools import cache
from typing import Any


def _plain(obj: Any, names: list[str]) -> dict[str, Any]:
    out = {}
    for k in names:
        try:
            v = getattr(obj, k)
        except Exception:  # noqa: BLE001 - a property the binding cannot read: not an option we can pass
            continue
        if isinstance(v, (bool, int, float, str)) and not callable(v):
            out[k] = v
    return out


def _public(obj: Any) -> list[str]:
    return [k for k in dir(obj) if not k.startswith("_") and not callable(getattr(obj, k, None))]


@cache
def clarabel_options() -> dict[str, Any]:
    """Clarabel's ``DefaultSettings`` fields and defaults."""
    if importlib.util.find_spec("clarabel") is None:
        return {}
    import clarabel

    s = clarabel.DefaultSettings()
    return _plain(s, _public(s))


@cache
def osqp_options() -> dict[str, Any]:
    """OSQP's settings (``OSQPSettings`` after ``osqp_set_default_settings``) and defaults; OSQP stores
    its switches as 0/1 integers: those with a 0/1 default are given as bools."""
    if importlib.util.find_spec("osqp") is None:
        return {}
    import osqp

    ext = osqp.OSQP().ext
    s = ext.OSQPSettings()
    ext.osqp_set_default_settings(s)
    out = _plain(s, _public(s))
    switches = ("adaptive_rho", "check_dualgap", "polishing", "rho_is_vec", "scaled_termination", "verbose",
                "warm_starting")
    return {k: (bool(v) if k in switches else v) for k, v in out.items()}


@cache
def piqp_options() -> dict[str, Any]:
    """PIQP's sparse-solver settings and defaults."""
    if importlib.util.find_spec("piqp") is None:
        return {}
    import piqp

    s = piqp.SparseSolver().settings
    return _plain(s, _public(s))


#: qpsolvers backend -> reader of its library's options (the backends whose options can be read)
QPSOLVERS_READERS = {"clarabel": clarabel_options, "osqp": osqp_options, "piqp": piqp_options}
#: cvxpy backend -> reader
CVXPY_READERS = {"CLARABEL": clarabel_options, "OSQP": osqp_options, "PIQP": piqp_options}
