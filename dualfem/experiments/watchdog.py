"""A guaranteed wall-clock limit for plugin code: a call runs in a worker process that is killed when
a phase outlives its budget.

The mechanism of every command that runs plugin code (``solve`` and ``compare`` through
:func:`guarded_call`, ``bench`` and ``stress`` through :class:`dualfem.experiments.harness.GuardedWorker`,
whose long-lived children speak the same protocol): the worker announces each phase and its budget
(``("phase", name, seconds)``); the parent waits on the pipe and, when a phase runs past its budget,
kills the worker (its whole process group: a plugin's own subprocesses too) and reports
``time_limit`` with the phase; a worker that dies (segmentation fault, out of memory) is reported
``crashed``, never a hang. The budget of a phase whose own limit is ``time_limit`` seconds is
:func:`budget` = ``time_limit * GUARD_FACTOR + GUARD_SLACK`` (the grace period; the defaults of a
bench spec's ``guard_factor`` and ``guard_slack``).

Start method: ``fork`` where the platform has it (Linux, macOS): the worker shares the parent's
memory copy-on-write, so nothing (a QP, a registered plugin class, a test's monkeypatch) is copied
or pickled on the way in; only the result and the worker's ``print`` output (forwarded to the
parent's ``sys.stdout``/``sys.stderr``) come back through the pipe. Callers fork before any
numerical library has started thread pools (``solve`` and ``compare`` fork before building the QP,
and the worker builds it). Where there is no ``fork`` (Windows), ``spawn``: the function and its
arguments are pickled (``solve`` and ``compare`` send the scene description and the solver objects,
not the QP) and the worker re-imports dualfem and its plugins (a solver registered at run time
in the calling process, not through an entry point, is unknown there).

No orphans: the worker dies with the parent (Linux ``PR_SET_PDEATHSIG`` plus a thread polling the
parent's pid, for SIGKILL of the parent) and is killed in a ``finally`` (Ctrl-C, exceptions).
"""
from __future__ import annotations

import gc
import io
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: budget of a phase = its own time limit x GUARD_FACTOR + GUARD_SLACK seconds
GUARD_FACTOR = 1.5
GUARD_SLACK = 10.0
#: the time limit (seconds) of a solver that has no ``time_limit`` parameter
DEFAULT_TIME_LIMIT = 600.0


def budget(time_limit: float) -> float:
    """Wall-clock budget (seconds) of a phase whose own limit is ``time_limit`` seconds."""
    return float(time_limit) * GUARD_FACTOR + GUARD_SLACK


def time_limit_of(solver: Any) -> float:
    """The solver's ``time_limit`` parameter (seconds) when it is a finite number > 0, else
    :data:`DEFAULT_TIME_LIMIT`."""
    params = getattr(solver, "params", None)
    v = params.get("time_limit") if isinstance(params, dict) else None
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
        return float(v)
    return DEFAULT_TIME_LIMIT


def limit_text(phase: str, seconds: float, time_limit: float) -> str:
    """The message of a worker killed in ``phase`` after ``seconds`` (budget of ``time_limit``)."""
    return (f"killed by the watchdog: phase '{phase}' ran past its budget of {seconds:.0f} s (time_limit "
            f"{time_limit:g} s x {GUARD_FACTOR:g} + {GUARD_SLACK:g} s grace)")


@dataclass
class Outcome:
    """What a guarded call gave: ``status`` ``done`` (``value`` is its return value), ``time_limit``
    (killed in ``phase`` after its ``budget``) or ``crashed`` (the worker died: ``message``);
    ``parts``: what the worker sent with :meth:`Guard.send` before the end; ``elapsed``: seconds."""

    status: str
    value: Any = None
    phase: str = ""
    budget: float = 0.0
    message: str = ""
    parts: list = field(default_factory=list)
    elapsed: float = 0.0


class Guard:
    """The worker's side: announce phases, send partial results."""

    def __init__(self, conn: Any, lock: threading.Lock) -> None:
        self._conn, self._lock = conn, lock

    def _put(self, msg: tuple) -> None:
        with self._lock:
            self._conn.send(msg)

    def phase(self, name: str, seconds: float) -> None:
        """Start phase ``name`` with a budget of ``seconds`` (the clock restarts now)."""
        self._put(("phase", str(name), float(seconds)))

    def send(self, obj: Any) -> None:
        """A partial result (kept by the parent even if the worker is killed later)."""
        self._put(("part", obj))


