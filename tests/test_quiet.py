"""Third-party libraries' banners: dropped from the terminal unless verbose output is asked for."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from dualfem.core.quiet import VERBOSE_ENV, set_verbose, verbose

SNIPPET = """
import os, sys
from dualfem.core.quiet import plugin_output
with plugin_output(drop_c_output=sys.argv[1] == "drop"):
    os.write(1, b"Running SomeLib 1.0: Copyright banner\\n")     # as a C library writes it
    print("python print")
print("after the block")
"""


def _run(mode: str, verbose_env: str | None) -> tuple[str, str]:
    env = {k: v for k, v in os.environ.items() if k != VERBOSE_ENV}
    if verbose_env is not None:
        env[VERBOSE_ENV] = verbose_env
    r = subprocess.run([sys.executable, "-c", SNIPPET, mode], env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout, r.stderr


@pytest.mark.parametrize("mode,env,shown", [("drop", None, False), ("drop", "0", False), ("drop", "1", True),
                                            ("keep", None, True)])
def test_c_banner_dropped_unless_verbose(mode, env, shown):
    """A built-in wrapper's library banner (drop) is dropped unless DUALFEM_VERBOSE; a plugin's (keep) goes
    to stderr; stdout holds only what dualfem prints after the block."""
    out, err = _run(mode, env)
    assert out == "after the block\n"
    assert ("Copyright banner" in err) is shown and "python print" in err


def test_set_verbose_reaches_worker_processes(monkeypatch):
    monkeypatch.delenv(VERBOSE_ENV, raising=False)
    set_verbose(True)
    assert os.environ[VERBOSE_ENV] == "1" and verbose()
    set_verbose(False)
    assert VERBOSE_ENV not in os.environ and not verbose()
    monkeypatch.setenv(VERBOSE_ENV, "0")
    assert not verbose()


def test_every_command_takes_verbose():
    from dualfem.cli.main import build_parser

    p = build_parser()
    for cmd in ("solve", "compare", "bench", "stress"):
        argv = {"solve": ["solve", "f2"], "compare": ["compare", "f2"], "bench": ["bench", "x.toml"],
                "stress": ["stress"]}[cmd]
        assert p.parse_args(argv + ["--verbose"]).verbose is True
