"""``dualfem report html``: the self-contained dashboard.

Without a browser: the page loads nothing from the network, embeds the data of every solver of its
input (the ranking numbers are those of ``dualfem report bench``), and bad inputs or output folders
are refused before anything is written. With headless Chromium (Debian's ``chromium``; skipped with a
reason when no browser is installed): the page renders its plots without a JavaScript error, and the
checker itself fails on a page that throws or that is blank.

Data: a tiny bench with convergence curves run here (f2, N = 8) and the committed breadth results.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from dualfem.cli.main import main
from dualfem.core.errors import InputError, MissingDependency
from dualfem.experiments import bench
from dualfem.experiments.spec import load_spec
from dualfem.experiments.store import read_results

pytest.importorskip("plotly", reason="dualfem report html needs plotly: pip install 'dualfem[html]'")

from dualfem.reports._bench_rank import rank_table  # noqa: E402
from dualfem.reports._bench_util import group_scenes  # noqa: E402
from dualfem.reports.html import build_dashboard  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BREADTH = ROOT / "benchmarks" / "results" / "breadth"
SPEC = """
name = "dash_t"
repeats = 1
warmup = false
time_limit = 30
curves = true
[tiers]
low = 1e-4
high = 1e-8
[floor]
repeats = 1
warmup = false
cholmod = false
[[scenes]]
scene = "f2"
N = 8
delta = [1e-3, 1e-7]
[[solvers]]
name = "uzawa"
[[solvers]]
name = "pdas"
[[solvers]]
name = "osqp"
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    """A tiny bench with curves (f2, N = 8, two deltas, two tiers, three solvers)."""
    d = tmp_path_factory.mktemp("dash_bench")
    (d / "spec.toml").write_text(SPEC, encoding="utf-8")
    with open(os.devnull, "w") as null:
        bench.run_sweep(load_spec(d / "spec.toml"), d / "out", progress=False, stream=null)
    assert (d / "out" / "curves.csv").is_file()
    return d / "out"


@pytest.fixture(scope="module")
def page(tiny, tmp_path_factory) -> Path:
    """One dashboard of the breadth results and the tiny bench (27+ solvers, curves, two sources)."""
    return build_dashboard([BREADTH, tiny], tmp_path_factory.mktemp("dash_page") / "dash")


def embedded(path: Path) -> dict:
    """The JSON data a page embeds (its ``<script id="dash-data">``)."""
    text = path.read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="dash-data">(.*?)</script>', text, re.S)
    assert m, "no embedded data"
    return json.loads(m.group(1))


class _Refs(HTMLParser):
    """Every src/href of the page's tags (script contents are not parsed as tags)."""

    def __init__(self):
        super().__init__()
        self.refs: list[tuple[str, str, str]] = []
        self.inline_scripts = 0

    def handle_starttag(self, tag, attrs):
        for k, v in attrs:
            if k in ("src", "href", "data") and v:
                self.refs.append((tag, k, v))
        if tag == "script" and not dict(attrs).get("src"):
            self.inline_scripts += 1


# ---------------------------------------------------------------- without a browser

def test_page_is_self_contained(page):
    html = page.read_text(encoding="utf-8")
    p = _Refs()
    p.feed(html)
    external = [r for r in p.refs if re.match(r"\s*(https?:)?//", r[2], re.I)]
    assert not external, f"the page loads from the network: {external[:5]}"
    assert not [r for r in p.refs if r[0] in ("script", "link", "img", "iframe")], p.refs
    assert p.inline_scripts >= 4          # error handlers, plotly.js, the data, the dashboard
    assert "Plotly" in html and len(html) > 3_000_000       # plotly.js itself is inline (~4.8 MB)
    assert '<meta name="generator" content="dualfem report html">' in html


