"""One source of numbers: every performance figure the README and docs/ quote is in the report named.

The texts (:func:`documents`): README.md and docs/*.md (the README's reference parts live there).

A *statement* of the README is a table row, or a clause of a prose paragraph or list item (split at
"; " and at sentence ends); code blocks are skipped. A *quantity* is a number or a range of numbers
("85-93", "0.71 to 0.94", "50 ... 2,000") followed by a performance unit: seconds (``s``, ``ms``,
``min``), memory (``GB``, ``MB``), a ratio to the floor (``x the floor``, ``x``), ``unknowns`` or
``M unknowns``. The *reports* a statement names are the ``reports/...md`` and
``benchmarks/results/...md`` paths (plain or as Markdown links) in that statement itself.

The rule (:func:`check`): every number of every quantity of a statement that names a report must
appear, as written in the README (thousands separators aside), as a number in one of the reports it
names. A README that wants a rounded or derived figure must say where to read it instead of copying
it. (A number is looked for anywhere in the report, not in a given column: a small integer can be
found by coincidence; ranges and decimals rarely are.) Not checked: quantities written as estimates
("~25 min", "about a minute": how long a command takes, not a measurement quoted from a report) and
statements that name no report; the second test lists the performance statements (times, memory,
floor ratios) that name none, so that a new unsourced figure is seen.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

NUM = r"\d[\d,]*(?:\.\d+)?"
#: a number or range, then a unit; group "est": an estimate marker before it
QUANTITY = re.compile(
    rf"(?P<est>(?:~|\babout |\baround |\bapprox\. )\s*)?(?<![\w.-])(?P<a>{NUM})"
    rf"(?:\s*(?:-|\u2013|\.\.\.?|\bto\b)\s*(?P<b>{NUM}))?"
    r"(?P<unit>\s*x the floor|x\b|\s*(?:M unknowns|unknowns|GB|MB|ms|min|s)\b)")   # "0.9x", not "1e-6 x y"
REPORT = re.compile(r"(?<![\w/.-])((?:reports|benchmarks/results)/[\w/.-]*\w\.md)\b")
NUMBER = re.compile(rf"(?<![\w.]){NUM}")


@dataclass(frozen=True)
class Statement:
    text: str          # the clause or table row
    line: int          # 1-based line of its paragraph's start in the README


def _norm(number: str) -> str:
    """A number as compared: thousands separators and a trailing decimal point dropped."""
    return number.replace(",", "").rstrip(".")


def blocks(text: str) -> list[tuple[int, str]]:
    """(first line, text) of every paragraph, list item and table row outside code blocks."""
    out: list[tuple[int, str]] = []
    cur: list[str] = []
    start = 0
    fence = False

    def flush():
        if cur:
            out.append((start, " ".join(s.strip() for s in cur)))
            cur.clear()

    for i, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            flush()
            fence = not fence
            continue
        if fence or line.startswith("    ") and not cur:
            continue                                   # a code block (fenced or indented)
        if not line.strip():
            flush()
        elif line.lstrip().startswith("|"):
            flush()
            out.append((i, line.strip()))
        elif line.lstrip().startswith(("* ", "- ", "#")):
            flush()
            start = i
            cur.append(line)
        else:
            if not cur:
                start = i
            cur.append(line)
    flush()
    return out


def statements(text: str) -> list[Statement]:
    """Every table row and every clause of every paragraph (see the module docstring)."""
    out = []
    for line, block in blocks(text):
        if block.startswith("|"):
            out.append(Statement(block, line))
            continue
        for clause in re.split(r";\s+|(?<=[.!?])\s+(?=[A-Z`*(\[])", block):
            if clause.strip():
                out.append(Statement(clause, line))
    return out


def quantities(s: str) -> list[re.Match]:
    """The performance quantities of a statement that are not estimates."""
    return [m for m in QUANTITY.finditer(s) if not m.group("est")]


def reports_named(st: Statement) -> list[str]:
    """The reports a statement names."""
    return REPORT.findall(st.text)


def numbers_in(path: Path) -> set[str]:
    return {_norm(n) for n in NUMBER.findall(path.read_text(encoding="utf-8"))}


def check(readme: str, root: Path = REPO, name: str = "README") -> list[str]:
    """One message per quoted number that is not in any report its statement names (empty: all agree)."""
    bad = []
    cache: dict[str, set[str]] = {}
    for st in statements(readme):
        qs = quantities(st.text)
        named = reports_named(st)
        if not qs or not named:
            continue
        for rep in named:
            if rep not in cache:
                p = root / rep
                cache[rep] = numbers_in(p) if p.exists() else set()
        have = set().union(*(cache[r] for r in named))
        for q in qs:
            for n in (q.group("a"), q.group("b")):
                if n is not None and _norm(n) not in have:
                    bad.append(f"{name} line {st.line}: {q.group(0).strip()!r} ({n} not in "
                               f"{', '.join(named)}): {st.text[:160]}")
    return bad


def unsourced(readme: str, name: str = "README") -> list[str]:
    """Statements with a quoted time, memory or floor ratio that name no report."""
    out = []
    for st in statements(readme):
        qs = [q for q in quantities(st.text) if q.group("unit").strip() in ("s", "ms", "GB", "MB", "x the floor")]
        if qs and not reports_named(st):
            out.append(f"{name} line {st.line}: {', '.join(q.group(0).strip() for q in qs)}: {st.text}")
    return out


# ------------------------------------------------------------------------------------------ tests
def documents() -> list[Path]:
    """README.md and every page of docs/."""
    return [REPO / "README.md", *sorted(REPO.glob("docs/*.md"))]


#: the pages that hold what was the README's reference part (its performance statements name their report
#: like the README's own); the older pages (testset.md's size tables, three_d.md's notes, ...) are checked
#: by the first test only
REFERENCE_PAGES = ("README.md", "docs/cli.md", "docs/conventions.md", "docs/layout.md", "docs/linear_algebra.md",
                   "docs/reports.md", "docs/solvers.md")


@pytest.mark.parametrize("path", documents(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_quoted_numbers_are_the_reports_numbers(path):
    rel = path.relative_to(REPO).as_posix()
    bad = check(path.read_text(encoding="utf-8"), name=rel)
    assert not bad, "\n".join(bad)


#: performance statements of the README that name no report on purpose (thresholds and settings, not
#: measurements); a new one fails the test below until it names its report or is added here with a reason
NOT_MEASUREMENTS = {
    "a solve longer than 2 s prints on stderr": "a threshold of the CLI (stage lines), not a measurement",
}


@pytest.mark.parametrize("rel", REFERENCE_PAGES)
def test_performance_statements_name_their_report(rel):
    left = [u for u in unsourced((REPO / rel).read_text(encoding="utf-8"), name=rel)
            if not any(k in u for k in NOT_MEASUREMENTS)]
    assert not left, "\n".join(left)


def test_the_reference_pages_exist_and_are_linked_from_the_readme():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for rel in REFERENCE_PAGES[1:]:
        assert (REPO / rel).exists() and f"]({rel})" in readme, rel


def test_checker_catches_a_wrong_number(tmp_path):
    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / "r.md").write_text("| N | time |\n|---|---|\n| 2048 | 76.4 |\n| 2048 | 84.6 |\n"
                                               "peak 17,690 MB, 8,394,750 unknowns, 0.71 x the floor\n")
    good = ("N = 2048 runs in 76.4-84.6 s with a 17690 MB peak and 8,394,750 unknowns "
            "(0.71x the floor): `reports/r.md`.")
    assert check(good, tmp_path) == []
    for wrong, number in (("76.4-84.6 s", "85"), ("17690 MB", "17.7"), ("8,394,750 unknowns", "8.4"),
                          ("0.71x", "0.72")):
        txt = good.replace(wrong, wrong.replace(wrong.split("-")[0].split(" ")[0].rstrip("x"), number, 1))
        msgs = check(txt, tmp_path)
        assert len(msgs) == 1 and f"({number} not in reports/r.md)" in msgs[0], (txt, msgs)
    # a link names the report too; a report that does not exist has no numbers
    assert check("Runs in 76.4 s ([end to end](reports/r.md)).", tmp_path) == []
    assert check("Runs in 76.4 s (`reports/missing.md`).", tmp_path) != []
    # estimates and statements that name no report are not checked, but unsourced() lists the latter
    assert check("The sweep takes ~25 min (`reports/r.md`).", tmp_path) == []
    assert unsourced("It runs in 93 s with a 17.7 GB peak.") != []
    assert unsourced("It runs in 76.4 s: `reports/r.md`.") == []


def test_statements_split_clauses_and_skip_code():
    text = ("Intro line one\nwith 5 s; then 7 GB: `reports/a.md`.\n\n```bash\nrun 9 s\n```\n\n"
            "| a | 3 s | `reports/b.md` |\n")
    sts = statements(text)
    assert [s.text for s in sts] == ["Intro line one with 5 s", "then 7 GB: `reports/a.md`.",
                                     "| a | 3 s | `reports/b.md` |"]
    assert reports_named(sts[0]) == [] and reports_named(sts[1]) == ["reports/a.md"]
    assert [q.group(0) for q in quantities("50 ... 2,000 cracks, 1.3 M unknowns, 0.9x, 85-93 s, 1e-6 x max|x|, "
                                           "0.8 x the floor, ~25 min")] == \
        ["1.3 M unknowns", "0.9x", "85-93 s", "0.8 x the floor"]
