"""Run the bad-input corpus (``tests/bad_inputs``): every case refused cleanly or answered correctly.

Each case runs ``dualfem`` (in this process through the command line's entry point, which the
caller passes in as ``main``: ``dualfem.cli.main.main``, since experiments do not import the cli;
or as a real subprocess) in a scratch folder and is classified (see tests/bad_inputs/README.md): ``refused``
(exit 2, one ``dualfem CMD: error:`` line with the expected words, nothing written),
``answered`` (exit 0/1, no traceback, the expected JSON), ``silent_wrong``, ``traceback``,
``data_lost``, ``wrote_on_refusal``, ``hang`` or ``wrong_refusal``.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dualfem.core.errors import InputError
from dualfem.core.scene import DEFAULT_SCENE, load_scene

#: outcome classes, in report order; only the first two are acceptable
OUTCOMES = ("refused", "answered", "silent_wrong", "traceback", "data_lost", "wrote_on_refusal", "hang",
            "wrong_refusal")


# ------------------------------------------------------------------------ crafted files
def _export(d: Path, **extra) -> None:

    qp = load_scene(DEFAULT_SCENE, {"N": 8}).build()
    data = {**qp.to_dict(), **extra}
    np.savez(d / "qp.npz", **data)


def _float_indices(d: Path) -> None:

    data = load_scene(DEFAULT_SCENE, {"N": 8}).build().to_dict()
    data["K_row"] = data["K_row"].astype(float) + 0.5
    np.savez(d / "qp.npz", **data)


def _huge_shape(d: Path) -> None:
    np.savez(d / "qp.npz", K_row=np.array([0]), K_col=np.array([0]), K_data=np.array([1.0]),
             K_shape=np.array([10**9, 10**9]), B_row=np.array([0]), B_col=np.array([0]), B_data=np.array([1.0]),
             B_shape=np.array([1, 10**9]), F=np.zeros(1))


def _shifted_qp(d: Path) -> None:
    # min 1/2 x^2  s.t.  x >= 1  (qpsolvers' G x <= h with G = -1, h = -1): solution x = 1, objective 0.5
    np.savez(d / "qp.npz", P=np.array([[1.0]]), q=np.array([0.0]), G=np.array([[-1.0]]), h=np.array([-1.0]))


def _bad_nu_export(d: Path) -> None:
    _export(d, param_nu=np.array(0.7))


def _foreign_results(d: Path) -> None:
    res = d / "res"
    res.mkdir()
    (res / "spec.toml").write_text('name = "someone_else"\n')
    (res / "results.csv").write_text("run_id,kind,status\nabc,run,solved\n")


def _old_grid(d: Path) -> None:
    (d / "grid").mkdir()
    (d / "grid" / "runs.jsonl").write_text('{"axis": "nu", "outcome": "correct", "solver": "pdas"}\n')


def _foreign_csv(d: Path) -> None:
    (d / "foreign.csv").write_text("name,age\nada,36\n")


def _a_directory(d: Path) -> None:
    (d / "adir").mkdir()


def _a_file(d: Path) -> None:
    (d / "afile").write_text("not a folder\n")


def _unrelated_h5(d: Path) -> None:
    (d / "out.h5").write_bytes(b"someone's HDF5 data")


def _fifos(d: Path) -> None:
    """Named pipes where a QP file, a scene file, a JSON file and a results folder's files are expected
    (opening one blocks until a writer comes: they must be refused by ``stat`` alone)."""
    for name in ("p.npz", "s.toml", "c.json"):
        os.mkfifo(d / name)
    (d / "res" / "rows").mkdir(parents=True)
    os.mkfifo(d / "res" / "results.csv")
    (d / "rows_fifo" / "rows").mkdir(parents=True)
    os.mkfifo(d / "rows_fifo" / "rows" / "abc.json")


def _minimal_results(d: Path) -> None:
    (d / "res").mkdir()
    (d / "res" / "results.csv").write_text("run_id,kind,status\nabc,run,solved\n")


def _convergence_jsons(d: Path) -> None:
    (d / "empty.json").write_text("{}\n")
    (d / "list.json").write_text("[]\n")
    (d / "no_levels.json").write_text(json.dumps({"scene": "f2", "solver": "pdas", "ref_N": 8, "Ns": [2],
                                                  "deltas": {"0.1": {"levels": [], "reference": {}}}, "time_s": 1}))


def _stress_meta_list(d: Path) -> None:
    """A stress folder whose meta.json is valid JSON but not an object (a hand edit, a foreign tool)."""
    (d / "grid").mkdir()
    (d / "grid" / "results.csv").write_text("run_id,kind,status,axis\nabc,stress,solved,N\n")
    (d / "grid" / "meta.json").write_text("[1, 2]\n")


def _folder_as_results_csv(d: Path) -> None:
    (d / "res" / "results.csv").mkdir(parents=True)


def _uncracked_scenes(d: Path) -> None:
    (d / "plate.toml").write_text("# no defect at all\nN = 8\ndefects = []\n")
    (d / "box.toml").write_text("# no defect at all, 3D\ndim = 3\nN = 3\ndefects = []\n")




MAKERS: dict[str, Callable[[Path], None]] = {
    "float_indices": _float_indices, "huge_shape": _huge_shape, "shifted_qp": _shifted_qp,
    "bad_nu_export": _bad_nu_export, "foreign_results": _foreign_results, "old_grid": _old_grid,
    "foreign_csv": _foreign_csv, "a_directory": _a_directory, "a_file": _a_file, "unrelated_h5": _unrelated_h5,
    "fifos": _fifos, "minimal_results": _minimal_results, "convergence_jsons": _convergence_jsons,
    "stress_meta_list": _stress_meta_list, "folder_as_results_csv": _folder_as_results_csv,
    "uncracked_scenes": _uncracked_scenes,
}


# ------------------------------------------------------------------------ running a case
def load_cases(corpus: Path) -> list[dict]:
    """The cases of ``corpus/cases.toml`` and then of every ``corpus/cases_*.toml`` (sorted; one file per
    class of attack keeps additions apart); two cases with one name are refused."""
    out: list[dict] = []
    for f in [corpus / "cases.toml", *sorted(corpus.glob("cases_*.toml"))]:
        if f.is_file():
            out += list(tomllib.loads(f.read_text(encoding="utf-8")).get("case", []))
    names = [c.get("name") for c in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"the corpus {str(corpus)!r} names two cases {dup[0]!r}")
    return out


def _snapshot(d: Path) -> dict[str, str]:
    out = {}
    for p in sorted(d.rglob("*")):
        if p.is_file():
            try:
                out[str(p.relative_to(d))] = hashlib.sha1(p.read_bytes()).hexdigest()
            except OSError:
                out[str(p.relative_to(d))] = "unreadable"
    return out


class _Timeout(Exception):
    pass


Main = Callable[[list[str]], int]


def _in_process(main: Main, argv: list[str], timeout: float) -> tuple[int | None, str, str, str]:
    """(exit code, stdout, stderr, traceback text) of ``dualfem ARGV`` run in this process by ``main``."""
    out, err = io.StringIO(), io.StringIO()

    def alarm(*_):
        raise _Timeout

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    tb = ""
    rc: int | None = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(argv)
    except _Timeout:
        rc = None
    except BaseException:  # noqa: BLE001 - an uncaught exception is exactly what we look for
        tb = traceback.format_exc()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return rc, out.getvalue(), err.getvalue(), tb


def _as_subprocess(argv: list[str], timeout: float, close_early: bool) -> tuple[int | None, str, str, str]:
    cmd = [sys.executable, "-m", "dualfem", *argv]
    env = dict(os.environ, MPLBACKEND="Agg")
    if close_early:       # like `dualfem ... | head -c 1`
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        p.stdout.read(1)
        p.stdout.close()
        try:
            _, err = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            return None, "", "", ""
        e = err.decode(errors="replace")
        return p.returncode, "", e, e if "Traceback" in e else ""
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return None, "", "", ""
    return r.returncode, r.stdout, r.stderr, r.stderr if "Traceback" in r.stderr else ""


def run_case(case: dict, corpus: Path, main: Main) -> dict:
    """Run one case in a fresh scratch folder; its record (``outcome`` one of :data:`OUTCOMES`).
    ``main``: the ``dualfem`` entry point (``argv -> exit code``) that runs an in-process case."""
    with tempfile.TemporaryDirectory(prefix="dualfem-bad-") as tmp:
        d = Path(tmp)
        if case.get("make"):
            MAKERS[case["make"]](d)
        for f in case.get("files", []):
            shutil.copy(corpus / f, d / Path(f).name)
        before = _snapshot(d)
        argv = [a.replace("{dir}", str(d)).replace("{corpus}", str(corpus)) for a in case["argv"]]
        cwd = os.getcwd()
        os.chdir(d)               # anything written without a path lands here and is seen
        t0 = time.perf_counter()
        try:
            if case.get("subprocess"):
                rc, out, err, tb = _as_subprocess(argv, case.get("timeout", 60), case.get("close_stdout_early", False))
            else:
                rc, out, err, tb = _in_process(main, argv, case.get("timeout", 60))
        finally:
            os.chdir(cwd)
        after = _snapshot(d)
        rec = {"class": case["class"], "name": case["name"], "argv": argv, "exit": rc, "seconds":
               round(time.perf_counter() - t0, 2), "stderr": err.strip()[-400:], "open": case.get("open", "")}
        rec["outcome"], rec["why"] = _classify(case, rc, out, err, tb, before, after)
        return _anonymous(rec, d, corpus)


def _anonymous(rec: dict, scratch: Path, corpus: Path) -> dict:
    """The record with the paths of this machine (the scratch folder, the corpus) written as ``{dir}`` and
    ``{corpus}``, as in the case's argv: a committed report names no folder of its author's machine."""
    subs = sorted({(str(p), tag) for base, tag in ((scratch, "{dir}"), (corpus, "{corpus}"))
                   for p in (base, base.resolve())}, key=lambda s: -len(s[0]))

    def clean(v):
        if isinstance(v, str):
            for path, tag in subs:
                v = v.replace(path, tag)
            return v
        return [clean(x) for x in v] if isinstance(v, list) else v

    return {k: clean(v) for k, v in rec.items()}


def _classify(case: dict, rc, out: str, err: str, tb: str, before: dict, after: dict) -> tuple[str, str]:
    if rc is None and not tb:
        return "hang", f"no answer within {case.get('timeout', 60)} s"
    if tb or "Traceback" in err:
        return "traceback", (tb or err).strip().splitlines()[-1][:200]
    lost = [f for f in before if f not in after or before[f] != after[f]]
    if lost:
        return "data_lost", f"changed or removed: {', '.join(lost)}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if case["expect"] == "refused":
        if rc != 2:
            return ("silent_wrong" if rc == 0 else "wrong_refusal"), f"exit {rc}, expected a refusal (exit 2)"
        if set(after) - set(before):
            return "wrote_on_refusal", f"wrote {', '.join(sorted(set(after) - set(before)))}"
        if len(lines) != 1 or not re.match(r"dualfem (report )?\S+: error: ", lines[0]):
            return "wrong_refusal", f"stderr is not one error line: {lines[:3]}"
        missing = [n for n in case.get("needles", []) if not re.search(n, lines[0], flags=re.I)]
        if missing:
            return "wrong_refusal", f"the message lacks {missing}: {lines[0][:200]}"
        return "refused", lines[0][:200]
    if rc == 2:
        return "wrong_refusal", f"refused a valid input: {lines[-1][:200] if lines else ''}"
    if rc not in (0, 1) and not case.get("close_stdout_early"):
        return "wrong_refusal", f"exit {rc}"
    return _check_answer(case, out)


def _check_answer(case: dict, out: str) -> tuple[str, str]:
    if not any(k in case for k in ("json_status", "json_energy", "finite_residuals", "json_defect_nodes")):
        return "answered", "no traceback, exit 0/1"
    try:
        rec = json.loads(out)
    except ValueError:
        return "silent_wrong", "stdout is not one JSON object"
    if "json_status" in case and rec.get("status") not in case["json_status"]:
        return "silent_wrong", f"status {rec.get('status')}, expected one of {case['json_status']}"
    if "json_defect_nodes" in case and rec.get("n_defect_nodes") != case["json_defect_nodes"]:
        return "silent_wrong", f"{rec.get('n_defect_nodes')} defect nodes, the scene has {case['json_defect_nodes']}"
    want = case.get("json_energy")
    got = rec.get("energy")
    if want is not None and not (got is not None and abs(got - want) <= 1e-8 * max(1, abs(want))):
        return "silent_wrong", f"energy {rec.get('energy')}, the file's objective is {case['json_energy']}"
    if case.get("finite_residuals") and not (rec.get("residuals") and all(
            v is not None and np.isfinite(v) for v in rec["residuals"].values())):
        return "silent_wrong", f"residuals {rec.get('residuals')}"
    return "answered", f"status {rec.get('status')}"


def run_corpus(corpus: Path, main: Main, progress: Callable[[str], None] | None = None) -> list[dict]:
    """Run every case of the corpus with the entry point ``main``; their records in file order."""
    corpus = Path(corpus).resolve()
    recs = []
    for case in load_cases(corpus):
        rec = run_case(case, corpus, main)
        recs.append(rec)
        if progress:
            progress(f"{rec['class']:8s} {rec['outcome']:16s} {rec['name']}")
    return recs
