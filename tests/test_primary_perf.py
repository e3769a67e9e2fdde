"""benchmarks/primary_perf.py: its target follows the bench's rule, and --render-only re-renders from the data."""
from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def pp():
    spec = importlib.util.spec_from_file_location("primary_perf", REPO / "benchmarks" / "primary_perf.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(method, delta, status="solved", ratio=0.8, error=1e-10):
    return {"N": 64, "ndof": 8382, "delta": delta, "method": method, "time_s": ratio * 0.02, "floor_s": 0.02,
            "ratio": ratio, "assembly_s": 0.01, "end_to_end_s": ratio * 0.02 + 0.01, "status": status,
            "iterations": {"outer": 5, "inner": 9}, "setup_s": 0.01, "solve_s": 0.002, "error": error,
            "repeats": 3, "certified": True, "process_peak_rss_mb": 130.0}


def _verdict(pp, rows, method):
    line = next(x for x in pp.target_lines(rows, 64) if x.startswith(f"* `{method}`"))
    return line.split(": ", 1)[1].split(" (", 1)[0]


def test_a_run_not_certified_solved_never_meets_the_target(pp):
    rows = [_row("uzawa", 1e-1), _row("uzawa", 1e-9, status="inaccurate", ratio=0.5, error=2e-7),
            _row("pdas", 1e-1), _row("pdas", 1e-9),
            _row("uzawa_auto", 1e-1), _row("uzawa_auto", 1e-9, error=5e-8)]
    assert _verdict(pp, rows, "uzawa") == "NOT met"          # fast, but inaccurate
    assert _verdict(pp, rows, "pdas") == "met"
    assert _verdict(pp, rows, "uzawa_auto") == "NOT met"     # solved, but error above ERR_TARGET
    slow = [_row("pdas", 1e-1, ratio=pp.FLOOR_TARGET * 1.01)]
    assert _verdict(pp, slow, "pdas") == "NOT met"


def test_render_only_reads_back_what_a_run_wrote(pp, tmp_path):
    rows = [_row("uzawa", 1e-1), _row("pdas", 1e-9, status="inaccurate", error=3e-7)]
    out = tmp_path / "perf.md"
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    info = {"cpu": "test cpu", "cores": 2}
    meta = {"machine": info, "load": [1.5, 2.5], "elapsed_s": 90.0, "command": "benchmarks/primary_perf.py --x"}
    out.with_suffix(".json").write_text(json.dumps(meta))
    assert pp._read_rows(out.with_suffix(".csv")) == rows
    assert pp.render_only(out) == 0
    text = out.read_text()
    assert text.startswith(pp.render(rows, info, (1.5,), (2.5,), 90.0, meta["command"]).split("\n\n")[0])
    assert "Re-rendered from" in text and "* `pdas`: NOT met" in text and pp.BELOW_FLOOR in text


def test_render_only_recovers_the_facts_from_an_old_header(pp, tmp_path):
    rows = [_row("uzawa", 1e-1)]
    out = tmp_path / "perf.md"
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    out.write_text(pp.render(rows, {"cpu": "AMD EPYC", "cores": 2}, (2.2,), (1.4,), 756.0, "benchmarks/p.py --force"))
    pp.render_only(out)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta == {"machine": {"cpu": "AMD EPYC", "cores": "2"}, "load": [2.2, 1.4], "elapsed_s": 756.0,
                    "command": "benchmarks/p.py --force"}
    out.with_suffix(".json").unlink()
    out.write_text("no header")
    with pytest.raises(pp.InputError, match="--render-only needs"):
        pp.render_only(out)
