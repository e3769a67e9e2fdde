"""The bad-input corpus tests/bad_inputs (issue: trust nothing, lose nothing): every case is
refused cleanly or answered correctly, and nothing a user had is changed.

A case marked ``open`` is a known failure, listed in reports/robustness.md: it must still fail
(so the marker is removed the day it is fixed), and it never counts as passing.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from dualfem.cli.main import main
from dualfem.experiments.robustness import load_cases, run_case

CORPUS = Path(__file__).parent / "bad_inputs"
CASES = load_cases(CORPUS)


def test_corpus_covers_every_class():
    classes = {c["class"] for c in CASES}
    assert {"scene", "qp", "spec", "results", "output", "cli"} <= classes
    assert len(CASES) >= 25


@pytest.mark.parametrize("case", CASES, ids=[f"{c['class']}: {c['name']}" for c in CASES])
def test_case(case):
    rec = run_case(case, CORPUS, main)
    if case.get("open"):
        assert rec["outcome"] not in ("refused", "answered"), \
            f"open case now passes ({rec['why']}): remove its 'open' marker in cases.toml"
        return
    assert rec["outcome"] in ("refused", "answered"), f"{rec['outcome']}: {rec['why']}"
    assert rec["outcome"] == case["expect"], rec
