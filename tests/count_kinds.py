"""Count the collected test items by kind: validation, physics, consistency (issue 24, item 7).

Not a test module (no ``test_`` prefix: pytest does not collect it). Usage, from the repository root::

    python tests/count_kinds.py                        # collects with pytest --collect-only -q
    python tests/count_kinds.py --ids FILE             # node ids read from FILE (output of --collect-only -q)
    python tests/count_kinds.py --junit report.xml     # also sums the time per kind from a pytest --junitxml file

The rule (first match wins; a node id is ``tests/<module>.py::<test name>[<parameters>]``, and only
the module and the test name are looked at, never the parameters):

1. **validation** if the module is one of :data:`VALIDATION_MODULES` (the bad-input corpus, the
   solver-parameter ranges, the robustness corpus, environment errors: modules that exist to check
   that bad input is refused), or
2. **physics** if the module is one of :data:`PHYSICS_MODULES` or the test name matches
   :data:`PHYSICS_NAME` (a known answer of the mechanics: the paper's tables, convergence rates,
   the delta limits, patch tests, exact uniform states, equilibrium / resultants, symmetry of the
   solution, opening / closing of the defect), or
3. **validation** if the test name matches :data:`VALIDATION_NAME` (refused / bad / invalid /
   malformed / unknown / missing / one-line error ... : input checks living in other modules), else
4. **consistency**: everything else (solvers agree with each other or with a certified reference,
   scale invariance, reproducibility, I/O round trips, caches, reports, the harness).

The time per kind (``--junit``) is the sum of the ``time`` attribute of the junit ``testcase``
elements, i.e. pytest's own measured call time of each item (setup of shared fixtures is charged to
the first item that uses them); without ``--junit`` no time is printed and the script says so.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

VALIDATION_MODULES = {"test_bad_input.py", "test_solver_params.py", "test_robustness.py",
                      "test_environment_errors.py"}
PHYSICS_MODULES = {"test_physics.py"}
PHYSICS_NAME = re.compile(
    r"patch|paper_table|report_paper|iteration_counts|convergence_rate|known_answer|delta_limit|glued|"
    r"free_crack|uniaxial|uniform_pressure|uniform_stress|equilibrium|resultant|opens_and|softer|"
    r"rigid_motions|von_mises|linear_field|trapezoid|symmetric_contact|point_symmetry|"
    r"symmetric_scene_is_symmetric|indentation|touches_the_floor", re.I)
VALIDATION_NAME = re.compile(
    r"refus|reject|bad|invalid|malformed|unknown|missing|not_a_number|out_of_range|input_error|"
    r"one_line|declares_its_range|validation|corrupt|unsafe|clobber|writes_nothing|read_only|enospc|"
    r"size_limit|full_device|no_traceback|checks_parameters", re.I)
KINDS = ("validation", "physics", "consistency")


def kind(node_id: str) -> str:
    """The kind of one collected item (see the module docstring for the rule)."""
    path, _, rest = node_id.partition("::")
    module = Path(path).name
    name = rest.split("[", 1)[0]
    if module in VALIDATION_MODULES:
        return "validation"
    if module in PHYSICS_MODULES or PHYSICS_NAME.search(name):
        return "physics"
    if VALIDATION_NAME.search(name):
        return "validation"
    return "consistency"


def collect(root: Path) -> list[str]:
    r = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"],
                       cwd=root, capture_output=True, text=True)
    ids = [ln.strip() for ln in r.stdout.splitlines() if "::" in ln]
    if not ids:
        raise SystemExit(f"no test collected:\n{r.stdout}\n{r.stderr}")
    return ids


def junit_times(path: Path) -> dict[str, float]:
    """{node id: seconds} from a pytest --junitxml file."""
    out = {}
    for tc in ET.parse(path).getroot().iter("testcase"):
        cls, name = tc.get("classname", ""), tc.get("name", "")
        mod = cls.replace(".", "/") + ".py"
        out[f"{mod}::{name}"] = float(tc.get("time", 0.0))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ids", type=Path, help="node ids, one a line (pytest --collect-only -q output)")
    ap.add_argument("--junit", type=Path, help="a pytest --junitxml report: time per kind")
    ap.add_argument("--top", type=int, default=5, help="print the N largest parametrized tests (default 5)")
    a = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[1]
    ids = ([ln.strip() for ln in a.ids.read_text().splitlines() if "::" in ln] if a.ids else collect(root))
    counts = Counter(kind(i) for i in ids)
    total = len(ids)
    times: dict[str, float] | None = None
    if a.junit:
        jt = junit_times(a.junit)
        times = Counter()
        for i in ids:
            times[kind(i)] += jt.get(i, 0.0)
    print(f"{total} items")
    for k in KINDS:
        t = f"  {times[k]:8.1f} s" if times is not None else ""
        print(f"  {k:12s} {counts[k]:5d}  {100 * counts[k] / total:5.1f} %{t}")
    print(f"time source: {'junit XML ' + str(a.junit) + ' (pytest call times)' if a.junit else 'none (pass --junit)'}")
    per_test = Counter(i.split("[", 1)[0] for i in ids)
    print(f"largest tests by item count (top {a.top}):")
    for name, n in per_test.most_common(a.top):
        print(f"  {n:5d}  {kind(name):12s} {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
