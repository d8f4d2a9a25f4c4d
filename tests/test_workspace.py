"""The frozen EOM, its workspace (mechdsl/eom/workspace.py) and the one recorder (simulation/record.py)."""
from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import mechdsl
from mechdsl.eom import workspace
from mechdsl.eom import EOM
from mechdsl.simulation import record as R

from sim_models import pendulum
import mechdsl.examples

MODELS = mechdsl.examples.folder()


def _unshared_pendulum(tag: str):
    """models/pendulum.mech with one more output: a structure no other test derives, so its
    workspace starts empty whatever ran before in the process."""
    text = (MODELS / "pendulum.mech").read_text().replace(
        "end Pendulum;", f"  output Real {tag} = 1.2345 * der(theta);\nend Pendulum;", 1)
    return mechdsl.loads(text)


def _record_keys(m) -> list:
    return [k for k, _ in m.workspace._shared.items() if isinstance(k[0], tuple) and k[0][0] == "record"]


def _fields_only(eom) -> bool:
    return set(vars(eom)) <= set(EOM.__dataclass_fields__)


def test_setting_an_attribute_on_an_eom_raises():
    e = pendulum()
    with pytest.raises(dataclasses.FrozenInstanceError):
        e.g = ca.SX(0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        e._fn_cache = {}                     # not even a private cache
    derived = mechdsl.load(MODELS / "double_pendulum.mech").eom     # the derive route's lazy EOM
    with pytest.raises(dataclasses.FrozenInstanceError):
        derived.M = None
    with pytest.raises(dataclasses.FrozenInstanceError):
        derived.notes = []


@pytest.mark.parametrize("model, kw", [
    ("double_pendulum.mech", {}),
    ("pendulum_cartesian.mech", {"reactions": True}),
    ("pendulum_cartesian.mech", {"method": "rattle", "dt": 0.01}),
    ("bouncing_ball.mech", {}),
    ("pendulum.mech", {"method": "stormer-verlet", "dt": 0.01}),
])
def test_runs_and_analyses_leave_nothing_on_the_eom(model, kw):
    m = mechdsl.load(MODELS / model)
    before = dict(vars(m.eom))
    m.simulate(0.2, points=11, **kw)
    if not m.eom.model.contacts:
        m.first_integrals()
    assert _fields_only(m.eom)
    assert all(vars(m.eom)[k] is v for k, v in before.items())        # no field replaced either
    assert m.workspace is workspace.of(m.eom)


def test_replace_copies_share_content_keyed_values_not_their_own():
    e = pendulum()
    a = e.workspace.memo("x", lambda: object())
    s = e.workspace.shared("y", lambda: object())
    c = e.replace(param_values=np.array([2.0, 1.0, 9.81]))
    assert c.workspace is not e.workspace
    assert c.workspace.memo("x", lambda: "fresh") == "fresh" and e.workspace.memo("x", lambda: None) is a
    assert c.workspace.shared("y", lambda: None) is s
    # by content: shared while the fields read are the same objects, not with other equations
    # (Drive.close_eom's copies: the second of two driven DAE runs used the first one's system)
    v = e.workspace.by_content(e, ("T", "V"), "z", lambda: object())
    assert c.workspace.by_content(c, ("T", "V"), "z", lambda: None) is v
    d = e.replace(V=2 * e.V)
    assert d.workspace.by_content(d, ("T", "V"), "z", lambda: "own") == "own"


def test_recorder_builds_one_function_per_set_of_names_and_reuses_it():
    m = _unshared_pendulum("w_reuse")
    r1 = m.simulate(0.5, points=21)
    keys = _record_keys(m)
    r2 = m.simulate(0.5, points=21)
    other = _unshared_pendulum("w_reuse")        # another model of the same structure and values:
    other.simulate(0.5, points=21)               # its EOM is a copy of the same derivation
    assert other.eom is not m.eom and other.workspace is not m.workspace
    assert len(keys) == 1 and _record_keys(m) == keys and _record_keys(other) == keys
    assert list(r1.signals) == list(r2.signals)
    for k in r1.signals:
        assert r1.signals[k] == pytest.approx(r2.signals[k], rel=0, abs=0)


def test_recorded_columns_against_closed_forms_at_random_states():
    """Energies and a vector output against numpy formulas of the same pendulum (independent of
    CasADi), at random states, parameters and inputs; vector columns are 1-based name[i]."""
    e = pendulum()
    rng = np.random.default_rng(7)
    N = 9
    t = np.sort(rng.uniform(0, 3, N))
    Q = rng.uniform(-3, 3, (N, 1))
    QD = rng.uniform(-5, 5, (N, 1))
    p = np.array([1.7, 0.8, 9.5])                  # m, L, g
    th, w = Q[:, 0], QD[:, 0]
    cols = R.merged(R.energies(e), {"tip": ca.vertcat(p_sin(e), p_cos(e))})
    sig = R.record(e, cols, t, Q, QD, p)
    assert list(sig) == ["kinetic_energy", "potential_energy", "energy", "tip[1]", "tip[2]"]
    T = 0.5 * p[0] * p[1] ** 2 * w ** 2
    V = -p[0] * p[2] * p[1] * np.cos(th)
    assert sig["kinetic_energy"] == pytest.approx(T, rel=1e-14)
    assert sig["potential_energy"] == pytest.approx(V, rel=1e-14)
    assert sig["energy"] == pytest.approx(T + V, rel=1e-13, abs=1e-12)
    assert sig["tip[1]"] == pytest.approx(p[1] * np.sin(th), rel=1e-14)
    assert sig["tip[2]"] == pytest.approx(-p[1] * np.cos(th), rel=1e-14)
    empty = R.record(e, cols, t[:0], Q[:0], QD[:0], p)
    assert list(empty) == list(sig) and all(len(v) == 0 for v in empty.values())


def p_sin(e):
    return e.p[1] * ca.sin(e.q[0])


def p_cos(e):
    return -e.p[1] * ca.cos(e.q[0])


def test_dae_records_multiplier_columns_through_the_recorder():
    """Reaction columns read lam: the recorder's lam input carries the run's multipliers; at
    rest at the bottom the rod force balances gravity (m g = 9.81 N with m = 1)."""
    m = mechdsl.load(MODELS / "pendulum_cartesian.mech")
    r = m.simulate(0.3, points=5, reactions=True, x0={"plane.x": 0.0, "plane.y": -1.0, "der(plane.x)": 0.0, "der(plane.y)": 0.0})
    lam = [k for k in r.signals if k.startswith("lambda[")]
    assert lam
    L = np.abs(r.signals[lam[0]])
    assert L == pytest.approx(np.full_like(L, L[0]), rel=1e-6) and L[0] > 0
    names = list(r.signals)
    assert names.index("energy") < names.index("constraint_drift") < names.index(lam[0])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_one_cold_workspace_used_from_several_threads_at_once():
    """Four threads simulate one model whose workspace is empty (a structure no other test
    derives): every value is built concurrently, the first stored wins, and every thread's
    result equals a later sequential run bit for bit."""
    m = _unshared_pendulum("w_ws")
    out = [None] * 4
    start = threading.Barrier(len(out))

    def run(i):
        start.wait()
        out[i] = m.simulate(0.5, points=21, outputs=("x", "w_ws"))

    threads = [threading.Thread(target=run, args=(i,)) for i in range(len(out))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    alone = m.simulate(0.5, points=21, outputs=("x", "w_ws"))
    assert len(_record_keys(m)) == 1
    for r in out:
        assert list(r.signals) == list(alone.signals) and "w_ws" in r.signals
        np.testing.assert_array_equal(r.q, alone.q)
        for k in alone.signals:
            np.testing.assert_array_equal(r.signals[k], alone.signals[k])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_workspace_dies_with_its_eom():
    import gc
    import weakref

    e = pendulum()
    ws = weakref.ref(e.workspace)
    del e
    gc.collect()
    assert ws() is None


def test_an_eom_read_from_the_model_cache_is_frozen_and_keeps_its_functions_in_the_workspace(tmp_path, monkeypatch):
    """modelcache.unpack_eom used to set the fields it did not hold, the Recorders and the
    stored Functions on the EOM after building it; now they are constructor values and
    workspace entries, and a warm run gives the cold run's numbers bit for bit."""
    from mechdsl import api
    from mechdsl.eom import codegen, modelcache

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(api, "_EOM_CACHE", {})
    monkeypatch.setattr(codegen, "_SETS", {})
    cold_model = mechdsl.load(MODELS / "double_pendulum.mech")
    cold = cold_model.simulate(0.5, points=11)
    cold_model._remember()
    monkeypatch.setattr(api, "_EOM_CACHE", {})
    monkeypatch.setattr(codegen, "_SETS", {})
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    e = m.eom
    assert isinstance(e, modelcache.CachedEOM)
    assert e.workspace.stored_functions(e)                  # the Functions the cold run built
    with pytest.raises(dataclasses.FrozenInstanceError):
        e.M = None
    warm = m.simulate(0.5, points=11)
    assert _fields_only(e)
    np.testing.assert_array_equal(warm.q, cold.q)
    for k in cold.signals:
        np.testing.assert_array_equal(warm.signals[k], cold.signals[k])
