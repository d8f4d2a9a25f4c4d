"""Issue 24, items 1 and 2: a warm run builds nothing again, the error estimate's companion runs
without recording, and ``auto`` chooses by the model and the options alone.

What is kept between runs (backends/ode.kept_setup, Model's kept problems) must not change a
number or the method: every test compares a warm run with a run that built everything afresh."""
import warnings

import numpy as np
import pytest

import mechdsl
from conftest import MODELS, needs_cc
from mechdsl.simulation.backends import crk
from mechdsl.simulation.backends import ode as O



@pytest.fixture(scope="module")
def double():
    return mechdsl.load(MODELS / "double_pendulum.mech", scene="Chaos")


def _run(m, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return m.simulate(**kw)


@needs_cc
def test_auto_takes_dopri5_at_loose_tolerances_and_dop853_below(double):
    """The rule of crk.loop_method: dopri5 at rtol >= DOPRI5_RTOL, else dop853 (benchmarks/auto_wp.py)."""
    loose = _run(double, t_end=2.0, rtol=1e-3, atol=1e-6)
    tight = _run(double, t_end=2.0, rtol=1e-6, atol=1e-8)
    assert crk.DOPRI5_RTOL == 1e-4
    assert loose.metadata["method"] == "dopri5" and tight.metadata["method"] == "dop853"
    assert "dopri5" in loose.metadata["method_reason"]
    # its error estimate's companion keeps the method that ran (at the tighter tolerance)
    assert "10x tighter" in loose.metadata["accuracy"]["error_estimate_method"]
    assert crk.loop_method(1e-4) == "dopri5" and crk.loop_method(9.9e-5) == "dop853"


@needs_cc
def test_a_warm_run_is_the_run_built_afresh(double, monkeypatch):
    """Same model and options -> same method and the same numbers, whatever the caches hold: the
    second call reuses the kept setup and problem, the third builds everything again."""
    first = _run(double, t_end=3.0, rtol=1e-7)
    warm = _run(double, t_end=3.0, rtol=1e-7)
    monkeypatch.setattr(O, "_SETUPS", {})
    double.__dict__.pop("_runs", None)
    fresh = _run(double, t_end=3.0, rtol=1e-7)
    for r in (warm, fresh):
        assert r.metadata["method"] == first.metadata["method"] == "dop853"
        np.testing.assert_array_equal(r.q, first.q)          # the same steps: the same bits
        np.testing.assert_array_equal(r["energy"], first["energy"])
        assert r.metadata["accuracy"]["error_estimate"] == first.metadata["accuracy"]["error_estimate"]
        assert r.stats["rhs_evals"] == first.stats["rhs_evals"]
    # each Result owns its metadata and arrays: changing one leaves the next run alone
    warm.metadata["notes"].append("mine")
    warm.metadata["options"]["parameters"].clear()
    again = _run(double, t_end=3.0, rtol=1e-7)
    assert "mine" not in again.metadata["notes"] and again.metadata["options"]["parameters"]
    assert again.q is not warm.q


def test_other_arguments_are_other_runs(double):
    """A kept problem is found by all the arguments: another tolerance, start or end is another run."""
    a = _run(double, t_end=1.0, rtol=1e-6)
    b = _run(double, t_end=1.0, rtol=1e-9)
    c = _run(double, t_end=1.0, rtol=1e-6, x0={"j1.phi": 0.5})
    d = _run(double, t_end=0.5, rtol=1e-6)
    assert a.metadata["options"]["rtol"] == 1e-6 and b.metadata["options"]["rtol"] == 1e-9
    assert c.metadata["options"]["start"]["j1.phi"] == 0.5 != a.metadata["options"]["start"]["j1.phi"]
    assert d.t[-1] == 0.5 and a.t[-1] == 1.0
    assert len(double.__dict__.get("_runs", {})) <= double.RUNS_KEPT


def test_companion_work_is_counted_and_is_an_independent_run(double):
    """stats["error_estimate_rhs_evals"] / ["error_estimate_steps"]: the companion's own work
    (benchmarks/nlink_run.py counts it); the estimate is |run - companion| / (1 - 1/10) at the
    companion's times, checked against a run made by hand at the companion's settings."""
    r = _run(double, t_end=4.0, rtol=1e-6, atol=1e-8, points=401)
    acc = r.metadata["accuracy"]
    method = r.metadata["method"]
    hand = _run(double, t_end=4.0, rtol=1e-7, atol=1e-9, points=201, method=method, error_estimate="off")
    assert r.stats["error_estimate_rhs_evals"] == hand.stats["rhs_evals"] > 0
    assert r.stats["error_estimate_steps"] == hand.stats["steps"] > 0
    diff = np.abs(r.q[::2] - hand.q).max(axis=0) / 0.9
    k = int(np.argmax(diff))
    assert acc["error_estimate_coordinate"] == r.coordinates[k]
    assert acc["error_estimate"] == pytest.approx(diff[k], rel=1e-9)


def test_estimate_off_has_no_companion_work(double):
    r = _run(double, t_end=1.0, error_estimate="off")
    assert r.stats.get("error_estimate_rhs_evals") is None


def test_kept_setups_are_bounded_and_keyed_by_values():
    """Array start and parameter values are part of the key by value (a benchmark passes the
    parameter vector as an array); the store holds at most SETUPS_KEPT setups."""
    from mechdsl.simulation.settings import SimulationSettings

    s = SimulationSettings(t_end=1.0)
    a = O._frozen(s.replace(p=np.array([1.0, 2.0])))
    b = O._frozen(s.replace(p=np.array([1.0, 2.0])))
    c = O._frozen(s.replace(p=np.array([1.0, 3.0])))
    assert a == b and hash(a) == hash(b) and a != c
    assert O._frozen(s.replace(x0={"a": 1.0})) == O._frozen(s.replace(x0={"a": 1.0}))
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    for k in range(O.SETUPS_KEPT + 3):
        _run(m, t_end=0.1 + 0.01 * k, points=3)
    assert len(O._SETUPS) <= O.SETUPS_KEPT


def test_plain_copy_is_deep():
    meta = {"a": [1, {"b": [2.0, "x"]}], "t": (1, 2), "c": {"d": None}}
    cp = O.plain_copy(meta)
    assert cp == meta
    cp["a"][1]["b"].append(3)
    cp["c"]["d"] = 1
    assert meta == {"a": [1, {"b": [2.0, "x"]}], "t": (1, 2), "c": {"d": None}}
    copy = O.plain_copier(meta)          # (the settings' plain form: its containers found once)
    for _ in range(2):
        cp = copy()
        assert cp == meta
        cp["a"][1]["b"].append(3)
        cp["c"]["d"] = 1
        assert meta == {"a": [1, {"b": [2.0, "x"]}], "t": (1, 2), "c": {"d": None}}


def test_non_finite_signal_still_fails_the_run():
    """The non-finite check's quick path (a finite sum) must not hide an inf or a nan."""
    from mechdsl.output.result import Result
    from mechdsl.simulation.accuracy import check_finite

    t = np.linspace(0, 1, 5)
    q = np.zeros((5, 1))
    sig = np.array([0.0, 1.0, np.inf, 2.0, 3.0])
    r = Result(t=t, q=q, qd=q.copy(), coordinates=("x",), signals={"y": sig}, stats={}, metadata={})
    check_finite(r)
    assert r.failure is not None and r.failure.cause == "non-finite output" and len(r.t) == 2
    big = np.array([1e308, 1e308, 1.0])          # a sum that overflows, every value finite
    r = Result(t=t[:3], q=q[:3], qd=q[:3].copy(), coordinates=("x",), signals={"y": big}, stats={}, metadata={})
    check_finite(r)
    assert r.failure is None and len(r.t) == 3
    qn = q.copy()
    qn[3, 0] = np.nan
    r = Result(t=t, q=qn, qd=q.copy(), coordinates=("x",), signals={}, stats={}, metadata={})
    check_finite(r)
    assert r.failure is not None and r.failure.cause == "non-finite state" and len(r.t) == 3


@needs_cc
def test_the_companion_in_the_runs_own_call_gives_the_same_estimate(double, monkeypatch):
    """From the second warm run on, the default estimate's companion runs in the run's own C call
    (crk_run_pair, backends/ode.Partner): the same run, the same companion, so the same estimate
    and the same work as the companion run on its own (no Partner kept on the setups); its seconds are the
    estimate's (error_estimate_cpu_time), not the run's."""
    runs = [_run(double, t_end=2.0, rtol=1e-8) for _ in range(3)]
    paired = runs[-1]
    assert "companion_cpu_time" in paired.stats["raw"]          # the pair ran
    from mechdsl.simulation import estimate as E

    for _, setup in O._SETUPS.values():
        monkeypatch.setattr(setup, "partner", None)
    monkeypatch.setattr(E, "partner", lambda run, setup, pv, xs: O.Partner(setup, pv, xs))   # never registered
    alone = _run(double, t_end=2.0, rtol=1e-8)
    assert "companion_cpu_time" not in alone.stats["raw"]
    np.testing.assert_array_equal(paired.q, alone.q)
    for key in ("error_estimate", "error_estimate_time", "error_estimate_coordinate", "error_estimate_ratio"):
        assert paired.metadata["accuracy"][key] == alone.metadata["accuracy"][key]
    for key in ("rhs_evals", "error_estimate_rhs_evals", "error_estimate_steps", "steps"):
        assert paired.stats[key] == alone.stats[key]
    raw = paired.stats["raw"]
    assert 0.0 <= raw["companion_cpu_time"] <= paired.stats["error_estimate_cpu_time"] + 1e-9


@pytest.mark.parametrize("case", ["plain", "nan", "inf", "zeros", "signed zeros"])
def test_the_facts_from_the_extremes_are_note_facts(case):
    """accuracy.note_extremes (the recorder's columns and their extremes from its C pass) notes the
    numbers note_facts' numpy pass notes, or nothing where numpy's order decides a zero's sign."""
    from mechdsl.simulation import accuracy as A

    rng = np.random.default_rng(3)
    block = rng.normal(size=(4, 50))
    if case == "nan":
        block[1, 7] = np.nan
    elif case == "inf":
        block[2, 0], block[3, 9] = np.inf, -np.inf
    elif case == "zeros":           # a kinetic energy from rest: its smallest value a zero
        block[0] = np.abs(block[0])
        block[0, 3] = 0.0
    elif case == "signed zeros":    # zeros of both signs at an extreme (also a constant zero: -lo is -0)
        block[1] = np.abs(block[1])
        block[1, 2], block[1, 5] = 0.0, -0.0
    rows = [block[i] for i in range(4)]
    finite = np.isfinite(block).all(axis=1)
    hi = [float(np.max(r)) if f else np.nan for r, f in zip(rows, finite | np.isinf(block).any(axis=1))]
    lo = [float(np.min(r)) if f else np.nan for r, f in zip(rows, finite | np.isinf(block).any(axis=1))]
    both = [bool(((r == 0) & np.signbit(r)).any() and ((r == 0) & ~np.signbit(r)).any()) for r in rows]
    flags = [1.0 if b and (h == 0 or lo_ == 0) else 0.0 for b, h, lo_ in zip(both, hi, lo)]
    A._FACTS.clear()
    noted = A.note_extremes(block, rows, hi + lo + flags)
    assert noted == (case != "signed zeros")
    mine = {id(v): A._FACTS.get(id(v), (None,))[1:] for v in rows}
    A._FACTS.clear()
    A.note_facts(block, rows)
    theirs = {id(v): A._FACTS[id(v)][1:] for v in rows}
    if noted:
        for k in theirs:       # (finite, max |v|, max |v - v0|): the same floats (nan as nan)
            assert [x if x == x else "nan" for x in mine[k]] == [x if x == x else "nan" for x in theirs[k]]


@needs_cc
def test_the_recorders_columns_are_its_rows(double):
    """Mapped.columns (crk_map_cols: the values by column and their extremes in one C pass) gives
    the recorder's values of Mapped.states, and extremes that are the columns' max and min."""
    for _ in range(2):
        _run(double, t_end=1.0, rtol=1e-8)
    s = next(v[1] for v in O._SETUPS.values() if v[0] is double.eom and v[1].settings.rtol == 1e-8
             and v[1]._recorders)
    pv, rec = next(iter(s._recorders.items()))
    fast = dict(zip(rec.__code__.co_freevars, (c.cell_contents for c in rec.__closure__)))["fast"]
    r = _run(double, t_end=1.0, rtol=1e-8)
    X, pv = np.ascontiguousarray(np.c_[r.q, r.qd]), np.frombuffer(pv, float).copy()
    vals, extremes = fast.columns(r.t, X, 2, pv)
    rows = fast.states(r.t, X, 2, pv)
    np.testing.assert_array_equal(vals, rows.T)
    k = vals.shape[0]
    assert extremes[:k] == vals.max(axis=1).tolist() and extremes[k:2 * k] == vals.min(axis=1).tolist()
    assert extremes[2 * k:] == [0.0] * k


@needs_cc
def test_the_kept_pair_call_is_the_call_prepared_afresh(double):
    """A setup keeps its run + companion C call prepared (crk_calls.KeptPair): a call from other
    start values gives the bits of the call prepared afresh (crk.run_pair), and each call's rows
    are its own (a later call writes fresh buffers, never an earlier Run's X)."""
    for _ in range(3):
        _run(double, t_end=1.0, rtol=1e-8)
    s = next(v[1] for v in O._SETUPS.values() if v[0] is double.eom and v[1].settings.rtol == 1e-8
             and v[1]._pairs)
    partner_setup, other, kp = next(iter(s._pairs.values()))
    assert kp is not None
    loop, method, grid, u, rtol, atol, max_steps, hmin = s._direct_call()
    loop2, method2, grid2, u2, rtol2, atol2, max_steps2, hmin2 = other
    pv = next(iter(s._recorders))
    pv = np.frombuffer(pv, float).copy()
    first = None
    for xs in (np.array([1.0, 0.5, 0.0, 0.0]), np.array([0.3, -0.2, 0.1, 0.0])):
        kept, kept2 = crk.run_kept_pair(kp, xs, pv, xs, pv, crk.I.Progress(None, 0.0, 1.0), (max_steps, hmin),
                                        (max_steps2, hmin2))
        fresh, fresh2 = crk.run_pair(loop, (method, grid, xs, pv, u, rtol, atol, max_steps, hmin), loop2,
                                     (method2, grid2, xs, pv, u2, rtol2, atol2, max_steps2, hmin2),
                                     crk.I.Progress(None, 0.0, 1.0))
        np.testing.assert_array_equal(kept.X, fresh.X)
        np.testing.assert_array_equal(kept2.X, fresh2.X)
        assert kept.stats["n_rhs"] == fresh.stats["n_rhs"] and kept2.stats["n_rhs"] == fresh2.stats["n_rhs"]
        if first is None:
            first, rows = kept, kept.X.copy()
    assert not np.array_equal(first.X, kept.X)
    np.testing.assert_array_equal(first.X, rows)          # the first call's rows untouched by the second
    # another thread in the kept call: this run prepares a pair call of its own (the same bits)
    warm = _run(double, t_end=1.0, rtol=1e-8)
    with kp.lock:
        aside = _run(double, t_end=1.0, rtol=1e-8)
    assert "companion_cpu_time" in aside.stats["raw"]
    np.testing.assert_array_equal(aside.q, warm.q)
    assert aside.metadata["accuracy"]["error_estimate"] == warm.metadata["accuracy"]["error_estimate"]


@needs_cc
@pytest.mark.parametrize("case", ["plain", "nan", "inf", "other grid"])
def test_the_comparison_in_c_is_the_numpy_comparison(case):
    """difference.compare with the runtime (crk_compare: one pass in C) fills the same numbers as
    without it (numpy), non-finite differences and a companion on other times included."""
    from types import SimpleNamespace

    from mechdsl.simulation import difference as D

    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 2.0, 101)
    X = rng.normal(size=(101, 6))
    u = t[::4].copy() if case != "other grid" else np.linspace(0.0, 2.0, 26) * (1 + 1e-9)
    Y = X[::4].copy() + 1e-6 * rng.normal(size=(26, 6))
    if case == "nan":
        Y[7, 1] = np.nan
    if case == "inf":
        Y[3, 2] = np.inf
        X[40, 0] = -np.inf
    s = SimpleNamespace(t_start=0.0, t_end=2.0, rtol=1e-6, atol=1e-8, error_estimate="coordinates")

    def filled(rt):
        r = SimpleNamespace(t=t, q=X[:, :3], coordinates=("a", "b", "c"), metadata={})
        other = SimpleNamespace(t=u, q=Y[:, :3], failure=None)
        D.compare(r, other, 0.9, s, lambda c: "m", rt=rt)
        return r.metadata["accuracy"]

    rt, _ = crk.runtime()
    in_c, in_numpy = filled(rt), filled(None)
    assert in_c.keys() == in_numpy.keys()
    for key, v in in_numpy.items():
        if isinstance(v, float) and np.isnan(v):
            assert np.isnan(in_c[key])
        else:
            assert in_c[key] == v, key          # the same operations on the same values: the same bits
    assert (D._in_c(rt, SimpleNamespace(t=t, q=X[:, :3]), SimpleNamespace(t=u, q=Y[:, :3]), 2.0, 0.9) is None) == (
        case == "other grid")