def test_page_embeds_every_solver_and_the_bench_numbers(page, tiny):
    data = embedded(page)
    rows = read_results(BREADTH) + read_results(tiny)
    variants = {str(r.get("variant") or r["solver"]) for r in rows if r["kind"] == "run"}
    names = [s["name"] for s in data["solvers"]]
    assert set(names) == variants and len(names) == len(variants) >= 27
    ran = {names[i] for i in data["runs"]["solver"]}
    assert ran == {str(r.get("variant") or r["solver"]) for r in rows
                   if r["kind"] == "run" and r["status"] != "skipped"}
    # every run id of the input that was not skipped is in the page, and its curve when it has one
    ids = set(data["runs"]["id"])
    assert {r["run_id"] for r in read_results(tiny) if r["kind"] == "run"} <= ids
    assert data["curves"] and set(data["curves"]) <= ids
    assert {data["curves"][i]["kind"] for i in data["curves"]} <= {"reference", "kkt"}
    # colours: Okabe-Ito, no two solvers share colour and marker
    pairs = [(s["color"], s["symbol"]) for s in data["solvers"]]
    assert len(set(pairs)) == len(pairs)
    # the ranking table for tier high, the first scene identity of f1, is the one 'dualfem report bench' computes
    ti = [t["name"] for t in data["tiers"]].index("high")
    si = data["scene_names"].index("f1")
    got = data["rank"][f"{ti}|{si}|-1"]
    runs = [r for r in read_results(BREADTH) if r["kind"] == "run" and r["scene"] == "f1" and r["status"] != "skipped"]
    for r in runs:
        r["tier"], r["variant"] = str(r.get("tier") or ""), str(r.get("variant") or r["solver"])
    runs = [r for sid, g in group_scenes(runs).items() if sid.label == data["scenes"][si] for r in g]
    assert runs and data["scenes"][si].startswith("f1, N = ")
    want, ncommon = rank_table(runs, "high", 1e-9, 10.0)
    cols = data["rank_columns"]
    assert got["n"] == ncommon
    assert [names[row[0]] for row in got["rows"]] == [s["variant"] for s in want]
    for row, s in zip(got["rows"], want):
        for c in ("runs", "claims", "certified", "success", "correct"):
            v = row[cols.index(c)]
            assert (v is None and not np.isfinite(s[c])) or v == pytest.approx(s[c], rel=1e-3), (c, row, s)


def test_text_of_the_results_stays_data(tmp_path, tiny):
    """A message or label holding HTML cannot end the data's <script> or add an element to the page."""
    import csv

    with open(tiny / "results.csv", newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        fields, rows = reader.fieldnames, list(reader)
    hostile = '</script><script>window.PWNED = 1</script><!-- & "'
    run = next(r for r in rows if r["kind"] == "run")
    run["message"], run["status"], run["label"] = hostile, "inaccurate", hostile
    (tmp_path / "res").mkdir()
    with open(tmp_path / "res" / "results.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    plain, bad = build_dashboard([tiny], tmp_path / "plain"), build_dashboard([tmp_path / "res"], tmp_path / "bad")

    def tags(path):
        p = _Refs()
        p.feed(path.read_text(encoding="utf-8"))
        return p.inline_scripts

    assert tags(bad) == tags(plain)
    data = embedded(bad)
    k = data["runs"]["id"].index(run["run_id"])
    assert data["runs"]["message"][k] == hostile and data["runs"]["label"][k] == hostile


def test_stress_results(tmp_path):
    """A stress folder (runs.jsonl): every solver, one tier of declared tolerances, rankings per delta."""
    from dualfem.reports._dash_data import STRESS_TIER, payload

    folder = ROOT / "benchmarks" / "results" / "stress_breadth"
    data = payload([folder])
    solvers = {json.loads(line)["solver"] for line in (folder / "runs.jsonl").read_text().splitlines() if line}
    assert {s["name"] for s in data["solvers"]} == solvers
    assert [t["name"] for t in data["tiers"]] == [STRESS_TIER] and data["targets"] == []
    assert f"0|-1|{len(data['deltas']) - 1}" in data["rank"]


def test_bad_inputs_are_refused_before_anything_is_written(tmp_path, tiny):
    out = tmp_path / "dash"
    with pytest.raises(InputError, match="does not exist"):
        build_dashboard([tmp_path / "nowhere"], out)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not a 'dualfem bench' folder"):
        build_dashboard([tmp_path / "empty"], out)
    header = (tiny / "results.csv").read_text(encoding="utf-8").splitlines()[0]
    (tmp_path / "norows").mkdir()
    (tmp_path / "norows" / "results.csv").write_text(header + "\n", encoding="utf-8")
    with pytest.raises(InputError, match="hold no runs"):
        build_dashboard([tmp_path / "norows"], out)
    only_refs = [line for line in (tiny / "results.csv").read_text(encoding="utf-8").splitlines()[1:]
                 if ",run," not in line]
    (tmp_path / "refs").mkdir()
    (tmp_path / "refs" / "results.csv").write_text("\n".join([header] + only_refs) + "\n", encoding="utf-8")
    with pytest.raises(InputError, match="hold no runs"):
        build_dashboard([tmp_path / "refs"], out)
    with pytest.raises(InputError, match="at least one RESULTS"):
        build_dashboard([], out)
    assert not out.exists()


def test_out_folder_rules(tmp_path, tiny):
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="is a file"):
        build_dashboard([tiny], tmp_path / "file")
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "notes.md").write_text("mine")
    with pytest.raises(InputError, match="did not write"):
        build_dashboard([tiny], busy)
    assert sorted(p.name for p in busy.iterdir()) == ["notes.md"]
    build_dashboard([tiny], busy, force=True)            # index.html beside them, nothing else touched
    assert (busy / "notes.md").read_text() == "mine" and (busy / "index.html").is_file()
    other = tmp_path / "other"
    other.mkdir()
    (other / "index.html").write_text("<html>someone's page</html>")
    with pytest.raises(InputError, match="not a dualfem dashboard"):
        build_dashboard([tiny], other)
    assert (other / "index.html").read_text() == "<html>someone's page</html>"
    own = tmp_path / "own"
    build_dashboard([tiny], own)
    build_dashboard([tiny], own)                         # its own earlier page is replaced
    assert [p.name for p in own.iterdir()] == ["index.html"]


