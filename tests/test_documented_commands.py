"""Every command shown in README.md and docs/*.md works as written.

The commands are discovered from the files, not listed here: every line of a fenced ``bash``, ``sh``,
``shell`` or ``console`` block (in a block with ``$ `` prompts, only the prompted lines; the rest is
output), in the order of the file; ``\\`` continues a line, ``# comments`` and what follows a shell
operator (``&&``, ``||``, ``|``, ``;``, ``>``) are dropped, ``python -m dualfem`` is ``dualfem``, and
``cat > FILE <<WORD`` writes its here-document to FILE. docs/plugins.md is executed by
tests/test_docs.py (with the guide's plugin installed) and skipped here.

``dualfem`` commands run in-process (:func:`dualfem.cli.main.main`), those of one file in order in one
scratch folder (holding ``benchmarks/`` and ``scenes/`` of the repository, and a copy of any other of its
folders a command names, e.g. ``examples/``). A ``*.toml`` file a command
names that does not exist there is the doc's ``toml`` block naming it in its first line, else its first
block of the kind (a sweep spec for ``bench``, else a scene), else a scene of the library of the doc's
dimension. Each command must exit 0 with no traceback and no error line. To stay fast, these test-only
changes are made, and each test prints the mode it ran in:

* ``--set N=V`` with V > 8 runs with ``N=8``; ``/tmp/...`` paths go into the scratch folder;
* ``full``: a scene whose estimated size is at most :data:`MAX_UNKNOWNS` unknowns is assembled and solved;
  a larger one is ``validated``: everything up to the assembly runs (options, solver parameters, the
  scene's keys and geometry checks, the memory check), then the command stops;
* ``compare`` without ``-s`` compares :data:`COMPARE_SOLVERS` (not every registered solver);
* ``testset`` validates the documented ``--sizes`` and writes the ``tiny`` class only;
* ``bench`` and ``stress`` are ``validated``: their inputs are checked (the spec and selection, every
  scene of the sweep; the stress grid) and their results folder is checked (a folder of another spec
  is refused) and claimed; the sweep is not run. A later ``report`` over such a bench folder reads the
  committed results of :data:`COMMITTED_RESULTS`, copied into it.

Other commands are not executed: ``bash scripts/X.sh`` is checked with ``bash -n``, ``pip install``
must name extras of pyproject.toml, and the kinds of :data:`NOT_RUN` (shell set-up, third-party tools)
are only listed; a command of any other kind fails the test, so that a new kind is taught here rather
than skipped.
"""
from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: doc files whose commands another test runs (with the set-up they need)
EXECUTED_ELSEWHERE = {"docs/plugins.md": "tests/test_docs.py runs every block of the guide with its plugin installed"}
SHELL_LANGS = {"bash", "sh", "shell", "console"}
OPERATORS = {"&&", "||", "|", ";", ">", ">>", "2>", "&"}
#: the largest scene (estimated unknowns) that is assembled and solved; a larger one is validated
MAX_UNKNOWNS = 20_000
#: the largest N of a structured scene (``--set N=V`` above it runs with this N)
TINY_N = 8
COMPARE_SOLVERS = ["pdas", "clarabel"]
#: the results a report reads in a bench folder the test only validated (a small committed sweep)
COMMITTED_RESULTS = ROOT / "benchmarks" / "results" / "target" / "results.csv"
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.S | re.M)
NOT_RUN = {"source": "shell set-up", ".": "shell set-up", "cd": "shell set-up", "cat": "shell set-up",
           "ls": "shell set-up", "mkdir": "shell set-up", "export": "shell set-up", "git": "fetches the code",
           "python": "a third-party tool", "python3": "a third-party tool", "pytest": "the test suite"}


@dataclass(frozen=True)
class Documented:
    """One documented command: its file (relative to the repository), line and words."""

    file: str
    line: int
    argv: tuple[str, ...]
    #: the here-document of ``cat > FILE <<WORD`` (written to FILE before the next command)
    body: str | None = None

    @property
    def id(self) -> str:
        return f"{self.file}:{self.line}"


def documented_commands(path: Path) -> list[Documented]:
    """The commands of ``path``'s shell blocks, in order (see the module docstring)."""
    text = path.read_text(encoding="utf-8")
    rel = path.relative_to(ROOT).as_posix()
    out = []
    for m in FENCE.finditer(text):
        if m.group(1) not in SHELL_LANGS:
            continue
        first = text[:m.start(2)].count("\n") + 1
        lines = m.group(2).splitlines()
        prompted = any(ln.startswith("$ ") for ln in lines)
        i = 0
        while i < len(lines):
            start, ln = i, lines[i]
            i += 1
            if prompted and not ln.startswith("$ "):
                continue
            ln = ln[2:] if prompted else ln
            while ln.endswith("\\") and i < len(lines):      # a continued line
                ln = ln[:-1] + " " + lines[i].removeprefix("> ")
                i += 1
            here = re.search(r"<<-?\s*['\"]?(\w+)", ln)
            body = None
            if here:                                          # the here-document's body
                ln, k = ln[:here.start()], i
                while i < len(lines) and lines[i].strip() != here.group(1):
                    i += 1
                body, i = "".join(f"{x}\n" for x in lines[k:i]), i + 1
                target = re.fullmatch(r"\s*cat\s*>\s*(\S+)\s*", ln)
                if target:
                    out.append(Documented(rel, first + start, ("cat", ">", target.group(1)), body))
                    continue
            words = shlex.split(ln, comments=True)
            words = words[:next((k for k, w in enumerate(words) if w in OPERATORS), len(words))]
            if words[:3] in (["python", "-m", "dualfem"], ["python3", "-m", "dualfem"]):
                words = ["dualfem", *words[3:]]
            if words:
                out.append(Documented(rel, first + start, tuple(words)))
    return out


