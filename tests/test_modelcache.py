"""The model cache (mechdsl.eom.modelcache): a second run neither parses nor derives, gives the
same numbers bit for bit, and a changed, corrupt or foreign cache file is rebuilt."""
import os
import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

import mechdsl.api as api
import mechdsl.eom.codegen as codegen
import mechdsl.mechanics
import mechdsl.frontend.parser
from mechdsl.eom import modelcache
from mechdsl.cli import main

from conftest import MODELS, drop_prepared_runs

WARNING_MODEL = """model P
  parameter Real m(unit = "kg") = 1;
  parameter Real L(unit = "m") = 1;
  coordinate Real theta(start = 1, speed = 0, unit = "rad");
  output Real E(unit = "J") = energy();
equation
  kinetic = 1/2*m*L^2*der(theta)^2;
  potential = m*9.81*L*(1 - cos(theta));
end P;
"""


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache folder and empty in-memory caches (as in a new process)."""
    d = tmp_path / "cache"
    monkeypatch.setenv("MECHDSL_CACHE", str(d))
    fresh(monkeypatch)
    return d / "models"


def fresh(monkeypatch):
    monkeypatch.setattr(api, "_EOM_CACHE", {})
    monkeypatch.setattr(codegen, "_SETS", {})


def forbid_front_end_and_derivation(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("parsed or derived on a cache hit")

    monkeypatch.setattr(mechdsl.mechanics, "derive", boom)
    monkeypatch.setattr(mechdsl.frontend.parser, "parse", boom)


def forbid_building_functions(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("built a CasADi Function the cache holds")

    monkeypatch.setattr(codegen, "_build", boom)


def entries(d):
    return sorted(d.glob("*.pkl")) if d.exists() else []


def simulate_csv(path, out, *extra):
    drop_prepared_runs(os.environ["MECHDSL_CACHE"])      # (these tests are about the model cache)
    assert main(["simulate", str(path), "--t-end", "0.5", "--points", "51", "--no-progress", "-o", str(out),
                 "--force", *extra]) == 0
    return out.read_bytes()


@pytest.mark.parametrize("name", ["double_pendulum", "pendulum_cartesian", "bouncing_ball", "heavy_top"])
def test_warm_run_is_bit_identical_and_neither_parses_nor_derives(cache, tmp_path, monkeypatch, capsys, name):
    """ODE, DAE, contact (hybrid) and fixed-step (canonical) problems."""
    model = MODELS / f"{name}.mech"
    cold = simulate_csv(model, tmp_path / "cold.csv")
    assert entries(cache), "the first run wrote no cache entry"
    fresh(monkeypatch)
    forbid_front_end_and_derivation(monkeypatch)
    forbid_building_functions(monkeypatch)
    warm = simulate_csv(model, tmp_path / "warm.csv")
    assert warm == cold


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_structural_settings_are_part_of_the_key(cache, tmp_path, monkeypatch):
    model = MODELS / "nlink_pendulum.mech"
    cold4 = simulate_csv(model, tmp_path / "a.csv", "--set", "N=4")
    cold3 = simulate_csv(model, tmp_path / "b.csv", "--set", "N=3")
    fresh(monkeypatch)
    forbid_front_end_and_derivation(monkeypatch)
    assert simulate_csv(model, tmp_path / "c.csv", "--set", "N=4") == cold4
    assert simulate_csv(model, tmp_path / "d.csv", "--set", "N=3") == cold3
    assert cold3 != cold4
    m = api.load(model).with_params(N=4)
    assert len(m.coordinates) == 4


def test_a_changed_file_is_analysed_and_derived_again(cache, tmp_path, monkeypatch):
    f = tmp_path / "p.mech"
    f.write_text(WARNING_MODEL)
    m1 = api.load(f)
    e1 = m1.eom
    m1.first_integrals()                                # an analysis stores the equations too
    assert modelcache.read(m1._cache.key).eom is not None
    f.write_text(WARNING_MODEL.replace("parameter Real m(unit = \"kg\") = 1;", "parameter Real m(unit = \"kg\") = 3;")
                 .replace("1/2*m*L^2", "1/3*m*L^2"))
    fresh(monkeypatch)
    calls = []
    derive = mechdsl.mechanics.derive
    monkeypatch.setattr(mechdsl.mechanics, "derive", lambda m: calls.append(1) or derive(m))
    m2 = api.load(f)
    assert m2.parameters["m"] == pytest.approx(3.0)
    e2 = m2.eom
    assert calls == [1]
    th, thd = 0.7, 1.3
    t1 = ca.Function("T", [e1.q, e1.qd, e1.p], [e1.T])([th], [thd], e1.param_values)
    t2 = ca.Function("T", [e2.q, e2.qd, e2.p], [e2.T])([th], [thd], e2.param_values)
    assert float(t1) == pytest.approx(0.5 * thd ** 2)          # 1/2 m L^2 thd^2, m = 1
    assert float(t2) == pytest.approx(thd ** 2)                # 1/3 m L^2 thd^2, m = 3


def test_warnings_of_the_front_end_are_kept(cache, tmp_path, monkeypatch):
    f = tmp_path / "w.mech"
    f.write_text(WARNING_MODEL)
    first = api.load(f)
    first.simulate(0.1, points=3)
    assert [w.code for w in first.warnings] == ["W402"]
    fresh(monkeypatch)
    forbid_front_end_and_derivation(monkeypatch)
    again = api.load(f)
    assert again._program is None                      # served from the cache
    assert again.warnings == first.warnings


@pytest.mark.slow_cases('flip', 'foreign-pickle', 'header')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("damage", ["truncate", "flip", "garbage", "empty", "header", "foreign-pickle"])
def test_a_corrupt_cache_file_is_rebuilt(cache, tmp_path, monkeypatch, damage):
    model = MODELS / "double_pendulum.mech"
    cold = simulate_csv(model, tmp_path / "cold.csv")
    for p in entries(cache):
        data = p.read_bytes()
        head, _, payload = data.partition(b"\n")
        if damage == "truncate":
            p.write_bytes(data[: len(data) // 2])
        elif damage == "flip":
            p.write_bytes(data[:-10] + bytes([data[-10] ^ 0xFF]) + data[-9:])
        elif damage == "garbage":
            p.write_bytes(os.urandom(len(data)))
        elif damage == "empty":
            p.write_bytes(b"")
        elif damage == "header":
            p.write_bytes(b"not a cache file\n" + payload)
        else:   # right format and hash, but not an entry
            import hashlib
            import pickle

            other = pickle.dumps({"something": "else"})
            p.write_bytes(f"{modelcache.FORMAT} {hashlib.sha256(other).hexdigest()}\n".encode() + other)
    fresh(monkeypatch)
    rebuilt = simulate_csv(model, tmp_path / "again.csv")
    assert rebuilt == cold
    for p in entries(cache):           # rewritten, and usable
        assert modelcache.read(p.stem) is not None


def test_an_unusable_cache_folder_is_no_error(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("MECHDSL_CACHE", str(blocker))
    fresh(monkeypatch)
    out = tmp_path / "r.csv"
    simulate_csv(MODELS / "pendulum.mech", out)
    assert out.exists()


def test_no_cache_option_and_api_flag(cache, tmp_path, monkeypatch):
    simulate_csv(MODELS / "pendulum.mech", tmp_path / "a.csv", "--no-cache")
    assert entries(cache) == []
    m = api.load(MODELS / "pendulum.mech", cache=False)
    m.simulate(0.1, points=3)
    api.loads(WARNING_MODEL, cache=False).eom
    assert entries(cache) == []
    api.load(MODELS / "pendulum.mech").eom
    assert len(entries(cache)) == 1


def test_fields_not_cached_are_derived_again_in_the_cached_symbols(cache, monkeypatch):
    """The 'aba' route builds M and bias lazily; an entry written before they were built
    serves them by a new derivation substituted into the cached symbols: the same numbers
    as a fresh derivation at random states (an independent route: M from the Lagrangian)."""
    model = MODELS / "nlink_pendulum.mech"
    m = api.load(model).with_params(N=3)
    e = m.eom
    m._remember()                                       # an entry written before M and bias were built
    assert e.route == "aba"
    assert "M" in modelcache.read(m._cache.key).eom["pending"]
    fresh(monkeypatch)
    c = api.load(model).with_params(N=3).eom
    assert isinstance(c, modelcache.CachedEOM)
    rng = np.random.default_rng(7)
    fM = ca.Function("M", [c.q, c.p], [c.M])
    fT = ca.Function("T", [c.q, c.qd, c.p], [c.T])
    for _ in range(3):
        q, qd = rng.normal(size=3), rng.normal(size=3)
        M = np.array(fM(q, c.param_values))
        assert qd @ M @ qd / 2 == pytest.approx(float(fT(q, qd, c.param_values)), rel=1e-12)
    pos = ca.Function("r", [c.q, c.p], [c.point_position("link[3].b")])
    # straight down at q = 0: the tip 3 rods below the hinge
    assert np.array(pos(np.zeros(3), c.param_values)).ravel() == pytest.approx([0, -3, 0], abs=1e-12)


def test_key_depends_on_text_target_items_and_limits():
    from mechdsl.frontend import limits

    base = modelcache.key("text", "f.mech", True, (None, None), ())
    assert base == modelcache.key("text", "f.mech", True, (None, None), ())
    others = [modelcache.key("text2", "f.mech", True, (None, None), ()),
              modelcache.key("text", "g.mech", True, (None, None), ()),
              modelcache.key("text", "f.mech", False, (None, None), ()),
              modelcache.key("text", "f.mech", True, ("M", None), ()),
              modelcache.key("text", "f.mech", True, (None, None), (("N", 3.0),))]
    with limits.override(coordinates=5000):
        others.append(modelcache.key("text", "f.mech", True, (None, None), ()))
    assert len({base, *others}) == len(others) + 1


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_warm_process_imports_neither_lark_nor_the_front_end_nor_the_mechanics(tmp_path):
    env = {**os.environ, "MECHDSL_CACHE": str(tmp_path / "cache")}
    cmd = [sys.executable, "-X", "importtime", "-m", "mechdsl", "simulate", str(MODELS / "pendulum.mech"),
           "--t-end", "0.1", "--points", "3", "--no-progress"]
    runs = [subprocess.run(cmd, env=env, capture_output=True, text=True) for _ in range(2)]
    assert [r.returncode for r in runs] == [0, 0], runs[1].stderr[-2000:]
    loaded = [{line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time")}
              for r in runs]
    heavy = {"lark", "mechdsl.frontend.parser", "mechdsl.semantic", "mechdsl.mechanics", "mechdsl.frontend.ast"}
    assert heavy <= loaded[0]                 # the cold run needs them: the check can fail
    assert not heavy & loaded[1]



@pytest.mark.parametrize("real", [False, True])
def test_a_cached_model_pickles_with_its_structural_overrides(cache, monkeypatch, real):
    """Sweeps on worker processes pickle a Model by its source and overrides: a Model read
    from the cache (and its parameter-value siblings) must carry its structural --set values."""
    import pickle

    model = MODELS / "nlink_pendulum.mech"
    api.load(model).with_params(N=4).eom
    fresh(monkeypatch)
    m = api.load(model).with_params(N=4)
    assert m._program is None                           # served from the cache
    if real:
        m = m.with_params(m=2.0)
    back = pickle.loads(pickle.dumps(m))
    assert len(back.coordinates) == 4
    assert back.parameters["m"] == pytest.approx(2.0 if real else 1.0)


def test_the_cache_keeps_a_bounded_number_of_entries(cache, monkeypatch):
    monkeypatch.setattr(modelcache, "MAX_ENTRIES", 3)
    for k in range(5):
        api.loads(WARNING_MODEL.replace("= 1;", f"= {k + 1};", 1))
    assert len(entries(cache)) == 3
    newest = api.loads(WARNING_MODEL.replace("= 1;", "= 5;", 1))._cache.key
    assert modelcache.read(newest) is not None                # the last written stays


def test_functions_with_fixed_parameters_are_not_served_for_free_ones(cache, monkeypatch):
    """Model.casadi(fixed_parameters=...) builds Functions with parameters as numbers; the
    cache must never hand them out where p holds every parameter (or the reverse)."""
    model = MODELS / "pendulum.mech"
    m = api.load(model, model="Pendulum")
    n_p = len(m.parameter_names)
    assert m.casadi(fixed_parameters=True)["ode"].size1_in(3) == 0
    m.simulate(0.1, points=3)                           # writes the entry with the run's Functions
    fresh(monkeypatch)
    again = api.load(model, model="Pendulum")
    assert again.casadi()["ode"].size1_in(3) == n_p
    assert again.casadi(fixed_parameters=True)["ode"].size1_in(3) == 0


def test_an_edited_mechdsl_is_a_new_key(tmp_path, monkeypatch):
    """Developers change mechdsl under one version number: the key includes the sources'
    sizes and modification times, so equations derived by older code are not served."""
    pkg = tmp_path / "src" / "mechdsl"
    (pkg / "eom").mkdir(parents=True)
    (pkg / "eom" / "modelcache.py").write_text("# stand-in\n")
    derive = pkg / "derive.py"
    derive.write_text("x = 1\n")
    monkeypatch.setattr(modelcache, "__file__", str(pkg / "eom" / "modelcache.py"))
    monkeypatch.setattr(modelcache, "_FINGERPRINT", [])
    before = modelcache.code_fingerprint()
    assert modelcache.code_fingerprint() == before              # stable within a process
    k1 = modelcache.key("text", "f.mech", True, (None, None), ())
    derive.write_text("x = 22\n")
    monkeypatch.setattr(modelcache, "_FINGERPRINT", [])
    assert modelcache.code_fingerprint() != before
    assert modelcache.key("text", "f.mech", True, (None, None), ()) != k1