class _InlineGuard:
    """The in-process stand-in of :class:`Guard` (see :func:`fork_is_unsafe`): phases are recorded in the
    outcome, not enforced; partial results go to ``on_part`` at once."""

    def __init__(self, out: Outcome, on_part: Callable[[Any], None] | None) -> None:
        self._out, self._on_part = out, on_part

    def phase(self, name: str, seconds: float) -> None:
        self._out.phase, self._out.budget = str(name), float(seconds)

    def send(self, obj: Any) -> None:
        self._out.parts.append(obj)
        if self._on_part is not None:
            self._on_part(obj)


def fork_is_unsafe() -> bool:
    """Whether this process has already run MKL PARDISO (its OpenMP thread pool): a process forked
    from it hangs in its first PARDISO call (the pool's threads and locks do not survive a fork).
    A fresh ``dualfem`` command never has (it forks before building the QP); a Python session that
    solved before calling :func:`dualfem.cli.main` may have."""
    mod = sys.modules.get("dualfem.numerics.factor.pardiso")
    return bool(getattr(mod, "STARTED", False))



class _Forward(io.TextIOBase):
    """``sys.stdout``/``sys.stderr`` of the worker: text goes to the parent's stream of the same name;
    ``fileno`` is the original descriptor (fd-level redirections of C output keep working)."""

    encoding = "utf-8"

    def __init__(self, guard: Guard, name: str, original: Any) -> None:
        super().__init__()
        self._guard, self._name, self._original = guard, name, original

    def writable(self) -> bool:
        return True

    def write(self, s: str) -> int:
        if s:
            self._guard._put(("out", self._name, str(s)))
        return len(s)

    def fileno(self) -> int:
        if self._original is None:
            raise io.UnsupportedOperation("no descriptor")
        return self._original.fileno()


# ---------------------------------------------------------------- process hygiene (harness workers too)
def volunteer_for_oom_killer() -> None:
    """Make this process the kernel's first choice when memory runs out (Linux; no-op elsewhere).

    A run that exhausts a shared machine's memory should lose its own worker, which the sweep
    records as a failed run, not the sweep's parent process or someone else's job.
    """
    try:
        with open("/proc/self/oom_score_adj", "w") as fh:
            fh.write("1000")
    except OSError:
        pass