ALL = [c for p in DOCS for c in documented_commands(p)]
RUN_HERE = [c for c in ALL if c.file not in EXECUTED_ELSEWHERE]


def test_commands_are_discovered_in_readme_and_docs():
    files = {c.file for c in ALL}
    assert "README.md" in files and any(f.startswith("docs/") for f in files)
    dual = [c for c in RUN_HERE if c.argv[0] == "dualfem"]
    assert {c.argv[1] for c in dual} >= {"solve", "compare", "bench", "export"}


def test_discovery_reads_prompts_comments_and_operators(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("```console\n$ dualfem list   # all\nproblems:\n$ cd d && python x.py\n```\n"
                   "```python\nimport os\n```\n```bash\ndualfem solve f2 --set N=8 || true\n"
                   "cat > s.toml <<'EOF'\nN = 8\nEOF\npython -m dualfem solve s.toml \\\n  --json\n```\n")
    got = [(c.line, c.argv) for c in documented_commands_at(doc, tmp_path)]
    assert got == [(2, ("dualfem", "list")), (4, ("cd", "d")), (10, ("dualfem", "solve", "f2", "--set", "N=8")),
                   (11, ("cat", ">", "s.toml")), (14, ("dualfem", "solve", "s.toml", "--json"))]
    assert documented_commands_at(doc, tmp_path)[3].body == "N = 8\n"


def documented_commands_at(path: Path, root: Path) -> list[Documented]:
    """:func:`documented_commands` for a file outside the repository (the discovery's own test)."""
    global ROOT
    saved, ROOT = ROOT, root
    try:
        return documented_commands(path)
    finally:
        ROOT = saved


# ------------------------------------------------------------------------------------------ running
class Validated(Exception):
    """Raised by the size guard: the command was checked up to the assembly of a large scene."""


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory):
    """One scratch folder per doc file (its commands run there in order)."""
    dirs: dict[str, Path] = {}

    def get(doc: str) -> Path:
        if doc not in dirs:
            d = tmp_path_factory.mktemp(re.sub(r"\W", "_", doc))
            for name in ("benchmarks", "scenes"):
                (d / name).symlink_to(ROOT / name, target_is_directory=True)
            dirs[doc] = d
        return dirs[doc]
    return get


def _tiny_argv(argv: list[str], cwd: Path) -> list[str]:
    """The test-only rewrites of the module docstring: N, /tmp paths, testset sizes."""
    out = []
    for i, a in enumerate(argv):
        m = re.fullmatch(r"N=(\d+)", a)
        if m and i > 0 and argv[i - 1] == "--set" and int(m.group(1)) > TINY_N:
            a = f"N={TINY_N}"
        if a.startswith("/tmp/"):
            a = str(cwd / a[1:])
        out.append(a)
    if out[0] == "testset":
        from dualfem.experiments.testset import parse_sizes

        if "--sizes" in out:
            k = out.index("--sizes")
            parse_sizes(out[k + 1])                        # the documented sizes are valid
            out[k + 1] = "tiny"
        else:
            out += ["--sizes", "tiny"]
    return out


def _toml_file(name: str, doc: Path, cwd: Path, spec: bool) -> None:
    """Write a ``.toml`` file a command names that neither the doc's commands nor the repository made: the
    doc's ``toml`` block that names it in its first line, else its first block of that kind (a sweep spec
    for ``bench``, else a scene), else (a scene) a library scene of the doc's dimension."""
    target = cwd / name
    if target.exists() or "/" in name:
        return
    text = doc.read_text(encoding="utf-8")
    blocks = [m.group(2) for m in FENCE.finditer(text) if m.group(1) == "toml"]
    named = [b for b in blocks if name in b.split("\n", 1)[0]]
    kind = [b for b in blocks if ("[[solvers]]" in b or "[[scenes]]" in b) == spec]
    if named or kind:
        target.write_text((named or kind)[0], encoding="utf-8")
    elif not spec:
        lib = "penny.toml" if re.search(r"dim\s*=\s*3", text) else "curved.toml"
        target.write_text((ROOT / "scenes" / lib).read_text(encoding="utf-8"), encoding="utf-8")


