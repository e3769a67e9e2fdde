"""scripts/_env.sh's ``quiet_pip``: pip's output (setuptools' ~50 lines of build warnings) is held back
when the install works and shown in full, with the exit status, when it fails."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FAKE_PIP = """#!/usr/bin/env bash
# a stand-in for "python -m pip": 50 lines of warnings; exits 3 when asked to install 'broken'
for i in $(seq 50); do echo "BuildBackendWarning line $i" >&2; done
case "$*" in *broken*) echo "ERROR: No matching distribution found for broken" >&2; exit 3 ;; esac
exit 0
"""

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")


def _quiet_pip(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    py = venv / "bin" / "python"
    py.write_text(FAKE_PIP)
    py.chmod(0o755)
    script = f'. scripts/_env.sh && quiet_pip {" ".join(args)}'
    return subprocess.run(["bash", "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=30,
                          env={"PATH": "/usr/bin:/bin", "VIRTUAL_ENV": str(venv), "TMPDIR": str(tmp_path)})


def test_quiet_pip_prints_nothing_when_the_install_works(tmp_path):
    p = _quiet_pip(tmp_path, "install", "-q", "-e", ".")
    assert p.returncode == 0 and p.stdout == "" and p.stderr == ""
    assert not list(tmp_path.glob("dualfem-pip.*"))          # its log is removed


def test_quiet_pip_shows_everything_when_the_install_fails(tmp_path):
    p = _quiet_pip(tmp_path, "install", "broken")
    assert p.returncode == 3
    assert "BuildBackendWarning line 50" in p.stderr and "No matching distribution found for broken" in p.stderr
    assert p.stderr.rstrip().splitlines()[-1] == "pip install broken failed (exit 3): its output is above"


@pytest.mark.parametrize("script", ["run.sh", "test.sh"])
def test_scripts_install_through_quiet_pip(script):
    text = (ROOT / "scripts" / script).read_text()
    assert "quiet_pip install" in text and "-m pip install" not in text
