"""The explicit workspace: setup / update / solve, what it reuses (counted), what it refuses, and that no
module keeps reusable state any more."""
from __future__ import annotations

import ast
import pickle
from pathlib import Path

import numpy as np
import pytest

from dualfem.core.errors import InputError
from dualfem.core.scene import load_scene
from dualfem.experiments.runner import run
from dualfem.numerics import linalg
from dualfem.numerics.certify import KSolver
from dualfem.workspace import Workspace

ROOT = Path(__file__).resolve().parents[1]
DELTAS = [10.0 ** -k for k in range(1, 10)]


def test_five_line_sweep_reuses_one_assembly_and_one_factorization():
    ws = Workspace("f2", {"N": 12})
    for delta in DELTAS:
        sol = ws.update(delta=delta).solve("pdas")
        assert sol.ok and sol.info["certificate"]["value"] <= 1e-9, (delta, sol.status, sol.message)
        assert ws.qp.params["delta"] == delta and ws.qp.store is ws.store
    assert (ws.builds, ws.assemblies, ws.factorizations) == (9, 1, 1)
    # the reused data gives the answer of a cold, separate build
    cold = run("pdas", load_scene("f2", {"N": 12, "delta": DELTAS[-1]}).build())
    assert np.abs(sol.x - cold.x).max() <= 1e-12 * np.abs(cold.x).max()


def test_setup_factorizes_and_solvers_and_certificate_share_it():
    ws = Workspace("f1", {"N": 12, "delta": 1e-5}).setup()
    assert (ws.builds, ws.assemblies, ws.factorizations) == (1, 1, 1) and len(ws.store) == 1
    for name in ("pdas", "uzawa_auto"):
        assert ws.solve(name).ok
    assert KSolver(ws.qp).red.factor is linalg.factor_fixed(ws.qp)
    assert ws.factorizations == 1
    ws.update(load="f2", load_scale=2.0)                  # another load: same K_fixed, F of its own
    sol = ws.solve("pdas")
    cold = run("pdas", load_scene("f2", {"N": 12, "delta": 1e-5, "load_scale": 2.0}).build())
    assert np.abs(sol.x - cold.x).max() <= 1e-12 * np.abs(cold.x).max()
    assert (ws.assemblies, ws.factorizations) == (1, 1)


def test_clear_and_a_fresh_workspace_factorize_cold():
    ws = Workspace("f2", {"N": 12})
    ws.solve("pdas")
    first = linalg.factor_fixed(ws.qp)
    ws.clear()
    assert len(ws.store) == 0
    ws.solve("pdas")
    assert ws.factorizations == 2 and linalg.factor_fixed(ws.qp) is not first
    assert ws.assemblies == 1                               # clear() keeps the assembly
    other = Workspace("f2", {"N": 12})
    other.solve("pdas")
    assert other.factorizations == 1 and linalg.factor_fixed(other.qp) is not linalg.factor_fixed(ws.qp)
    assert other.qp.K_fixed is not ws.qp.K_fixed            # and assembles on its own


@pytest.mark.parametrize("keys", [{"N": 16}, {"E": 1000.0}, {"nu": 0.2}, {"rotate_deg": 10.0},
                                  {"defect": [[0.25, 0.25], [0.75, 0.25]]}])
def test_updates_that_change_the_mesh_or_K_fixed_are_refused(keys):
    ws = Workspace("f2", {"N": 12}).setup()
    qp = ws.qp
    key = next(iter(keys))
    with pytest.raises(InputError, match=rf"cannot change '{key}'.*new Workspace"):
        ws.update(delta=1e-3, **keys)
    assert ws.qp is qp and ws.problem.params["delta"] == 1e-5          # nothing changed
    with pytest.raises(InputError, match="unknown scene key 'foo'"):
        ws.update(foo=1)
    with pytest.raises(InputError, match="delta"):
        ws.update(delta=-1.0)                                           # validated like a scene key
    assert ws.qp is qp


def test_a_problem_without_update_keys_refuses_every_update(tmp_path):
    path = tmp_path / "q.npz"
    load_scene("f2", {"N": 8}).build().save(path)
    ws = Workspace(str(path))
    assert ws.solve("pdas").ok
    with pytest.raises(InputError, match="update\\(\\) changes only nothing"):
        ws.update(path=str(path))


def test_different_meshes_never_share_a_factorization():
    store = linalg.FactorStore()
    qps = [load_scene("f2", {"N": 12}).build(), load_scene("f2", {"N": 16}).build(),
           load_scene("f2", {"N": 12, "E": 1000.0}).build()]             # same pattern as the first, other values
    factors = []
    for qp in qps:
        qp.store = store
        factors.append(linalg.factor_fixed(qp))
    assert len({id(f) for f in factors}) == 3 and store.factorizations == 3
    assert [linalg.factor_fixed(qp) for qp in qps] == factors            # each finds its own again
    assert linalg.FactorStore().factorizations == 0