def die_with_parent() -> None:
    """Ask the kernel to kill this process when its parent dies (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)      # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (and is not a zombie: a killed parent not yet reaped)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def _context() -> Any:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else "spawn")


def _child(conn: Any, fn: Callable, args: tuple, parent: int) -> None:  # pragma: no cover - in the worker
    if hasattr(os, "setpgid"):
        try:
            os.setpgid(0, 0)          # its own group: killed with everything it starts
        except OSError:
            pass
    die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # Ctrl-C is the parent's: it kills this worker

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(3)

    threading.Thread(target=watch, name="dualfem-watchdog-parent", daemon=True).start()
    guard = Guard(conn, threading.Lock())
    sys.stdout = _Forward(guard, "stdout", sys.__stdout__)
    sys.stderr = _Forward(guard, "stderr", sys.__stderr__)
    try:
        msg: tuple = ("done", fn(guard, *args))
    except BaseException as exc:  # noqa: BLE001 - the parent re-raises it
        import traceback

        try:                          # the worker's traceback travels with it (shown if nothing catches it)
            exc.add_note("raised in the watchdog's worker process:\n" + "".join(traceback.format_tb(exc.__traceback__)))
        except Exception:  # noqa: BLE001
            pass
        msg = ("raised", exc)
    try:
        guard._put(msg)
    except Exception as exc:  # noqa: BLE001 - an unpicklable result or exception
        guard._put(("raised", RuntimeError(f"the worker's {msg[0]} result could not be sent back: "
                                           f"{type(exc).__name__}: {exc}")))
    conn.close()


def kill_group(proc: Any) -> None:
    """SIGKILL a worker's process group (the worker leads it: a plugin's own subprocesses go too) and the
    worker itself; ``proc``: a ``subprocess.Popen`` or a ``multiprocessing`` process (not started: a no-op)."""
    if proc.pid is not None and hasattr(os, "killpg"):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
    try:
        proc.kill()
    except (OSError, AttributeError, ValueError):
        pass


def _kill(proc: Any) -> None:
    """Kill the worker and its process group; reap it."""
    kill_group(proc)
    proc.join(5.0)


def _inline_call(fn: Callable, args: tuple, phase: str, seconds: float,
                 on_part: Callable[[Any], None] | None) -> Outcome:
    """``fn`` in this process, its phases recorded but not enforced (a fork would hang: see
    :func:`fork_is_unsafe`); said by a RuntimeWarning."""
    import warnings

    # a warning (shown once per process by Python's default filter), not a line on stderr: a command's errors
    # stay one line
    warnings.warn("this process has run MKL PARDISO, which a forked worker cannot use: plugin code runs in "
                  "this process and its time limit is not enforced by the watchdog", RuntimeWarning, stacklevel=3)
    t0 = time.monotonic()
    out = Outcome(status="running", phase=phase, budget=float(seconds))
    try:
        out.value = fn(_InlineGuard(out, on_part), *args)
        out.status = "done"
    finally:
        out.elapsed = time.monotonic() - t0
    return out


def guarded_call(fn: Callable, *args: Any, phase: str, seconds: float,
                 on_part: Callable[[Any], None] | None = None) -> Outcome:
    """``fn(guard, *args)`` in a worker process; the first phase is ``phase`` with a budget of ``seconds``.

    ``fn`` announces later phases with ``guard.phase(name, seconds)`` and may send partial results
    with ``guard.send(obj)`` (passed to ``on_part`` and kept in ``Outcome.parts``). An exception
    raised by ``fn`` is raised here (its traceback stays in the worker). The worker is gone when
    this returns or raises, whatever happened (killed at its budget, Ctrl-C of the parent). In a process
    that has already run MKL PARDISO (:func:`fork_is_unsafe`), ``fn`` runs in this process instead.
    """
    ctx = _context()
    if ctx.get_start_method() == "fork" and fork_is_unsafe():
        return _inline_call(fn, args, phase, seconds, on_part)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()            # a forked worker must not inherit (and repeat) unwritten output
        except (OSError, ValueError, AttributeError):
            pass
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, os.getpid()), name="dualfem-watchdog")
    t0 = time.monotonic()
    out = Outcome(status="running", phase=phase, budget=float(seconds))
    try:
        gc.freeze()                   # the worker's collections do not touch (and copy) the parent's objects
        try:
            proc.start()
        finally:
            gc.unfreeze()
        if hasattr(os, "setpgid"):
            try:
                os.setpgid(proc.pid, proc.pid)        # at once, so that a kill cannot miss the group
            except OSError:
                pass
        send.close()
        deadline = t0 + out.budget
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                out.status = "time_limit"
                break
            if not recv.poll(min(left, 1.0)):
                continue
            try:
                msg = recv.recv()
            except (EOFError, OSError):
                proc.join(1.0)
                code = proc.exitcode
                why = " (killed: out of memory?)" if code == -signal.SIGKILL else ""
                out.status = "crashed"
                out.message = f"worker process died in phase '{out.phase}' (exit code {code}{why})"
                break
            except Exception as exc:  # noqa: BLE001 - e.g. an exception class the parent cannot unpickle
                out.status = "crashed"
                out.message = (f"the worker's answer in phase '{out.phase}' could not be read: "
                               f"{type(exc).__name__}: {exc}")
                break
            if msg[0] == "phase":
                out.phase, out.budget = msg[1], msg[2]
                deadline = time.monotonic() + out.budget
            elif msg[0] == "out":
                stream = sys.stdout if msg[1] == "stdout" else sys.stderr
                stream.write(msg[2])
                stream.flush()
            elif msg[0] == "part":
                out.parts.append(msg[1])
                if on_part is not None:
                    on_part(msg[1])
            elif msg[0] == "done":
                out.status, out.value = "done", msg[1]
                break
            else:                      # "raised"
                raise msg[1]
    finally:
        _kill(proc)
        recv.close()
        out.elapsed = time.monotonic() - t0
    return out
