"""No orphans: after ``kill -9`` or SIGTERM of a ``--jobs 2`` sweep, no process of it is alive 5 s later.

A real ``dualfem bench SPEC --jobs 2`` is started in its own session; the sweep process alone is
killed, either once its loky workers and their guarded children run (``running``) or as soon as its
loky workers exist, before they have a task (``starting``: a worker still importing, or handed a task
after its sweep died), and the session's live processes (loky workers, guarded harness children,
loky's and multiprocessing's resource trackers) are counted 5 s later. Before the fix of issue 26,
item 6, 6 processes were left for minutes (``running``); before that of issue 37, item 7, 4 to 8
(``starting``: the workers watched their sweep only from their first task on).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("joblib")
if not Path("/proc/self/stat").exists():  # pragma: no cover
    pytest.skip("needs Linux /proc", allow_module_level=True)

SPEC = """
name = "orphans"
repeats = 50
warmup = false
time_limit = 60
[tiers]
low = 1e-3
[floor]
enabled = false
[[scenes]]
scene = ["f1", "f2"]
N = [16]
delta = [1e-3, 1e-9]
[[solvers]]
name = "osqp"
[[solvers]]
name = "clarabel"
"""


def session_processes(sid: int) -> list[tuple[int, str]]:
    """(pid, command line) of the live (not zombie) processes of session ``sid``."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, IndexError):
            continue
        if fields[0] != "Z" and int(fields[3]) == sid:
            out.append((int(d.name), cmd.strip()[-80:]))
    return out


def _left_after(proc: subprocess.Popen, sig: signal.Signals) -> list[tuple[int, str]]:
    """Send ``sig`` to ``proc`` alone (not its session), wait for it, and return the processes of its
    session still alive 5 s later (a tree that is gone cannot come back)."""
    os.kill(proc.pid, sig)
    proc.wait(timeout=30)
    gone = time.monotonic() + 5.0
    while session_processes(proc.pid) and time.monotonic() < gone:
        time.sleep(0.1)
    return session_processes(proc.pid)


def _reap(proc: subprocess.Popen) -> None:
    """SIGKILL whatever is left of ``proc``'s session and ``proc`` itself (a test's cleanup)."""
    for pid, _ in session_processes(proc.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def _plugin_env(tmp_path: Path, module: str, source: str, **extra: str) -> dict[str, str]:
    """An environment in which ``source`` is an installed solver plugin ``module`` (a distribution with a
    ``dualfem.solvers`` entry point on PYTHONPATH), as a third party would ship it."""
    src, site = tmp_path / "src", tmp_path / "site" / f"{module}-0.1.dist-info"
    src.mkdir()
    site.mkdir(parents=True)
    (src / f"{module}.py").write_text(source)
    dist = module.replace("_", "-")
    (site / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (site / "entry_points.txt").write_text(f"[dualfem.solvers]\n{module} = {module}\n")
    env = dict(os.environ, MPLBACKEND="Agg", **extra)
    env["PYTHONPATH"] = os.pathsep.join([str(site.parent), str(src), env.get("PYTHONPATH", "")])
    return env


def _ready(moment: str, procs: list[tuple[int, str]]) -> bool:
    if moment == "starting":
        return sum("popen_loky_posix" in c for _, c in procs) == 2
    return sum("harness --child" in c for _, c in procs) == 2


@pytest.mark.parametrize("moment", ["running", "starting"])
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_no_process_outlives_a_killed_parallel_sweep(tmp_path, sig, moment):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC, encoding="utf-8")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "dualfem", "bench", str(spec), "--jobs", "2", "--out", str(out),
                             "--no-progress-bar"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            if _ready(moment, session_processes(proc.pid)):
                time.sleep(1.0 if moment == "running" else 0.3)   # inside a task / still starting
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep finished before it could be killed"
        running = session_processes(proc.pid)
        if moment == "running":
            assert sum("harness --child" in c for _, c in running) == 2, running   # two guarded children
        assert sum("loky" in c.lower() for _, c in running) >= 2, running         # under two loky workers
        left = _left_after(proc, sig)                        # the sweep alone, not its group
        assert left == [], f"{len(left)} process(es) alive 5 s after {sig.name} of the sweep: {left}"
    finally:
        _reap(proc)


SPIN_SRC = '''
import sys, time
from dualfem.core.registry import register_solver
from dualfem.core.solver import Solver


@register_solver
class Spin(Solver):
    name = "hostile_spin"

    def solve(self):
        print("ready", file=sys.stderr, flush=True)
        while True:
            time.sleep(0.01)
'''


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_the_watchdogs_worker_dies_with_a_killed_solve(tmp_path, sig):
    """``dualfem solve`` runs the plugin in a worker process (issue 37, item 4): killing the command
    while its plugin runs leaves no worker behind (PR_SET_PDEATHSIG and a watch of the parent's pid)."""
    env = _plugin_env(tmp_path, "hostile_spin", SPIN_SRC)
    cmd = [sys.executable, "-m", "dualfem", "solve", "f1", "--set", "N=8", "--solver", "hostile_spin"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        for line in proc.stderr:
            if "ready" in line:
                break
        assert len(session_processes(proc.pid)) == 2, session_processes(proc.pid)   # the command and its worker
        left = _left_after(proc, sig)
        assert left == [], f"{len(left)} process(es) alive 5 s after {sig.name} of solve: {left}"
    finally:
        _reap(proc)


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


SPAWNER_SRC = '''
import os, subprocess, sys, time
from dualfem.core.registry import register_solver
from dualfem.core.solver import Solver


@register_solver
class Spawner(Solver):
    name = "hostile_spawner"
    defaults = {"tol": 1e-8, "time_limit": 1.0}

    def solve(self):
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        with open(os.environ["SPAWNER_PIDFILE"], "w") as fh:
            fh.write(str(child.pid))
        while True:
            time.sleep(0.05)
'''

SPAWNER_SPEC = """
name = "spawner"
repeats = 1
warmup = false
time_limit = 1
guard_slack = 0.5
[tiers]
low = 1e-3
[floor]
enabled = false
[[scenes]]
scene = ["f1"]
N = [8]
[[solvers]]
name = "hostile_spawner"
"""


def test_a_killed_bench_run_takes_the_processes_its_plugin_started_with_it(tmp_path):
    """bench's guard kills the guarded child's whole process group (issue 37, item 7): a plugin's own
    subprocess dies with the run killed at its time limit (before: it was left running)."""
    (tmp_path / "spec.toml").write_text(SPAWNER_SPEC)
    pidfile = tmp_path / "pid"
    env = _plugin_env(tmp_path, "hostile_spawner", SPAWNER_SRC, SPAWNER_PIDFILE=str(pidfile))
    r = subprocess.run([sys.executable, "-m", "dualfem", "bench", str(tmp_path / "spec.toml"), "--out",
                        str(tmp_path / "out"), "--no-progress-bar"], env=env, capture_output=True, text=True,
                       timeout=120, start_new_session=True)
    assert "time_limit" in r.stderr, r.stderr
    pid = int(pidfile.read_text())
    try:
        gone = time.monotonic() + 5.0
        while _alive(pid) and time.monotonic() < gone:
            time.sleep(0.1)
        assert not _alive(pid), "the plugin's subprocess outlived its run killed by bench's guard"
    finally:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
