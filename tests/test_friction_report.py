"""``dualfem report friction`` (dualfem/reports/friction.py): a one-case study renders its tables and the 2D figure,
re-renders from its JSON, and a file that is not a friction study is refused with one line."""
from __future__ import annotations

import json

import pytest

from dualfem.cli.main import main

pytest.importorskip("gmsh")
pytest.importorskip("clarabel")


@pytest.mark.slow
def test_one_case_study_renders_and_rerenders(tmp_path):
    from dualfem.core.io import dumps
    from dualfem.experiments.friction import study
    from dualfem.reports.friction import render

    res = study(levels_2d=((0.05, 0.004),), angles=(30.0,), cases_2d=(("tresca", 0.1),), levels_3d=(),
                cases_3d=())
    (tmp_path / "friction.json").write_text(dumps(res))
    md = render(res, tmp_path).read_text()
    assert "| 30 | Tresca g = 0.1 | 0.800 | 0.346 | 0.100 | 11, 7.63% |" in md
    assert (tmp_path / "friction_2d.png").exists() and "7 of 7 nodes stick" in md
    assert main(["report", "friction", "--from-json", str(tmp_path / "friction.json"), "--out",
                 str(tmp_path / "again")]) == 0
    assert (tmp_path / "again" / "friction.md").read_text() == md
    # --compare on a stored study: the solvers' table alone, stored beside the re-rendered page
    assert main(["report", "friction", "--from-json", str(tmp_path / "friction.json"), "--compare", "osqp",
                 "--out", str(tmp_path / "cmp")]) == 0
    page = (tmp_path / "cmp" / "friction.md").read_text()
    assert "| 2D tresca g=0.1 | osqp | solved |" in page and "| 3D tresca g=0.2 | osqp | skipped: " in page
    assert json.loads((tmp_path / "cmp" / "friction.json").read_text())["compare"]
    again = study(levels_2d=((0.05, 0.004),), angles=(30.0,), cases_2d=(("tresca", 0.1),), levels_3d=(),
                  cases_3d=(), resume=res)                  # --resume: the stored rows are kept, not solved again
    assert again["inclined"][0] is res["inclined"][0] and again["stuck"] is res["stuck"]


def test_a_file_that_is_not_a_study_is_refused(tmp_path, capsys):
    bad = tmp_path / "x.json"
    bad.write_text(json.dumps({"solver": "clarabel"}))
    assert main(["report", "friction", "--from-json", str(bad), "--out", str(tmp_path)]) != 0
    assert "not a friction.json" in capsys.readouterr().err