def test_a_qp_built_alone_shares_one_factorization_among_compare_and_the_certificate():
    from dualfem.experiments.compare import compare_solvers

    qp = load_scene("f2", {"N": 12, "delta": 1e-9}).build()
    assert qp.store is None
    compare_solvers(qp, ["pdas", "uzawa_auto"])
    assert isinstance(qp.store, linalg.FactorStore) and qp.store.factorizations == 1
    assert KSolver(qp).red.factor is linalg.factor_fixed(qp)
    assert qp.store.factorizations == 1
    other = load_scene("f2", {"N": 12, "delta": 1e-9}).build()           # another QP: its own store
    linalg.factor_fixed(other)
    assert other.store is not qp.store and other.store.factorizations == 1


def test_the_store_is_not_part_of_the_qp_value():
    ws = Workspace("f2", {"N": 8})
    qp = ws.qp
    copy = pickle.loads(pickle.dumps(qp))
    assert copy.store is None and qp.store is ws.store
    assert "store" not in qp.to_dict() and "store=" not in repr(qp)


def _module_level_caches(path: Path) -> list[str]:
    """Module-level names bound to a mutable container ({}, [], set(), dict(), OrderedDict(), ...)."""
    found = []
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets, value = [], None
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        called = ast.unparse(value.func).rsplit(".", 1)[-1] if isinstance(value, ast.Call) else ""
        mutable = isinstance(value, (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp, ast.SetComp)) or \
            called in ("dict", "list", "set", "OrderedDict", "defaultdict", "WeakValueDictionary",
                       "WeakKeyDictionary") or called.endswith(("Cache", "Store"))
        if mutable:
            found += [ast.unparse(t) for t in targets]
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            for deco in node.decorator_list:
                name = ast.unparse(deco)
                if "cache" in name:                       # functools.cache / lru_cache on a module function
                    found.append(f"@{name} {node.name}")
    return found


def test_no_module_level_reuse_state():
    files = [ROOT / "dualfem/numerics/linalg.py", ROOT / "dualfem/experiments/workspace.py",
             *sorted((ROOT / "problems/thin_defect").glob("*.py"))]
    assert all(f.exists() for f in files)
    assert {str(f.relative_to(ROOT)): c for f in files if (c := _module_level_caches(f))} == {}
    assert not (ROOT / "dualfem/core/caches.py").exists()
    for name in ("DEFAULT_CACHE", "FactorCache", "clear_cache", "_FROZEN_HASHES"):
        assert not hasattr(linalg, name), name
    import dualfem.problems.thin_defect as td

    assert not hasattr(td, "_ASSEMBLY") and not hasattr(td, "clear_assembly_cache")


def test_linear_algebra_page_example_runs(capsys):
    """The five-line sweep of docs/linear_algebra.md (at a small N)."""
    text = (ROOT / "docs" / "linear_algebra.md").read_text(encoding="utf-8")
    block = next(b.split("```", 1)[0] for b in text.split("```python\n")[1:] if "dualfem.workspace" in b)
    assert len([ln for ln in block.splitlines() if ln.strip()]) == 5
    ns: dict = {}
    exec(block.replace('"N": 256', '"N": 12'), ns)      # noqa: S102 - the project's own docs
    ws = ns["ws"]
    assert (ws.assemblies, ws.factorizations) == (1, 1)
    assert capsys.readouterr().out.count("solved") == 3


def test_the_workspace_backend_goes_to_setup_and_solvers():
    from dualfem.numerics.factor import available

    ws = Workspace("f2", {"N": 12}, factor="superlu").setup()
    sol = ws.solve("pdas")
    assert sol.ok and sol.params["factor"] == "superlu" and ws.factorizations == 1
    assert linalg.factor_fixed(ws.qp, "superlu").backend == "superlu"
    assert ws.solve("pdas", {"factor": available()[0]}).ok      # the solver's own choice wins
    with pytest.raises(InputError, match="factor"):
        Workspace("f2", {"N": 12}, factor="no_such_backend")


def test_a_problem_instance_and_its_updates():
    problem = load_scene("f3", {"N": 12})
    ws = Workspace(problem, {"delta": 1e-3})
    assert ws.problem.params["delta"] == 1e-3 and ws.problem.shared is problem.shared
    assert ws.update(delta=1e-7).solve("uzawa_auto").ok
    assert problem.params["delta"] == 1e-5                      # the given instance is left as it was
    assert (ws.builds, ws.assemblies, ws.factorizations) == (1, 1, 1)
    assert "assemblies=1" in repr(ws)
