"""The one experiment harness: guarded worker processes and the executors that feed them.

A task is a dict with a ``kind``. It runs in a long-lived child Python process
(:class:`GuardedWorker`) that the parent kills when a phase exceeds its wall-clock budget (the
child announces each phase and its budget), or that dies on its own (segmentation fault, out of
memory): the parent then makes an error row, never loses the task and never hangs (the protocol,
the budgets and the process hygiene of :mod:`dualfem.experiments.watchdog`, whose forked workers
guard ``solve`` and ``compare``; here long-lived children serve many tasks). Children
volunteer to the kernel's OOM killer, die with their parent (no orphans after ``kill -9`` or
SIGTERM of a sweep: PDEATHSIG and a watch of the parent's pid in every child, and in every loky
worker a watch of the sweep process, :func:`watch_parent`) and report their peak resident memory
with every row (``peak_rss_mb``).

The child dispatches on ``task["kind"]`` to the handlers in :data:`HANDLERS` (``bench`` runs,
references and floors; ``stress`` runs). Executors: the calling thread (``jobs = 1``),
joblib/loky (``jobs > 1``) or a dask.distributed scheduler; only the parent writes files. The one
scheduler that feeds them (task dependencies, gates, the results store) is
:func:`dualfem.experiments.bench.run_tasks`.
"""
from __future__ import annotations

import importlib
import os
import pickle
import select
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from dualfem.core.errors import describe_exception
from dualfem.experiments.watchdog import die_with_parent, kill_group, pid_alive, volunteer_for_oom_killer

#: task kind -> "module:function" of the handler ``(task, tick) -> (row dict, payload)``
HANDLERS = {
    "run": "dualfem.experiments.bench:execute",
    "reference": "dualfem.experiments.bench:execute",
    "floor": "dualfem.experiments.bench:execute",
    "stress": "dualfem.experiments.stress:execute_task",
}
#: budget of the first phase, before the child has announced one (start-up, imports)
START_BUDGET = 120.0

_MSG = struct.Struct("!Q")


