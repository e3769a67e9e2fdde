"""``dualfem report plugins`` (small sizes): the report and its figure are written."""

import pytest

from dualfem.cli.main import main
from dualfem.cli.reports.plugins import run as report
from dualfem.core.errors import InputError


def test_report_plugins_small(tmp_path):
    out = tmp_path / "rep"
    assert main(["report", "plugins", "--", "--N", "8", "--sizes", "8", "--out", str(out), "--dpi", "40"]) == 0
    text = (out / "plugins.md").read_text()
    png = out / "figures" / "plugins_signorini.png"
    assert png.is_file() and png.stat().st_size > 5000
    assert "| dual_gradient | solved |" in text and "figures/plugins_signorini.png" in text
    # the flat-foundation rows show errors at round-off level
    flat = [ln for ln in text.splitlines() if ln.startswith("| 8 | strain |")]
    assert flat and float(flat[0].split("|")[4]) < 1e-10


@pytest.mark.parametrize("argv", [["--sizes", "10"], ["--sizes", "a,b"], ["--N", "2"]])
def test_report_plugins_bad_args(argv, tmp_path):
    with pytest.raises(InputError):
        report(argv + ["--out", str(tmp_path)])


def test_report_plugins_renders_without_solving(tmp_path, monkeypatch):
    """The experiment's data is plain JSON; the renderer draws and writes from it without running a solver."""
    import json

    import dualfem.experiments.runner as runner
    from dualfem.experiments.plugins import collect
    from dualfem.reports.plugins import render

    data = json.loads(json.dumps(collect(N=8, sizes=(8,), progress=lambda m: None)))

    def no_solver(*a, **k):
        raise AssertionError("the renderer ran a solver")

    monkeypatch.setattr(runner, "run", no_solver)
    text = render(data, tmp_path, dpi=40)
    assert (tmp_path / "figures" / "plugins_signorini.png").stat().st_size > 5000
    assert f"Reference: `{data['reference']}`" in text and data["reference"] in ("pdas", "clarabel")
    assert text.count("| solved |") >= 2 and "| 8 | strain |" in text