@needs_cc
def test_a_ctrl_c_during_the_paired_companion_is_an_interrupted_estimate(double, monkeypatch):
    """A Ctrl-C that arrives while the run's own C call runs the companion (after the run reached
    its end) is reported as before, when the companion ran alone: the run complete, its estimate
    interrupted (RunInterrupted, interrupted_during the error estimate)."""
    from mechdsl.output.result import RunInterrupted

    for _ in range(2):
        _run(double, t_end=1.0, rtol=1e-8)            # the second registers the companion
    s = next(v[1] for v in O._SETUPS.values() if v[0] is double.eom and v[1].settings.rtol == 1e-8)
    rt = s._direct_call()[0].rt
    real = rt._pair

    def pair_then_ctrl_c(*args):
        real(*args)
        raise KeyboardInterrupt                       # as the signal is raised when the call returns

    monkeypatch.setattr(rt, "_pair", pair_then_ctrl_c)
    with pytest.raises(RunInterrupted) as info:
        _run(double, t_end=1.0, rtol=1e-8)
    r = info.value.result
    assert r.failure is None and r.t[-1] == pytest.approx(1.0, abs=1e-12)
    assert "error estimate" in r.metadata["interrupted_during"]
    assert "interrupted" in r.metadata["accuracy"]["error_estimate_unavailable"]
    monkeypatch.undo()
    again = _run(double, t_end=1.0, rtol=1e-8)
    np.testing.assert_array_equal(again.q, r.q)