# ------------------------------------------------------------------------ messages
def _send(fh, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    fh.write(_MSG.pack(len(data)) + data)
    fh.flush()


def _recv_blocking(fh) -> Any:
    head = fh.read(_MSG.size)
    if len(head) < _MSG.size:
        raise EOFError
    (n,) = _MSG.unpack(head)
    data = fh.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


# ---------------------------------------------------------------- process hygiene
def rss_mb(pid: int | str = "self") -> float:
    """Resident memory of a process in MB (Linux /proc; 0 elsewhere or if it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        return 0.0


#: guarded children started by this process (killed by :func:`watch_parent` when the sweep is gone)
_CHILDREN: set[subprocess.Popen] = set()
_WATCHING: int | None = None


def watch_parent(parent: int, interval: float = 0.1) -> None:
    """In an executor's worker process: exit as soon as the sweep process ``parent`` is gone.

    PR_SET_PDEATHSIG alone does not make a tree die with its root: it fires when the *thread*
    that forked a process exits, and a loky worker blocked in a task (waiting on its guarded
    child) never notices that the sweep was killed (docs/measurements.md). A daemon thread polls ``os.getppid()``
    (which changes when the parent process dies, whatever killed it), kills this worker's guarded
    children and exits; the children die with it in any case (their own PDEATHSIG and watch).
    Started once per process (later calls with the same parent are no-ops), at the worker's start
    (the executor's initializer, so that an idle worker or one still importing dies too) and again
    with every task. A worker whose ``parent`` is already gone exits at once (it never starts the
    task it was handed); one that is not a child of a live ``parent`` (another executor's topology)
    watches ``parent``'s pid instead of its own parent pid.
    """
    global _WATCHING
    if _WATCHING == parent:
        return
    if os.getppid() == parent:
        def alive() -> bool:
            return os.getppid() == parent
    elif pid_alive(parent):
        def alive() -> bool:
            return pid_alive(parent)
    else:                             # the sweep died before this worker got here
        os._exit(3)
    _WATCHING = parent

    def loop() -> None:
        while alive():
            time.sleep(interval)
        for proc in list(_CHILDREN):
            kill_group(proc)
        os._exit(3)

    threading.Thread(target=loop, name="dualfem-watch-parent", daemon=True).start()




def run_in_worker(task: dict, parent: int) -> tuple[dict, Any]:
    """:func:`run_guarded` in an executor's worker process that dies with the sweep ``parent``."""
    watch_parent(parent)
    return run_guarded(task)


class _PeakWatch:
    """Samples this process's RSS (peak since :meth:`reset`) and exits if the parent is gone."""

    def __init__(self, parent: int) -> None:
        self.peak = rss_mb()
        self.parent = parent
        threading.Thread(target=self._loop, daemon=True).start()

    def _loop(self) -> None:
        while True:
            if os.getppid() != self.parent:
                os._exit(3)
            self.peak = max(self.peak, rss_mb())
            time.sleep(0.1)

    def reset(self) -> None:
        self.peak = rss_mb()


# ---------------------------------------------------------------------- the child
def _handler(kind: str) -> Callable:
    mod, fn = HANDLERS[kind].split(":")
    return getattr(importlib.import_module(mod), fn)


def _child_main() -> None:  # pragma: no cover - runs in the child process
    """Serve tasks on stdin/stdout; anything written to fd 1 by C libraries is dropped."""
    die_with_parent()
    volunteer_for_oom_killer()
    os.environ.setdefault("MPLBACKEND", "Agg")
    # the parent that started us (not os.getppid() now: it may already be gone, and we reparented)
    watch = _PeakWatch(int(os.environ.get("DUALFEM_HARNESS_PARENT") or os.getppid()))
    out_fd = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)      # C libraries print to fd 1 (e.g. OSQP's polishing notes): drop it
    sys.stdout = sys.stderr
    out = os.fdopen(out_fd, "wb")
    inp = sys.stdin.buffer
    while True:
        try:
            task = _recv_blocking(inp)
        except EOFError:
            return
        watch.reset()
        try:
            row, payload = _handler(task["kind"])(task, lambda phase, budget: _send(out, ("phase", phase, budget)))
        except BaseException as exc:  # noqa: BLE001 - every failure becomes an error row
            row, payload = error_row(task, describe_exception(exc)), None
        row["peak_rss_mb"] = round(max(watch.peak, rss_mb()), 1)
        _send(out, ("done", row, payload))
        if not task.get("keep_cache"):
            import gc

            gc.collect()      # the task's QP took its factorizations with it: free any cycle too


def error_row(task: dict, message: str, status: str = "error") -> dict:
    """The row of a task that produced no result (``status`` error, time_limit, crashed, skipped)."""
    from dualfem.experiments.machine import utc_now
    from dualfem.experiments.row import Row
    from dualfem.verify.judge import outcome_without_answer

    row = Row(run_id=task.get("run_id", ""), kind=task.get("kind", "run"), status=status, claimed_status=None,
              message=message, started_utc=utc_now())
    for k in ("spec", "scene", "scene_key", "label", "solver", "variant", "tier", "tol", "repeats", "time_limit",
              "cold_setup", "axis", "coords", "scene_name"):
        if task.get(k) is not None:
            row[k] = task[k]
    row.solver_params = dict(task.get("params") or {})
    for k, v in (task.get("scene_params") or {}).items():     # as a finished run's row: the report groups by them
        row[f"scene_{k}"] = v
    row.grade = outcome_without_answer(status)
    return row.to_dict()


# --------------------------------------------------------------------- the parent
class GuardedWorker:
    """A child Python process that executes tasks; killed when a phase exceeds its budget.

    Blocking use: :meth:`run`. Non-blocking use (many workers, one loop): :meth:`submit`, then
    :meth:`poll` whenever :meth:`fileno` is readable or a deadline may have passed.
    """

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.buf = b""
        self.task: dict | None = None
        self.phase, self.budget, self.deadline = "start", START_BUDGET, 0.0

    # ---------------------------------------------------------------- lifecycle
    def _start(self) -> None:
        env = dict(os.environ)
        env.setdefault("MPLBACKEND", "Agg")
        env["DUALFEM_HARNESS_PARENT"] = str(os.getpid())     # the child exits when this process is gone
        from dualfem.numerics.la import current

        env.update(current().child_env())                    # the run's linear-algebra context (--factor)
        group = {"process_group": 0} if hasattr(os, "killpg") else {}    # its own group: killed with its children
        self.proc = subprocess.Popen([sys.executable, "-m", "dualfem.experiments.harness", "--child"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, bufsize=0, **group)
        _CHILDREN.add(self.proc)
        self.buf = b""

    def close(self) -> None:
        """Ask the child to exit (kill it if it does not within 5 s)."""
        if self.proc is not None:
            _CHILDREN.discard(self.proc)
            try:
                self.proc.stdin.close()
                self.proc.wait(timeout=5)
            except Exception:  # noqa: BLE001
                pass
            kill_group(self.proc)        # and whatever its tasks started and left running
            self.proc.wait()
            self.proc = None

    def kill(self) -> None:
        """Kill the child and every process it started (its group) now (its task is lost; the caller
        makes the error row)."""
        if self.proc is not None:
            _CHILDREN.discard(self.proc)
            kill_group(self.proc)
            self.proc.wait()
            self.proc = None

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    def fileno(self) -> int:
        return self.proc.stdout.fileno()

    # ---------------------------------------------------------------- protocol
    def _read(self, deadline: float) -> Any:
        fd = self.proc.stdout.fileno()
        while True:
            if len(self.buf) >= _MSG.size:
                (n,) = _MSG.unpack(self.buf[:_MSG.size])
                if len(self.buf) >= _MSG.size + n:
                    msg = pickle.loads(self.buf[_MSG.size:_MSG.size + n])
                    self.buf = self.buf[_MSG.size + n:]
                    return msg
            r, _, _ = select.select([fd], [], [], max(deadline - time.monotonic(), 0.0))
            if not r:
                raise TimeoutError
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                raise EOFError
            self.buf += chunk

    def submit(self, task: dict) -> None:
        """Send ``task`` to the child (started if needed)."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.task, self.phase, self.budget = task, "start", START_BUDGET
        self.deadline = time.monotonic() + self.budget
        _send(self.proc.stdin, task)

    def poll(self, wait: float = 0.0) -> tuple[dict, Any] | None:
        """(row, payload) once the submitted task is finished, killed or dead; None while it runs."""
        task = self.task
        try:
            while True:
                msg = self._read(min(time.monotonic() + wait, self.deadline))
                if msg[0] == "phase":
                    self.phase, self.budget = msg[1], float(msg[2])
                    self.deadline = time.monotonic() + self.budget
                elif msg[0] == "done":
                    self.task = None
                    return msg[1], msg[2]
        except TimeoutError:
            if time.monotonic() < self.deadline:
                return None
            self.kill()
            self.task = None
            return error_row(task, f"killed by the wall-clock guard: phase '{self.phase}' exceeded {self.budget:.0f} s",
                             status="time_limit"), None
        except (EOFError, BrokenPipeError, OSError):
            code = self.proc.poll() if self.proc else None
            self.kill()
            self.task = None
            why = " (killed: out of memory?)" if code == -9 else ""
            return error_row(task, f"worker process died in phase '{self.phase}' (exit code {code}{why})",
                             status="crashed"), None

    def run(self, task: dict) -> tuple[dict, Any]:
        """Execute ``task`` in the child and wait for its row."""
        try:
            self.submit(task)
        except (BrokenPipeError, OSError) as exc:
            self.kill()
            return error_row(task, f"cannot start the worker process: {exc}"), None
        while True:
            res = self.poll(wait=3600.0)
            if res is not None:
                return res


# ----------------------------------------------------------------------- executors
_LOCAL = threading.local()


def run_guarded(task: dict) -> tuple[dict, Any]:
    """Execute ``task`` in this thread's guarded child process (the function sent to executors)."""
    w = getattr(_LOCAL, "worker", None)
    if w is None:
        w = _LOCAL.worker = GuardedWorker()
    try:
        return w.run(task)
    except Exception as exc:  # noqa: BLE001 - never lose a task
        return error_row(task, describe_exception(exc)), None


def _close_local_worker(now: bool = False) -> None:
    """Close this thread's guarded child (``now``: kill it and its group, e.g. after Ctrl-C of the sweep:
    a child in its own process group does not see the terminal's SIGINT)."""
    w = getattr(_LOCAL, "worker", None)
    if w is not None:
        w.kill() if now else w.close()
        _LOCAL.worker = None


#: seconds to wait for a dask scheduler before refusing its address
DASK_CONNECT_TIMEOUT = 20.0


def _execute_dask(tasks: list[dict], address: str,
                  connect_timeout: float = DASK_CONNECT_TIMEOUT) -> Iterable[tuple[dict, Any]]:
    from dualfem.core.errors import InputError, MissingDependency

    try:
        from distributed import Client, as_completed
    except ImportError:
        raise MissingDependency("--dask needs dask.distributed: pip install 'dualfem[parallel]'") from None
    try:
        client = Client(address, timeout=f"{float(connect_timeout)}s")
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--dask: cannot connect to the scheduler at {address!r} within {connect_timeout:g} s: "
                         f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    except ValueError as exc:         # not an address at all (e.g. "tcp://host:port:x")
        raise InputError(f"--dask: {address!r} is not a scheduler address: {exc}") from None
    if not tasks:
        client.close()
        return
    try:
        futs = client.map(run_guarded, tasks, pure=False)
        for fut in as_completed(futs):
            try:
                yield fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker: record it
                yield error_row(tasks[futs.index(fut)], f"dask task failed: {type(exc).__name__}: {exc}"), None
    finally:
        client.close()


def check_dask(address: str, connect_timeout: float = DASK_CONNECT_TIMEOUT) -> None:
    """InputError (one line) unless a dask scheduler answers at ``address`` within ``connect_timeout`` s
    (called before a sweep writes anything)."""
    for _ in _execute_dask([], address, connect_timeout):
        pass


def execute_all(tasks: list[dict], jobs: int = 1, dask: str | None = None,
                connect_timeout: float = DASK_CONNECT_TIMEOUT) -> Iterable[tuple[dict, Any]]:
    """Yield (row, payload) for every task as it finishes (``connect_timeout``: seconds to wait for
    the ``dask`` scheduler)."""
    if not tasks:
        return
    if dask:
        yield from _execute_dask(tasks, dask, connect_timeout)
    elif jobs > 1:
        try:
            from joblib import Parallel, delayed
        except ImportError:
            from dualfem.core.errors import MissingDependency
            raise MissingDependency("--jobs needs joblib: pip install 'dualfem[parallel]'") from None
        me = os.getpid()          # each loky worker exits as soon as this process is gone, from its start
        par = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered", initializer=watch_parent,
                       initargs=(me,))
        yield from par(delayed(run_in_worker)(t, me) for t in tasks)
    else:
        try:
            for t in tasks:
                yield run_guarded(t)
        except BaseException:
            _close_local_worker(now=True)
            raise
        finally:
            _close_local_worker()


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] == ["--child"]:
        _child_main()
    else:
        print("usage: python -m dualfem.experiments.harness --child (internal)", file=sys.stderr)
        sys.exit(2)
