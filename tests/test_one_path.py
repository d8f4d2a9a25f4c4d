"""Issue 22, "One path for every run": every entry point goes through one prepared problem, and
the four defects where the paths disagreed.

1. ``m.casadi()["ode"]`` of a constrained model is the formulated problem's index-1 ODE (the
   run's accelerations), ``["outputs"]`` works there, the DAE pieces are there by name.
2. ``m.casadi(compiled=True)`` compiles only what is asked, derivatives only on request, and a
   compile that cannot be done says so (never the virtual machine's Functions silently).
3. ``m.simulate()`` without an end time: the scene's stop time, else 10 s, as the CLI.
4. ``mechdsl.dae.simulate_dae`` and ``mechdsl.impacts.simulate_with_contacts`` give the same
   checks as ``Model.simulate``.
"""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from conftest import MODELS, needs_cc
from mechdsl.diagnostics import MechError, UsageError

# ------------------------------------------------------------------ defect 1


def _kkt_accelerations(f, x, p, h=1e-6, h2=1e-4):
    """q'' of M q'' = bias - G^T lambda, G q'' = gamma, solved with numpy from the model's
    M, bias and the constraints' g alone (G and gamma by central differences of g: independent
    of the KKT code of mechdsl.dae)."""
    n = x.size // 2
    q, qd = x[:n], x[n:]
    M = np.array(f["mass_matrix"](q, 0.0, p), float)
    b = np.array(f["bias"](0.0, x, [], p), float).ravel()

    def g(qq):
        return np.array(f["constraints"](0.0, np.r_[qq, qd], [], p)[0], float).ravel()

    E = np.eye(n) * h
    G = np.column_stack([(g(q + E[i]) - g(q - E[i])) / (2 * h) for i in range(n)])
    # gamma = -(d/dq (G qd)) qd: the second directional derivative of g along qd
    gamma = -(g(q + h2 * qd) - 2 * g(q) + g(q - h2 * qd)) / h2 ** 2
    Minv = np.linalg.inv(M)
    lam = np.linalg.lstsq(G @ Minv @ G.T, G @ Minv @ b - gamma, rcond=1e-10)[0]   # rows may be redundant
    return Minv @ (b - G.T @ lam)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_casadi_ode_of_a_closed_loop_is_the_runs_index1_ode():
    """four_bar.mech at its consistent start: the tree cut open accelerates at [12.50, -35.20,
    4.53], the run integrates [3.68, -2.97, 2.02] (the issue's numbers); casadi()["ode"] was
    the former."""
    m = mechdsl.load(MODELS / "four_bar.mech")
    r = m.simulate(0.01, points=3)                     # its first row is the consistent start
    x = np.r_[r.q[0], r.qd[0]]
    p = m.parameter_values
    f = m.casadi()
    xdot = np.array(f["ode"](0.0, x, [], p), float).ravel()
    n = m.eom.n
    np.testing.assert_allclose(xdot[:n], r.qd[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(xdot[n:], _kkt_accelerations(f, x, p), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(xdot[n:], [3.68, -2.97, 2.02], atol=0.01)
    # the run's own accelerations: its speeds over two short steps (second-order difference)
    h = 1e-4
    v = m.simulate(2 * h, points=3, rtol=1e-12, atol=1e-12).qd
    np.testing.assert_allclose((-3 * v[0] + 4 * v[1] - v[2]) / (2 * h), xdot[n:], rtol=1e-5, atol=1e-5)


def test_casadi_outputs_of_a_closed_loop_read_the_multipliers():
    """The reaction outputs of four_bar need the multipliers: E801 before; now the run's values."""
    m = mechdsl.load(MODELS / "four_bar.mech")
    r = m.simulate(0.01, points=3)
    x = np.r_[r.q[0], r.qd[0]]
    f = m.casadi()
    out = dict(zip(f["outputs"].name_out(), f["outputs"](0.0, x, [], m.parameter_values)))
    for name in ("crank_angle", "F_close[1]", "F_close[2]", "F_close[3]"):
        assert float(out[name]) == pytest.approx(r[name][0], rel=1e-9, abs=1e-9), name
    # the DAE pieces by name
    for name in ("multipliers", "constraints", "constraint_jacobian", "mass_matrix", "bias"):
        assert name in f
    lam = np.array(f["multipliers"](0.0, x, [], m.parameter_values), float).ravel()
    assert lam.size == m.eom.m and np.isfinite(lam).all()
    G = np.array(f["constraint_jacobian"](0.0, x, [], m.parameter_values), float)
    assert G.shape == (m.eom.m, m.eom.n)


def test_an_unconstrained_models_functions_are_unchanged():
    """Without constraints the problem's ode is the model's own (the tree is the model)."""
    from mechdsl.eom.codegen import casadi_functions

    m = mechdsl.load(MODELS / "double_pendulum.mech")
    x = np.r_[0.3, -0.2, 0.1, 0.4]
    a = np.array(m.casadi()["ode"](0.0, x, [], m.parameter_values), float)
    b = np.array(casadi_functions(m.eom)["ode"](0.0, x, [], m.parameter_values), float)
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)


# ------------------------------------------------------------------ defect 2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_compiled_casadi_compiles_only_what_is_asked(tmp_path, monkeypatch):
    """Before: the first Function asked for compiled every Function of the model with first
    and second derivatives (the 20-link chain: 78 s, 7.2 GB)."""
    from mechdsl.eom import codegen

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    monkeypatch.setattr(codegen, "_SETS", {})
    calls = []
    real = codegen.compile_functions

    def spy(funcs, *a, **kw):
        calls.append(([f.name() for f in funcs], kw.get("derivatives", 0)))
        return real(funcs, *a, **kw)

    monkeypatch.setattr(codegen, "compile_functions", spy)
    m = mechdsl.load(MODELS / "pendulum.mech")
    fs = m.casadi(compiled=True)
    assert calls == []                              # nothing until a Function is asked for
    ode = fs["ode"]
    assert calls == [(["ode"], 0)] and ode.class_name() == "External" and fs.compiled
    fs["energy"]
    assert calls[-1] == (["energy"], 0) and len(calls) == 2
    x = np.r_[0.3, 0.1]
    np.testing.assert_allclose(np.array(ode(0, x, [], m.parameter_values), float),
                               np.array(m.casadi()["ode"](0, x, [], m.parameter_values), float), rtol=1e-13)
    # derivatives on request: the library then holds the Jacobian casadi.external looks for
    d = m.casadi(compiled=True, derivatives=1)["ode"]
    assert calls[-1] == (["ode"], 1)
    J = np.array(d.jacobian()(0, x, [], m.parameter_values, 0)[1], float)     # d xdot / d x, compiled
    assert J.shape == (2, 2) and J[0, 1] == 1.0 and J[1, 0] < 0


def test_compiled_casadi_without_a_compiler_says_so(monkeypatch):
    """Before: the virtual machine's Functions came back without a word (``.compiled`` False)."""
    from mechdsl.eom import codegen

    monkeypatch.setattr(codegen, "find_compiler", lambda: None)
    monkeypatch.setattr(codegen, "_SETS", {})       # no Function set of an earlier test
    m = mechdsl.load(MODELS / "pendulum.mech")
    with pytest.raises(MechError) as e:
        m.casadi(compiled=True)["ode"]
    assert e.value.first.code == "E804" and "no C compiler" in e.value.first.message


@needs_cc
def test_compiled_casadi_over_the_budget_says_so_before_compiling(monkeypatch):
    from mechdsl.eom import codegen

    monkeypatch.setattr(codegen, "cflags_for", lambda size: pytest.fail("the compiler was started"))
    monkeypatch.setattr(codegen, "_SETS", {})
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    with pytest.raises(MechError) as e:
        m.casadi(compiled=True, compile_budget=1000)["ode"]
    assert e.value.first.code == "E805" and "compile budget" in e.value.first.message
    with pytest.raises(UsageError):
        m.casadi(compiled=True, derivatives=3)


# ------------------------------------------------------------------ defect 3


def test_simulate_without_an_end_time_uses_the_scene_else_10_s():
    """The CLI's rule (--t-end: scene stop_time, else 10); Model.simulate() raised before."""
    plain = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    assert plain.scene_settings.get("stop_time") is None
    r = plain.simulate(points=3)
    assert r.t[-1] == pytest.approx(10.0, rel=1e-15) and plain.settings().t_end == 10.0
    scene = mechdsl.load(MODELS / "double_pendulum.mech", scene="Chaos")
    stop = scene.scene_settings["stop_time"]
    assert scene.simulate(points=3).t[-1] == pytest.approx(stop, rel=1e-15)


# ------------------------------------------------------------------ defect 4


def _refusal(call):
    try:
        call()
    except (MechError, UsageError) as e:
        return type(e).__name__, str(e)
    return None


@pytest.mark.parametrize("kw", [{"p": {"m": -1.0}}, {"bogus": 1}, {"points": 10, "budget": 5}, {"rtol": 2.0}])
def test_the_dae_entry_checks_as_model_simulate(kw):
    from mechdsl.dae import simulate_dae

    m = mechdsl.load(MODELS / "four_bar.mech", model="FourBar")
    want = _refusal(lambda: m.simulate(0.1, **kw))
    assert want is not None
    assert _refusal(lambda: simulate_dae(m.eom, 0.1, **kw)) == want


@pytest.mark.parametrize("kw", [{"p": {"m": -1.0}}, {"rest_speed": -1.0}, {"impact_order": "random"},
                                {"points": 10, "budget": 5}])
def test_the_contact_entry_checks_as_model_simulate(kw):
    from mechdsl.impacts import simulate_with_contacts

    m = mechdsl.load(MODELS / "bouncing_ball.mech", model="BouncingBall")
    want = _refusal(lambda: m.simulate(0.1, **kw))
    assert want is not None
    assert _refusal(lambda: simulate_with_contacts(m.eom, None, 0.1, **kw)) == want


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_entries_give_the_runs_of_model_simulate():
    """Same numbers and the same record of what ran."""
    from mechdsl.dae import simulate_dae
    from mechdsl.impacts import simulate_with_contacts

    for file, entry in (("four_bar.mech", lambda e: simulate_dae(e, 0.5, points=11)),
                        ("bouncing_ball.mech", lambda e: simulate_with_contacts(e, None, 0.5, points=11))):
        m = mechdsl.load(MODELS / file)
        model = mechdsl.load(MODELS / file, model=m.name)
        a, b = model.simulate(0.5, points=11), entry(model.eom)
        np.testing.assert_array_equal(a.q, b.q)
        assert a.metadata["run"] == b.metadata["run"]


# ------------------------------------------------------------------ one prepared problem


@pytest.mark.slow_cases('four_bar.mech-None-kw1')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("file, scene, kw", [
    ("double_pendulum.mech", None, {"t_end": 1.0}),                  # ODE
    ("four_bar.mech", None, {"t_end": 0.5}),                         # DAE
    ("bouncing_ball.mech", None, {"t_end": 1.0}),                    # contacts
    ("kepler.mech", "Orbits", {"t_end": 2.0, "points": 51}),          # fixed step
])
def test_prepared_equals_direct(file, scene, kw):
    """solve(prepare(problem)) is solve(problem), number for number (rumoca's test pattern)."""
    from mechdsl.simulation import solve
    from mechdsl.simulation.prepared import prepare

    m = mechdsl.load(MODELS / file, scene=scene)
    problem = m.problem(points=kw.pop("points", 21), **kw)
    a, b = solve(problem), solve(prepare(problem))
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(np.c_[a.q, a.qd], np.c_[b.q, b.qd])
    assert a.signals.keys() == b.signals.keys()
    for k in a.signals:
        np.testing.assert_array_equal(a.signals[k], b.signals[k])
    # what ran is the same, but for the engine: a model interprets until its evaluations paid
    # for its compile (payback.py: the second run in a process may be the compiled one), with
    # the same bits (the arrays above)
    ra, rb = ({k: v for k, v in r.metadata["run"].items() if k != "compiled"} for r in (a, b))
    assert ra == rb


def test_prepared_at_other_values_equals_a_direct_run_and_builds_nothing(monkeypatch):
    """Parameters and start values are overridden without a rebuild: no CasADi Function, no
    integrator and no library is built for the runs at other values, and each gives the direct
    run's numbers (the method of auto is the one prepared)."""
    from mechdsl import integrators as I
    from mechdsl.eom import codegen
    from mechdsl.simulation import formulate, simulate, solve
    from mechdsl.simulation.prepared import prepare

    m = mechdsl.load(MODELS / "double_pendulum.mech")
    problem = m.problem(t_end=1.0, points=21, method="cvodes-bdf")
    prep = prepare(problem)
    first = solve(prep)                     # builds the integrator (once)
    builds = []
    for mod, name in ((I, "make_integrator"), (codegen, "_build"), (codegen, "compile_functions")):
        real = getattr(mod, name)
        monkeypatch.setattr(mod, name, lambda *a, _real=real, _n=name, **k: builds.append(_n) or _real(*a, **k))
    values = [({"l": 1.3}, None), (None, {"j1.phi": 0.4, "der(j2.phi)": -1.0}), ({"g": 3.7}, {"j2.phi": 2.0})]
    runs = [solve(prep.at(p=p, x0=x0)) for p, x0 in values]
    assert builds == []
    assert prep.integrator() is prep.integrator()
    for (p, x0), r in zip(values, runs):
        direct = simulate(m.eom, problem.settings.replace(p=p, x0=x0))
        np.testing.assert_array_equal(np.c_[r.q, r.qd], np.c_[direct.q, direct.qd])
        assert not np.array_equal(r.q, first.q)
    # auto: chosen once at prepare, kept by the runs at other values
    auto = prepare(m.problem(t_end=1.0, points=21))
    r = solve(auto.at(p={"l": 1.3}))
    assert r.metadata["method"] == auto.method
    direct = solve(formulate(m.eom, auto.problem.settings.replace(p={"l": 1.3}, method=auto.method)))
    np.testing.assert_array_equal(r.q, direct.q)


def test_the_prepared_integrator_is_the_runs_and_the_sweeps():
    """The vectorized sweep maps the integrator a single run integrates with."""
    from mechdsl.simulation.prepared import prepare
    from mechdsl.sweep.runs import mapped_integrator

    m = mechdsl.load(MODELS / "double_pendulum.mech")
    prep = prepare(m.problem(t_end=0.5, points=11, method="erk"))
    integ = prep.integrator()
    x0 = np.r_[m.eom.start()[0], m.eom.start()[1]]
    xf = np.array(integ(x0=x0, p=m.parameter_values)["xf"], float).T
    from mechdsl.simulation import solve

    r = solve(prep)
    np.testing.assert_array_equal(xf[1:], np.c_[r.q, r.qd][1:])
    F = mapped_integrator(prep, 2, 1)
    both = np.array(F(x0=np.c_[x0, x0], p=np.c_[m.parameter_values, m.parameter_values])["xf"], float)
    np.testing.assert_array_equal(both[:, :11].T, xf)


def test_the_problems_functions_do_not_replace_the_models_in_the_model_cache(tmp_path, monkeypatch):
    """The model cache stores the Functions codegen built for a model; a constrained problem's
    ``ode`` (another Function under the same name) must not be stored as the model's."""
    from mechdsl.eom import codegen, modelcache

    m = mechdsl.load(MODELS / "four_bar.mech")
    problem_ode = m.casadi()["ode"]
    own = codegen.casadi_functions(m.eom, sx=True)["ode"]
    stored = modelcache._functions(m.eom)
    assert all(f is not problem_ode for f in stored.values())
    x = np.r_[0.3, 0.2, 0.1, 1.0, 0.0, 0.0]
    assert not np.allclose(np.array(problem_ode(0, x, [], m.parameter_values), float),
                           np.array(own(0, x, [], m.parameter_values), float))
