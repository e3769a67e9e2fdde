"""Errors from the environment, not the input (issue 14, 'zero tracebacks'): a missing scikit-fem, a
full disk, a file size limit, a read-only place, stdout on a full device. Each is one line
``dualfem CMD: error: ...`` with exit status 2, and no file is left half-written.

The missing module and the size limit are simulated in a child process (``sys.modules['skfem'] =
None``; ``RLIMIT_FSIZE``, which makes the kernel fail the write like a full disk does); ENOSPC
itself comes from /dev/full (stdout) or from a library writer failing midway (monkeypatched).
"""
from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualfem.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def child(argv: list[str], *, prelude: str = "", fsize: int | None = None, stdout=subprocess.PIPE,
          cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``python -m dualfem ARGV`` in a child process, after ``prelude``; ``fsize`` caps file sizes (bytes)."""
    code = f"import sys\n{prelude}\nfrom dualfem.cli.main import main\nsys.exit(main({argv!r}))\n"

    def limit():
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-c", code], stdout=stdout, stderr=subprocess.PIPE, text=True,
                          env=env, cwd=cwd, timeout=60, preexec_fn=limit if fsize else None)


def one_line(err: str, cmd: str, *needles: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith(f"dualfem {cmd}: error: "), lines[0]
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


BLOCK_SKFEM = "sys.modules['skfem'] = None"


# ------------------------------------------------------------------ scikit-fem missing
def test_skfem_missing_a_scene_that_needs_it_names_what_to_install(tmp_path):
    r = child(["solve", "signorini", "--set", "N=8"], prelude=BLOCK_SKFEM, cwd=tmp_path)
    assert r.returncode == 2
    one_line(r.stderr, "solve", "'skfem'", "pip install scikit-fem")


def test_skfem_missing_the_thin_defect_scenes_do_not_need_it(tmp_path):
    """f1/f2/f3 are assembled by dualfem.core.elasticity: they answer without scikit-fem."""
    r = child(["solve", "f2", "--set", "N=8", "--json"], prelude=BLOCK_SKFEM, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert '"status": "solved"' in r.stdout and "Traceback" not in r.stderr


def test_skfem_missing_is_listed(tmp_path):
    r = child(["list"], prelude=BLOCK_SKFEM, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    line = next(ln for ln in r.stdout.splitlines() if ln.strip().startswith("signorini "))
    assert "NOT INSTALLED" in line and "scikit-fem" in line


def test_an_undeclared_missing_module_is_one_line(monkeypatch, capsys):
    """A plugin that imports a missing module without declaring it in ``requires``."""
    from dualfem.problems.thin_defect import ThinDefect

    def build(self):
        raise ModuleNotFoundError("No module named 'skfem'", name="skfem")

    monkeypatch.setattr(ThinDefect, "build", build)
    assert main(["solve", "f2", "--set", "N=8"]) == 2
    one_line(capsys.readouterr().err, "solve", "'skfem'", "pip install scikit-fem")


# ------------------------------------------------------------------ full disk
@pytest.mark.parametrize("argv, target", [
    (["export", "f2", "--set", "N=8", "-o", "{d}/qp.npz"], "qp.npz"),
    (["solve", "f2", "--set", "N=8", "--vtk", "{d}/out.vtu"], "out.vtu"),
])
def test_file_size_limit_mid_write_is_one_line_and_leaves_nothing(tmp_path, argv, target):
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    r = child(argv, fsize=2000, cwd=tmp_path)
    assert r.returncode == 2
    one_line(r.stderr, argv[0], "cannot write", target, "nothing was written")
    assert os.listdir(tmp_path) == [], os.listdir(tmp_path)          # no partial file, no temporary file


def test_enospc_in_a_library_writer_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    def savez_then_full(fh, **arrays):
        fh.write(b"PK\x03\x04" + b"\0" * 512)                          # a partial zip, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez_compressed", savez_then_full)
    out = tmp_path / "qp.npz"
    assert main(["export", "f2", "--set", "N=8", "-o", str(out)]) == 2
    one_line(capsys.readouterr().err, "export", str(out), "No space left on device")
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize("argv", [["solve", "f2", "--set", "N=8", "--json"], ["list"]])
def test_stdout_on_a_full_device_is_one_line(tmp_path, argv):
    with open("/dev/full", "w") as full:
        r = child(argv, stdout=full, cwd=tmp_path)
    assert r.returncode == 2
    one_line(r.stderr, argv[0], "No space left on device")


# ------------------------------------------------------------------ unwritable places
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc (Linux)")
def test_vtk_where_even_root_cannot_write_is_refused_before_the_solve(capsys):
    """/proc refuses new files to everyone (os.access says yes to root): checked before solving."""
    assert main(["solve", "f2", "--set", "N=8", "--vtk", "/proc/dualfem-test.vtu"]) == 2
    out, err = capsys.readouterr()
    one_line(err, "solve", "--vtk", "/proc")
    assert "solved" not in out                                        # refused before the solve


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write in a read-only folder")
def test_read_only_folder_is_refused_before_the_solve(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert main(["solve", "f2", "--set", "N=8", "--vtk", str(ro / "out.vtu")]) == 2
        one_line(capsys.readouterr().err, "solve", "--vtk", "permission")
    finally:
        ro.chmod(0o700)
    assert os.listdir(ro) == []