def _patch_for_speed(monkeypatch) -> None:
    """The size guard, compare's default solvers and bench's tiny sweep (see the module docstring)."""
    import dualfem.core.scene as scene_mod
    import dualfem.experiments.bench as bench_mod
    import dualfem.experiments.compare as compare_mod
    real_build, real_open = scene_mod.build_qp, bench_mod.open_store

    def guarded_build(problem):
        est = problem.size_estimate() if hasattr(problem, "size_estimate") else None
        if est is not None and est[0] > MAX_UNKNOWNS:
            raise Validated(f"validated up to the assembly ({est[1]}: about {est[0]:,} unknowns > {MAX_UNKNOWNS:,})")
        return real_build(problem)

    def claimed_only(out, *args, **kwargs):
        real_open(out, *args, **kwargs).close()            # the folder checked (another spec's?) and claimed
        raise Validated(f"validated: its inputs checked, its results folder {out} checked and claimed; the sweep "
                        f"not run")

    monkeypatch.setattr(scene_mod, "build_qp", guarded_build)
    monkeypatch.setattr(compare_mod, "default_solvers", lambda: list(COMPARE_SOLVERS))
    monkeypatch.setattr(bench_mod, "open_store", claimed_only)


def _run_dualfem(cmd: Documented, cwd: Path, monkeypatch, capsys) -> str:
    from dualfem.cli.main import main

    argv = _tiny_argv(list(cmd.argv[1:]), cwd)
    for a in argv:
        top = a.split("/", 1)[0]
        if "/" in a and not (cwd / top).exists() and (ROOT / top).is_dir() and top not in ("dualfem", "reports"):
            shutil.copytree(ROOT / top, cwd / top)       # e.g. examples/plate.toml: a copy, never the repository's
        if a.endswith(".toml") and not a.startswith("-"):
            _toml_file(a, ROOT / cmd.file, cwd, spec=argv[0] == "bench")
    modes: list[str] = []
    if argv[0] == "report":
        for a in argv[2:]:
            if (cwd / a).is_dir() and (cwd / a / "spec.toml").is_file() and not (cwd / a / "results.csv").exists():
                shutil.copyfile(COMMITTED_RESULTS, cwd / a / "results.csv")
                modes.append(f"(on the committed {COMMITTED_RESULTS.parent.name} results)")
    _patch_for_speed(monkeypatch)
    monkeypatch.chdir(cwd)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    try:
        rc = main(argv)
    except Validated as why:
        capsys.readouterr()
        return str(why)
    except SystemExit as exc:                               # --help of a report kind
        rc = exc.code or 0
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    assert rc == 0, f"{cmd.id}: dualfem {' '.join(argv)} exited {rc}:\n{err[-2000:]}"
    assert not [ln for ln in err.splitlines() if ": error:" in ln], err
    old = [ln.split("warning: ", 1)[1] for ln in err.splitlines() if ": warning:" in ln and "deprecated" in ln]
    return " ".join(["full", *modes, *(f"(deprecated form: {w})" for w in old)])


def _check_other(cmd: Documented, cwd: Path) -> str:
    argv = list(cmd.argv)
    if cmd.body is not None:
        (cwd / argv[2]).write_text(cmd.body, encoding="utf-8")
        return f"wrote {argv[2]} (a here-document)"
    if argv[0] in ("bash", "sh") and len(argv) > 1 and argv[1].startswith("scripts/"):
        script = ROOT / argv[1]
        assert script.is_file(), f"{cmd.id}: {argv[1]} does not exist"
        if shutil.which("bash"):
            p = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True, timeout=30)
            assert p.returncode == 0, f"{cmd.id}: {argv[1]}: {p.stderr}"
        return "not run (installs): its syntax checked"
    if argv[0] == "pip" and argv[1:2] == ["install"]:
        extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
        for a in argv[2:]:
            m = re.fullmatch(r"(?:dualfem|\.)\[([\w,-]+)\]", a)
            if m:
                missing = [e for e in m.group(1).split(",") if e not in extras]
                assert not missing, f"{cmd.id}: pip install names unknown extras {missing}"
        return "not run (installs): its extras checked"
    assert argv[0] in NOT_RUN, (f"{cmd.id}: a documented command of an unknown kind ({argv[0]!r}): teach "
                                f"tests/test_documented_commands.py how to run or check it")
    return f"not run ({NOT_RUN[argv[0]]})"


@pytest.mark.parametrize("cmd", RUN_HERE, ids=[c.id for c in RUN_HERE])
def test_documented_command_works(cmd, workdirs, monkeypatch, capsys, record_property):
    cwd = workdirs(cmd.file)
    mode = _run_dualfem(cmd, cwd, monkeypatch, capsys) if cmd.argv[0] == "dualfem" else _check_other(cmd, cwd)
    record_property("mode", mode)
    print(f"{cmd.id}: {' '.join(cmd.argv)} -> {mode}")
