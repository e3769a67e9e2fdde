"""``dualfem bench SPEC -s/-d/-r``: selection and overrides of a sweep spec, and docs/bench.md complete."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from dualfem.core.errors import InputError
from dualfem.experiments import spec as spec_mod
from dualfem.experiments.spec import load_spec
from dualfem.experiments.spec_select import apply_selection, make_selection, parse_pick

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "benchmarks" / "small.toml"


def test_parse_pick_values_and_nesting():
    p = parse_pick("uzawa[r=[1e5, 1e7],tol=1e-9,name_like=clarabel,flag=true,s=\"a,b\"]", "-s")
    assert p.name == "uzawa"
    assert dict(p.overrides) == {"r": [1e5, 1e7], "tol": 1e-9, "name_like": "clarabel", "flag": True, "s": "a,b"}
    assert parse_pick("  f2  ", "-d").overrides == ()


@pytest.mark.parametrize("bad", ["pdas[tol=", "pdas[tol=1]]", "x y", "pdas[=1]", "pdas[tol=1,,r=2]",
                                 "pdas[tol=1,tol=2]", "pdas[1x=3]", "", "a" * 20_000, "pdas[", "pdas[ ",
                                 "pdas]", "pdas[]", "pdas[tol=1][r=2]", "pdas[tol=]", "pdas[tol=\"1]",
                                 "pdas[tol=[1,2]", "[tol=1]", "pdas[tol=1]x"])
def test_parse_pick_refuses(bad):
    with pytest.raises(InputError, match=r"-s/--solver"):
        parse_pick(bad, "-s/--solver")


def test_repeats_range():
    for bad in (0, -1, 1001, True):
        with pytest.raises(InputError, match="-r/--repeats"):
            make_selection(None, None, bad)


def _data():
    return tomllib.loads(SMALL.read_text())


def test_solver_selection_keeps_adds_and_overrides():
    sel = make_selection(["pdas[tol=1e-9]", "osqp[polish=[true,false]]", "mprgp"], None, None)
    out = apply_selection(_data(), sel)
    names = [b["name"] for b in out["solvers"]]
    assert names == ["pdas", "osqp", "mprgp"]                   # mprgp is not in small.toml: added
    assert out["solvers"][0]["params"] == {"tol": 1e-9} and "grid" not in out["solvers"][0]
    assert out["solvers"][1]["grid"] == {"polish": [True, False]} and "params" not in out["solvers"][1]
    assert out["scenes"] == _data()["scenes"]                    # scenes untouched
    assert _data() == tomllib.loads(SMALL.read_text())           # the input is not changed


def test_scene_selection_restricts_dedups_and_adds():
    sel = make_selection(None, ["f2[N=8,delta=[0.1,1e-9]]", "curved"], 2)
    out = apply_selection(_data(), sel)
    # small.toml has two blocks holding f2 (N=16 with f1/f3 and N=32): restricted to f2 with N=8 they coincide
    assert out["scenes"] == [{"scene": "f2", "N": 8, "delta": [0.1, 1e-9]}, {"scene": "curved"}]
    assert out["repeats"] == 2


def test_repeats_override_every_block():
    data = _data()
    data["scenes"][1]["repeats"] = 5
    data["solvers"][0]["repeats"] = 7
    data["floor"] = {"repeats": 4}
    out = apply_selection(data, make_selection(None, None, 1))
    assert out["repeats"] == 1 and out["scenes"][1]["repeats"] == 1 and out["solvers"][0]["repeats"] == 1
    assert out["floor"]["repeats"] == 1


def test_effective_spec_text_reloads_to_the_same_sweep(tmp_path):
    sel = make_selection(["pdas", "osqp[polish=true]"], ["f2[N=8]"], 1, ("-s pdas", "-s 'osqp[polish=true]'"))
    spec = load_spec(SMALL, sel)
    assert spec.text.startswith("# the spec ") and "-s pdas" in spec.text.splitlines()[0]
    again = tmp_path / "spec.toml"
    again.write_text(spec.text)
    re_read = load_spec(again)
    assert [b["name"] for b in re_read.solvers] == ["pdas", "osqp"]
    assert re_read.solvers[1]["params"] == {"polish": True}
    assert re_read.scenes == spec.scenes == [{"scene": "f2", "N": 8, "delta": [0.1, 1e-5, 1e-9]}]
    assert re_read.repeats == 1
    # no selection: the file's own text, as before
    assert load_spec(SMALL).text == SMALL.read_text()


def test_selection_errors_are_the_specs_own():
    with pytest.raises(InputError, match="unknown parameter 'foo' for solver 'pdas'"):
        load_spec(SMALL, make_selection(["pdas[foo=1]"], None, None))
    with pytest.raises(InputError, match="unknown solver 'nosuch'"):
        load_spec(SMALL, make_selection(["nosuch"], None, None))


def test_cli_refuses_bad_selection_before_writing(tmp_path, capsys):
    from dualfem.cli import main

    out = tmp_path / "out"
    assert main(["bench", str(SMALL), "-s", "pdas[tol=", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dualfem bench: error: -s/--solver") and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_docs_name_every_spec_key():
    """docs/bench.md documents every key the spec parser accepts (a new key without docs fails here)."""
    doc = (ROOT / "docs" / "bench.md").read_text()
    spec_block = doc.split("## The spec file", 1)[1]
    documented = set(re.findall(r"^\s*([a-z_]+)\s*=", spec_block, flags=re.M))
    documented |= set(re.findall(r"^\[+([a-z_]+)\]+", spec_block, flags=re.M))
    keys = (spec_mod.SPEC_KEYS | spec_mod.SOLVER_KEYS | spec_mod.REFERENCE_KEYS | spec_mod.FLOOR_KEYS
            | spec_mod.SCENE_KEYS_RESERVED)
    missing = sorted(keys - documented)
    assert not missing, f"docs/bench.md does not document: {missing}"
    for opt in ("-s SOLVER[KEY=V,...]", "-d SCENE[KEY=V,...]", "-r REPEATS"):
        assert opt in doc


def test_solver_params_one_value_per_key():
    from dualfem.experiments.spec_select import solver_params

    assert solver_params(parse_pick("osqp[tol=1e-7,polish=true,backend=x]", "-s")) == {
        "tol": 1e-7, "polish": True, "backend": "x"}
    with pytest.raises(InputError, match=r"-s/--solver.*grid of 'dualfem bench'"):
        solver_params(parse_pick("pdas[tol=[1e-6,1e-9]]", "-s/--solver"))