def test_cli(tmp_path, tiny, capsys):
    assert main(["report", "list"]) == 0
    assert re.search(r"^html\s", capsys.readouterr().out, re.M)
    assert main(["report", "html", str(tiny), "--out", str(tmp_path / "d")]) == 0
    assert (tmp_path / "d" / "index.html").is_file()
    assert "dualfem report html" in embedded(tmp_path / "d" / "index.html")["command"]
    capsys.readouterr()
    assert main(["report", "html", str(tmp_path / "missing"), "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dualfem report: error:") and "missing" in err[0]
    assert main(["report", "html", str(tiny), "--out", str(tmp_path / "f"), "--shift", "-1"]) == 2
    assert not (tmp_path / "e").exists() and not (tmp_path / "f").exists()


def test_missing_plotly_names_the_extra(tmp_path, tiny, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "plotly.offline", None)       # import plotly.offline -> ImportError
    with pytest.raises(MissingDependency, match=r"pip install 'dualfem\[html\]'"):
        build_dashboard([tiny], tmp_path / "d")
    assert not (tmp_path / "d").exists()


def chromium() -> str | None:
    """The headless browser: Debian's ``chromium`` or Ubuntu's ``chromium-browser``."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


needs_chromium = pytest.mark.skipif(chromium() is None, reason="no chromium/chromium-browser binary (Debian: "
                                                                 "apt-get install chromium; scripts/test.sh does)")
needs_js = pytest.mark.skipif(chromium() is None and shutil.which("node") is None,
                              reason="neither node nor chromium to run the page's JavaScript helpers")


# ---------------------------------------------------------------- the page's arithmetic (node, else Chromium)

def _js(tmp_path: Path, code: str):
    """The JSON value of the JavaScript expression ``code``, evaluated after the dashboard's pure helpers
    (``DashLib`` as ``L``): under node when installed, else in headless Chromium (the value written into
    the page's body and read from the dumped DOM)."""
    import html as html_mod
    from importlib import resources

    lib = (resources.files("dualfem.reports") / "templates" / "dashboard_lib.js").read_text(encoding="utf-8")
    if shutil.which("node"):
        f = tmp_path / "t.cjs"
        f.write_text(lib + "\nconst L = module.exports;\nconsole.log(JSON.stringify(" + code + "));\n",
                     encoding="utf-8")
        return json.loads(subprocess.run(["node", str(f)], capture_output=True, text=True, timeout=30,
                                         check=True).stdout)
    f = tmp_path / "t.html"
    f.write_text("<!DOCTYPE html><html><body><script>" + lib + "</script><script>const L = window.DashLib;"
                 "document.body.textContent = JSON.stringify(" + code + ");</script></body></html>", encoding="utf-8")
    dom = _chromium_run(["--dump-dom", f.resolve().as_uri()], tmp_path / "js")
    m = re.search(r"<body>(.*?)</body>", dom, re.S)        # the body holds only the value now
    assert m, dom[:500]
    return json.loads(html_mod.unescape(m.group(1)))


@needs_js
def test_median_curve_and_band(tmp_path):
    """Three runs' curves: the median and interquartile band at the first and last time, by hand."""
    curves = [{"t": [1, 2, 4], "e": [1e-1, 1e-3, 1e-6]}, {"t": [1, 3], "e": [1e-2, 1e-8]},
              {"t": [2, 4], "e": [1, None]}]
    b = _js(tmp_path, f"L.medianBand({json.dumps(curves)})")
    assert len(b["t"]) == 64 and b["t"][0] == 1 and b["t"][-1] == 4
    assert np.diff(np.log(b["t"])) == pytest.approx(np.full(63, np.log(4) / 63))
    # t = 1: two runs started (0.1, 1e-2): the geometric median, quartiles of the logs
    assert b["n"][0] == 2 and b["med"][0] == pytest.approx(10 ** -1.5)
    assert b["lo"][0] == pytest.approx(10 ** -1.75) and b["hi"][0] == pytest.approx(10 ** -1.25)
    # t = 4: 1e-6, 1e-8 (held since t = 3) and 1 (held: the sample at t = 4 has no error)
    assert b["n"][-1] == 3 and b["med"][-1] == pytest.approx(1e-6)
    assert b["lo"][-1] == pytest.approx(1e-7) and b["hi"][-1] == pytest.approx(1e-3)
    assert _js(tmp_path, 'L.medianBand([{"t": [1], "e": [null]}])') is None


@needs_js
def test_median_curve_is_that_of_the_static_figures(tmp_path):
    """The page's median and band equal dualfem.reports._bench_curves.median_curve on the same curves."""
    from dualfem.reports._bench_curves import Curve, median_curve

    rng = np.random.default_rng(7)
    curves = []
    for k in range(7):
        n = int(rng.integers(1, 12))
        t = np.sort(rng.uniform(0.01, 1.0, n)) * 10 ** rng.uniform(-1, 1)
        t[n // 2:] = np.maximum.accumulate(t[n // 2:])
        if n > 3:
            t[2] = t[1]                                  # equal times: the later sample counts
        e = 10 ** np.sort(rng.uniform(-14, 0, n))[::-1]
        if k == 3:
            e[-1] = 0.0                                  # floored at 1e-16
        curves.append((t, e))
    want = median_curve([Curve(str(k), "s", "x", "k", "reference", np.arange(len(t)), t, e)
                         for k, (t, e) in enumerate(curves)])
    got = _js(tmp_path, "L.medianBand(" + json.dumps([{"t": t.tolist(), "e": e.tolist()} for t, e in curves]) + ")")
    assert got["t"] == pytest.approx(want.time_s, rel=1e-12)
    assert got["n"] == want.n_defined.tolist()
    for key, ref in (("med", want.median), ("lo", want.low), ("hi", want.high)):
        vals = np.array([np.nan if v is None else v for v in got[key]])
        assert np.isnan(vals).tolist() == np.isnan(ref).tolist()
        assert vals[~np.isnan(vals)] == pytest.approx(ref[~np.isnan(ref)], rel=1e-9), key


@needs_js
def test_numbers_are_written_as_python_writes_them(tmp_path):
    vals = [1e-6, 5.95e-9, 0.00126, 1500, 999.96, 1e-5, 0.1, 16, 1e-4, 1e-16, 123456, 1234567, -2.5e-7, 0.5]
    got = _js(tmp_path, f"{json.dumps(vals)}.map((v) => [L.g(v, 3), L.g(v, 6)])")
    assert got == [[format(v, ".3g"), format(v, ".6g")] for v in vals]


# ---------------------------------------------------------------- in headless Chromium

@dataclass
class PageCheck:
    """What the browser saw: ``problems`` (empty: the page rendered), the screenshot, the DOM."""

    problems: list[str] = field(default_factory=list)
    screenshot: Path | None = None
    dom: str = ""


def _chromium_run(args: list[str], work: Path, timeout: float = 60.0) -> str:
    """stdout of headless Chromium with ``args`` (its own profile under ``work``, removed after; the whole
    process group killed after ``timeout`` s: TimeoutError)."""
    work.mkdir(parents=True, exist_ok=True)
    base = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
            "--disable-extensions", f"--user-data-dir={work / 'profile'}", "--host-resolver-rules=MAP * ~NOTFOUND"]
    proc = subprocess.Popen(base + [a for a in args if a not in base], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise TimeoutError(f"chromium did not finish within {timeout:g} s") from None
    finally:
        shutil.rmtree(work / "profile", ignore_errors=True)
    return out.decode("utf-8", errors="replace")


def check_page(html: Path, work: Path, size: str = "1280,1000", timeout: float = 60.0) -> PageCheck:
    """Open ``html`` in headless Chromium (no sandbox and no GPU, as root in a container; every host name
    unresolvable, so nothing can come from the network), dump its DOM after the scripts ran and take a
    screenshot; a problem for a JavaScript error or rejection the page's handlers wrote into the DOM,
    for a missing ``data-dash-rendered="ok"`` marker, for fewer than two plotly plots, and for a blank
    screenshot (one colour over more than 99 % of its pixels)."""
    work.mkdir(parents=True, exist_ok=True)
    shot = work / "screenshot.png"
    cmd = [chromium(), "--hide-scrollbars", "--virtual-time-budget=15000", f"--window-size={size}",
           f"--screenshot={shot}", "--dump-dom", html.resolve().as_uri()]
    try:
        dom = _chromium_run(cmd[1:], work, timeout)
    except TimeoutError as exc:
        return PageCheck([str(exc)])
    res = PageCheck(dom=dom, screenshot=shot if shot.is_file() else None)
    root = re.search(r"<html\b([^>]*)>", res.dom)        # the marks are attributes of <html> itself
    marks = root.group(1) if root else ""
    m = re.search(r'<pre id="dash-errors"[^>]*>(.*?)</pre>', res.dom, re.S)
    if 'data-dash-error="1"' in marks or (m and m.group(1).strip()):
        res.problems.append("JavaScript error: " + (m.group(1).strip() if m else "?")[:2000])
    if 'data-dash-rendered="ok"' not in marks:
        res.problems.append("the page never set data-dash-rendered=ok (its plots were not drawn)")
    layers = res.dom.count('class="main-svg"')
    if layers < 2:
        res.problems.append(f"{layers} plotly svg layers in the DOM (want >= 2)")
    if res.screenshot is None:
        res.problems.append("chromium wrote no screenshot")
    else:
        import matplotlib.image as mpimg

        img = mpimg.imread(res.screenshot)[..., :3]
        _, counts = np.unique(img.reshape(-1, 3), axis=0, return_counts=True)
        if counts.max() > 0.99 * counts.sum():
            res.problems.append(f"blank screenshot: one colour covers {100 * counts.max() / counts.sum():.2f} % of it")
    return res





@needs_chromium
def test_dashboard_renders_in_chromium(page, tmp_path):
    res = check_page(page, tmp_path / "chromium")
    assert res.problems == [], res.problems
    assert res.dom.count("js-plotly-plot") >= 2
    # the side panel lists every solver of the input, one checkbox each
    data = embedded(page)
    # a median curve for every solver with curves (the tiny bench's uzawa and pdas; osqp has no iterates),
    # but the reference solver's own runs (pdas: error 0 by construction) are a line, not a competitor
    solver_of = dict(zip(data["runs"]["id"], data["runs"]["solver"]))
    selfref = dict(zip(data["runs"]["id"], data["runs"]["selfref"]))
    with_curves = {solver_of[i] for i, c in data["curves"].items() if c["kind"] == "reference" and not selfref[i]}
    assert {data["solvers"][i]["name"] for i in with_curves} == {"uzawa"}
    assert {solver_of[i] for i, c in data["curves"].items() if c["kind"] == "reference"} > with_curves
    assert re.search(rf'<div id="dash-status"[^>]*data-median-curves="{len(with_curves)}"', res.dom), \
        re.search(r'<div id="dash-status"[^>]*>', res.dom)
    assert len(re.findall(r'<input type="checkbox" data-solver=', res.dom)) == len(data["solvers"])
    if os.environ.get("DUALFEM_DASHBOARD_SCREENSHOT"):          # keep the picture when asked
        shutil.copy(res.screenshot, os.environ["DUALFEM_DASHBOARD_SCREENSHOT"])


@needs_chromium
def test_checker_fails_on_a_javascript_error(page, tmp_path):
    html = page.read_text(encoding="utf-8")
    # plotly.js left out (it takes most of the browser's time; the page's script throws before using it)
    html = re.sub(r'(<script id="plotly-js">).*?(</script>)', lambda m: m.group(1) + m.group(2), html, count=1,
                  flags=re.S)
    assert len(html) < 2_000_000
    # the data of a broken writer: the page's script throws on it; and a promise nobody catches
    broken = re.sub(r'(<script type="application/json" id="dash-data">).*?(</script>)',
                    lambda m: m.group(1) + '{"runs": null}' + m.group(2), html, count=1, flags=re.S)
    broken = broken.replace("<body>", '<body><script>Promise.reject(new Error("deliberate rejection"));</script>', 1)
    assert broken != html
    bad = tmp_path / "broken.html"
    bad.write_text(broken, encoding="utf-8")
    res = check_page(bad, tmp_path / "chromium")
    assert any(p.startswith("JavaScript error") and "TypeError" in p and "deliberate rejection" in p
               for p in res.problems), res.problems
    assert any("never set data-dash-rendered" in p for p in res.problems)


@needs_chromium
def test_checker_fails_on_a_blank_page(tmp_path):
    blank = tmp_path / "blank.html"        # claims to be rendered, shows nothing
    blank.write_text('<!DOCTYPE html><html data-dash-rendered="ok"><body><pre id="dash-errors"></pre>'
                     '<svg class="main-svg"></svg><svg class="main-svg"></svg></body></html>', encoding="utf-8")
    res = check_page(blank, tmp_path / "chromium", size="400,300")
    assert [p for p in res.problems if p.startswith("blank screenshot")], res.problems
    assert not [p for p in res.problems if "JavaScript" in p or "rendered" in p]


GMSH = ROOT / "benchmarks" / "results" / "gmsh_scene"


def test_a_scene_without_N_is_faceted_by_its_identity(tmp_path):
    """A gmsh scene given by mesh_size: scene identities name mesh_size, each has its floor; the targets
    checklist only when asked."""
    from dualfem.reports._dash_data import payload

    data = payload([GMSH])
    assert data["scenes"] == ["inclined_biaxial, mesh_size = 0.04", "inclined_biaxial, mesh_size = 0.02"]
    assert "Ns" not in data and sorted(f["scene"] for f in data["floors"]) == [0, 1]
    assert data["targets"] == [] and data["show_targets"] is False
    assert payload([GMSH], show_targets=True)["show_targets"] is True
    # the reference solver's own runs are flagged (drawn as a line in the energy-norm view)
    sel = [s for s, solver in zip(data["runs"]["selfref"], data["runs"]["solver"])
           if data["solvers"][solver]["name"] == "pdas"]
    assert sel and all(sel) and not any(s for s, solver in zip(data["runs"]["selfref"], data["runs"]["solver"])
                                        if data["solvers"][solver]["name"] != "pdas")
    if chromium() is not None:
        res = check_page(build_dashboard([GMSH], tmp_path / "d"), tmp_path / "chromium")
        assert res.problems == [], res.problems
        summary = re.search(r'<p id="dash-summary">(.*?)</p>', res.dom, re.S).group(1)
        assert "N in" not in summary and "inclined_biaxial, mesh_size = 0.02" in summary
        assert re.search(r'<section id="targets-section"[^>]*hidden', res.dom)
        assert "floor N=" not in res.dom and ">floor<" in res.dom.replace("</tspan>", "<")


def test_a_stress_row_is_named_by_its_scene_not_its_load():
    from dualfem.reports._dash_data import _stress_row

    r = _stress_row({"kind": "stress", "scene": {"load": "f2", "N": 16, "delta": 1e-5}, "scene_name": "curved",
                     "axis": "delta", "coords": {"delta": 1e-5}, "solver": "pdas"})
    assert r["scene"] == "curved" and r["scene_N"] == 16
    assert _stress_row({"scene": {"load": "f2"}, "axis": "N", "coords": {}, "solver": "pdas"})["scene"] == "f2"


def test_a_run_with_two_repeats_gives_one_curve_not_a_saw_tooth():
    from dualfem.reports._dash_data import _curves

    recs = [{"run_id": "r", "time_s": t, "error": e, "iteration": i, "error_kind": "reference", "repeat": rep}
            for rep, t0 in ((2, 0.0), (1, 0.05)) for i, (t, e) in enumerate([(t0 + 0.1, 1.0), (t0 + 0.2, 1e-9)])]
    c = _curves({"r": recs})["r"]
    assert c["t"] == [0.15, 0.25] and c["e"] == [1.0, 1e-9]      # repeat 1 only, errors decreasing


@needs_chromium
def test_many_panels_open_on_the_first_scene(tmp_path):
    """More than 24 scene x delta panels (the default sweep: 51, no curves): the page opens on the first
    scene's deltas."""
    res = check_page(build_dashboard([ROOT / "benchmarks" / "results" / "default"], tmp_path / "d"),
                     tmp_path / "chromium")
    assert res.problems == [], res.problems
    assert "opens on the scene curved (51 scene and delta panels in all)" in res.dom
    assert "curved, delta = 1e-05" in res.dom and "f1, N = 32, delta" not in res.dom
