"""Modules split for size (issue 34, item 8) keep their old import paths: the names are the same objects."""
from __future__ import annotations

import pytest


@pytest.mark.parametrize("name", ["read_results", "read_results_checked", "write_csv", "write_parquet",
                                  "check_report_input", "TEXT_COLUMNS", "REPORT_COLUMNS"])
def test_results_file_names_stay_importable_from_the_store(name):
    from dualfem.experiments import results_csv, store

    assert getattr(store, name) is getattr(results_csv, name)


def test_parallel_rows_stays_importable_from_the_certificate():
    from dualfem.numerics import certify, dependent_rows

    assert certify.parallel_rows is dependent_rows.parallel_rows


def test_the_store_reads_back_what_it_writes(tmp_path):
    """The split store and results file together: a row written through the store's old path is read back."""
    from dualfem.experiments.store import read_results, write_csv

    write_csv(tmp_path / "results.csv", [{"run_id": "a1", "kind": "run", "status": "solved", "total_s": 0.5}])
    (row,) = read_results(tmp_path)
    assert (row["run_id"], row["kind"], row["status"], row["total_s"]) == ("a1", "run", "solved", 0.5)
