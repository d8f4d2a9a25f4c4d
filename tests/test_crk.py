"""The compiled stepping loop (mechdsl.simulation.backends.crk): dopri5 and dop853 in C.

Checked against independent references: scipy's RK45/DOP853 stepping in Python (the same
algorithm, so the same steps), closed-form motions, CasADi's own integrators, and the
output grid (the dense output must not change the steps)."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from mechdsl import eom as E
from mechdsl.eom.codegen import find_compiler
from mechdsl.simulate import simulate
from mechdsl.simulation.backends import crk, runtime_lib
from sim_models import blowup, chain, pendulum
import mechdsl.examples

PAIRS = {"dopri5": "scipy-rk45", "dop853": "scipy-dop853"}


def oscillator(w=3.0):
    """x'' = -w^2 x from x = 1, x' = 0: x = cos(w t)."""
    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 1)
    return E.from_lagrangian("Osc", ["x"], ["k"], [w * w], q, qd, t, p, 0.5 * qd[0] ** 2, 0.5 * p[0] * q[0] ** 2,
                             q0=[1.0], qd0=[0.0])


def _in_c(r):
    """Whether the run stepped in the C loop: the model compiled, or interpreted by vm.c (a model the
    cache has not compiled yet runs interpreted until that has paid for its compile: payback.py)."""
    if find_compiler() is None:     # no compiler: the run says so and steps in Python
        assert any("compiled stepping loop unavailable" in w for w in r.metadata["warnings"])
        return False
    assert r.metadata["loop_engine"] in ("compiled", "interpreted"), r.metadata["warnings"]
    assert r.metadata["options"]["compiled"] is (r.metadata["loop_engine"] == "compiled")
    return True


@pytest.mark.parametrize("method", list(PAIRS))
def test_compiled_loop_takes_the_steps_of_scipys_same_method(method):
    e = chain(2)
    r = simulate(e, 1.5, method=method, rtol=1e-8, atol=1e-8, points=31)
    ref = simulate(e, 1.5, method=PAIRS[method], rtol=1e-8, atol=1e-8, points=31)
    assert r.success and ref.success
    _in_c(r)
    assert r.stats["steps"] == ref.stats["steps"]
    assert r.stats["rhs_evals"] == ref.stats["rhs_evals"]
    assert r.stats["rejected_steps"] >= 0 and r.stats["jac_evals"] == 0
    # compiled and virtual machine right-hand sides differ by round-off only
    np.testing.assert_allclose(np.c_[r.q, r.qd], np.c_[ref.q, ref.qd], rtol=0, atol=1e-10)
    assert r.metadata["method"] == method and "compiled stepping loop" in r.metadata["integrator"]


@pytest.mark.parametrize("method,rtol,bound", [("dopri5", 1e-9, 2e-7), ("dop853", 1e-11, 1e-9)])
def test_harmonic_oscillator_against_the_closed_form_on_every_output_point(method, rtol, bound):
    w = 3.0
    r = simulate(oscillator(w), 10.0, method=method, rtol=rtol, atol=rtol, points=777)
    assert r.success
    _in_c(r)
    err = max(np.abs(r.q[:, 0] - np.cos(w * r.t)).max(), np.abs(r.qd[:, 0] + w * np.sin(w * r.t)).max() / w)
    assert err < bound, err
    assert err > 0     # not a copy of the closed form


@pytest.mark.parametrize("method", list(PAIRS))
def test_output_grid_density_does_not_change_the_solution(method):
    e = pendulum(theta0=2.5)
    coarse = simulate(e, 4.0, method=method, rtol=1e-10, atol=1e-10, points=5)
    fine = simulate(e, 4.0, method=method, rtol=1e-10, atol=1e-10, points=4001)
    assert coarse.stats["steps"] == fine.stats["steps"]
    assert coarse.stats["rejected_steps"] == fine.stats["rejected_steps"]
    assert coarse.q[-1, 0] == pytest.approx(fine.q[-1, 0], abs=1e-14)
    # the fine grid's points at the coarse times come from the dense output, not from a step end
    idx = [round(k * 1000) for k in range(5)]
    np.testing.assert_allclose(fine.q[idx, 0], coarse.q[:, 0], rtol=0, atol=1e-8)


def test_agrees_with_casadis_own_integrator():
    e = chain(3)
    r = simulate(e, 1.0, method="dop853", rtol=1e-11, atol=1e-11, points=11)
    ref = simulate(e, 1.0, method="cvodes-adams", rtol=1e-11, atol=1e-11, points=11)
    assert r.success and ref.success
    np.testing.assert_allclose(np.c_[r.q, r.qd], np.c_[ref.q, ref.qd], rtol=0, atol=1e-7)


@pytest.mark.parametrize("method", list(PAIRS))
def test_failure_says_when_and_keeps_the_solution_up_to_it(method):
    r = simulate(blowup(), 2.0, method=method, rtol=1e-10, atol=1e-10, points=201)
    assert not r.success
    assert r.failure.time == pytest.approx(math.sqrt(2), abs=0.02)
    assert r.t[-1] < math.sqrt(2)
    exact = 1 / (1 - r.t / math.sqrt(2))
    np.testing.assert_allclose(r.q[:, 0], exact, rtol=1e-5)


def test_step_limit_is_a_failure_with_its_cause():
    r = simulate(chain(2), 5.0, method="dop853", rtol=1e-10, atol=1e-10, points=3, max_steps=5)
    assert not r.success
    assert r.failure.cause == "too many steps"
    assert 0 < r.failure.time < 2.5


def test_without_a_compiler_the_same_method_runs_in_python(monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setattr(crk, "_RUNTIME", {})
    e = oscillator(2.0)
    r = simulate(e, 2.0, method="dop853", rtol=1e-9, atol=1e-9, points=21)
    assert r.success
    assert r.metadata["options"]["compiled"] is False
    assert any("no C compiler" in w for w in r.metadata["warnings"])
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setattr(crk, "_RUNTIME", {})
    monkeypatch.delenv("CC")
    c = simulate(e, 2.0, method="dop853", rtol=1e-9, atol=1e-9, points=21)
    _in_c(c)
    assert c.stats["steps"] == r.stats["steps"]
    np.testing.assert_allclose(c.q, r.q, rtol=0, atol=1e-12)


def test_integrator_options_are_refused_as_a_usage_error():
    from mechdsl.diagnostics import UsageError

    with pytest.raises(UsageError, match="dop853"):
        simulate(chain(2), 1.0, method="dop853", integrator_options={"foo": 1})


def test_registry_names_and_no_jacobian():
    from mechdsl.simulation.registry import check_method, methods

    for m in PAIRS:
        assert not check_method(m).needs_jacobian and check_method(m).compiled_loop
        assert "ode" in check_method(m).kinds and "ode" in methods()[m].kinds
    assert "events" in methods()["dop853"].kinds      # the contact back end's name is kept


# --------------------------------------------------------------------------- method auto: the stepping loop


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_auto_runs_the_stepping_loop_for_short_and_long_runs_and_says_why():
    """auto no longer weighs a compile against the run's length (a loose tolerance used to fall
    back to erk in the virtual machine, slower than a tight one): short and long runs, loose and
    tight tolerances all run the stepping loop, the model compiled by its size."""
    e = pendulum(theta0=2.5)
    if find_compiler() is None:
        r = simulate(e, 2.0, rtol=1e-8, atol=1e-8)
        assert r.metadata["method"] == "erk" and "no C compiler" in r.metadata["compiled"]
        return
    for t_end, rtol, method in ((2.0, 1e-8, "dop853"), (300.0, 1e-8, "dop853"), (2.0, 1e-3, "dopri5"),
                                (300.0, 1e-12, "dop853")):
        r = simulate(e, t_end, rtol=rtol, atol=rtol, points=31)
        assert r.success and r.metadata["method"] == method, (t_end, rtol, r.metadata["method"])
        assert r.metadata["compiled"].startswith("auto (") and "operations a right-hand side" in r.metadata["compiled"]
        assert "stepping loop" in r.metadata["method_reason"]
        _in_c(r)        # (compiled, or interpreted until its compile has paid: payback.py)
        assert r.metadata["auto"]["compile"]["engine"] == "compiled"       # the size's decision
    # opting out keeps the virtual machine's erk; both within the tolerance of each other
    r = simulate(e, 300.0, rtol=1e-8, atol=1e-8, points=301)
    off = simulate(e, 300.0, rtol=1e-8, atol=1e-8, points=301, compiled=False)
    assert off.metadata["method"] == "erk" and off.metadata["compiled"] == "off (requested)"
    assert off.metadata["options"]["compiled"] is False
    np.testing.assert_allclose(r.q[:, 0], off.q[:, 0], rtol=0, atol=1e-4)


def _fresh(monkeypatch, folder):
    """A new cache folder and nothing kept in this process: as a first run on a new machine."""
    monkeypatch.setenv("MECHDSL_CACHE", str(folder))
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setattr(crk, "_RUNTIME", {})


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.skipif(find_compiler() is None, reason="without a compiler auto is erk whatever the cache")
def test_auto_choice_and_numbers_do_not_depend_on_what_the_cache_holds(tmp_path, monkeypatch):
    """Same model and options -> same method, metadata and bits: in an empty cache (the model runs
    interpreted: payback.py), in process again (its set-up buys: compiled), in the warm cache, and
    again after the model's library was deleted.  Only the engine (loop_engine) follows the cache."""
    e = chain(3)
    kw = dict(rtol=1e-7, atol=1e-9, points=41)
    runs = []
    _fresh(monkeypatch, tmp_path / "c")
    runs.append(simulate(e, 3.0, **kw))                # empty cache: interpreted
    runs.append(simulate(e, 3.0, **kw))                # in process again: compiled (bought)
    _fresh(monkeypatch, tmp_path / "c")
    runs.append(simulate(e, 3.0, **kw))                # warm on disk, new process
    libs = sorted((tmp_path / "c").glob("*.so"))
    # the model's library (one: the one bought is the one the next set-up loads) and the runtime's
    # (unless it was built at install time: runtime_lib.py)
    assert len(libs) == (1 if runtime_lib.packaged() else 2)
    assert [r.metadata["loop_engine"] for r in runs] == ["interpreted", "compiled", "compiled"]
    for lib in libs:
        lib.unlink()
    _fresh(monkeypatch, tmp_path / "c")
    runs.append(simulate(e, 3.0, **kw))                # libraries gone: rebuilt
    first = runs[0]
    for r in runs:
        assert r.success
        for key in ("method", "compiled", "method_reason", "auto"):
            assert r.metadata[key] == first.metadata[key], key
        assert r.metadata["run"]["compiled"] is (r.metadata["loop_engine"] == "compiled")
        assert r.stats["steps"] == first.stats["steps"] and r.stats["rhs_evals"] == first.stats["rhs_evals"]
        assert np.array_equal(r.q, first.q) and np.array_equal(r.qd, first.qd)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.skipif(find_compiler() is None, reason="the engines are C")
def test_engines_give_the_same_bits_and_the_size_decides(monkeypatch):
    """The interpreted and the compiled model take the same steps to the last bit (the stepping
    loop's two engines, crk.engine_for); above COMPILE_OPS auto interprets, compiled = true
    compiles whatever the size."""
    for e in (chain(2), pendulum(theta0=2.5), oscillator(2.0)):
        c = simulate(e, 4.0, rtol=1e-9, atol=1e-9, points=51)
        monkeypatch.setattr(crk, "COMPILE_OPS", 0)
        i = simulate(e, 4.0, rtol=1e-9, atol=1e-9, points=51)
        forced = simulate(e, 4.0, rtol=1e-9, atol=1e-9, points=51, compiled=True)
        monkeypatch.undo()
        # (the size's decision; a model the cache has not compiled yet runs interpreted first: payback.py)
        assert c.metadata["auto"]["compile"]["engine"] == "compiled" and i.metadata["loop_engine"] == "interpreted"
        assert "interpreted in C" in i.metadata["compiled"] and i.metadata["options"]["compiled"] is False
        assert forced.metadata["loop_engine"] == "compiled" and forced.metadata["options"]["compiled"] is True
        assert i.stats["steps"] == c.stats["steps"]
        for r in (i, forced):
            assert np.array_equal(r.q, c.q) and np.array_equal(r.qd, c.qd)


@pytest.mark.skipif(find_compiler() is None, reason="the engines are C")
def test_the_stiffness_test_of_an_interpreted_model_runs_its_program_with_the_same_bits(monkeypatch):
    """auto's stiffness test (choose.numeric_jacobian) evaluates the ode of a model the loop
    interprets by the interpreter program its run uses (crk.interpreted_rows; the 200-link
    chain's 801 evaluations): the Jacobian has the bits of CasADi's virtual machine, so the
    choice and its numbers are the same."""
    from mechdsl.eom.codegen import casadi_functions
    from mechdsl.simulation import choose

    e = chain(3)
    funcs = casadi_functions(e, names=("ode",), sx=True)      # the Function the loop runs (crk.loop_ode)
    f = funcs["ode"]
    assert crk.interpreted_rows(funcs) is None                 # compiled: CasADi's map, nothing built
    monkeypatch.setattr(crk, "COMPILE_OPS", 0)
    rows = crk.interpreted_rows(funcs)
    assert rows is not None
    rng = np.random.default_rng(3)
    for _ in range(5):
        x0 = rng.normal(size=f.nnz_in(1))
        pv = rng.uniform(0.5, 2.0, size=f.nnz_in(3))
        u = np.zeros(f.nnz_in(2))
        a = choose.numeric_jacobian(f, 0.3, x0, u, pv)
        b = choose.numeric_jacobian(f, 0.3, x0, u, pv, rows)
        assert np.abs(a).max() > 0 and np.array_equal(a.view(np.int64), b.view(np.int64))
        monkeypatch.setattr(choose, "_CHOICES", {})
        by_vm = choose.choose_method(e, funcs, x0, pv, 0.0, 5.0, 1e-8, u=u)
        monkeypatch.setattr(choose, "_CHOICES", {})
        assert choose.choose_method(e, funcs, x0, pv, 0.0, 5.0, 1e-8, u=u, rows=rows) == by_vm


@pytest.mark.skipif(find_compiler() is None, reason="the engines are C")
def test_the_estimates_companion_keeps_the_interpreted_loop(monkeypatch):
    """A run whose model is interpreted in the stepping loop (above COMPILE_OPS) has its error
    estimate's companion in that loop too (issue 24: it ran as scipy's DOP853 stepped in Python,
    at 2-3x the run's cost per evaluation): both runs in the loop, and the same estimate to the
    last bit as the compiled model's (the engines give the same bits)."""
    e = chain(2)
    c = simulate(e, 4.0, rtol=1e-9, atol=1e-9, points=51, method="dop853")
    engines = []
    run = crk.run_compiled

    def spy(loop, *a, **k):
        engines.append(loop.engine)
        return run(loop, *a, **k)
    monkeypatch.setattr(crk, "COMPILE_OPS", 0)
    monkeypatch.setattr(crk, "run_compiled", spy)
    i = simulate(e, 4.0, rtol=1e-9, atol=1e-9, points=51, method="dop853")
    monkeypatch.undo()
    assert engines == ["interpreted", "interpreted"]
    ec, ei = c.metadata["accuracy"]["error_estimate"], i.metadata["accuracy"]["error_estimate"]
    assert ec is not None and ec > 0 and np.array_equal(ei, ec)
    assert i.stats["error_estimate_rhs_evals"] == c.stats["error_estimate_rhs_evals"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.skipif(find_compiler() is None, reason="the engines are C")
def test_an_interpreted_model_compiles_once_it_has_paid_and_keeps_its_bits(monkeypatch, tmp_path):
    """Above COMPILE_OPS the loop interprets the model until its interpreted evaluations, counted
    across runs (payback.py), reach PAYBACK_EVALS: then it compiles, within the run (between two
    slices) or from the start of the next.  The engines give the same bits and a slice carries the
    whole state, so every run gives the numbers of the compiled run, wherever the switch lands."""
    from mechdsl.simulation.backends import crk_calls, payback

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))          # a count of its own
    e, kw = chain(3), dict(rtol=1e-10, atol=1e-10, points=51, method="dop853", error_estimate="off")
    c = simulate(e, 20.0, **kw, compiled=True)
    n = c.stats["rhs_evals"]
    monkeypatch.setattr(crk, "COMPILE_OPS", 0)
    monkeypatch.setattr(crk_calls, "SLICE", 1e-5)            # many slices: the switch lands inside the run
    monkeypatch.setattr(payback, "PAYBACK_EVALS", 10 ** 12)
    monkeypatch.setattr(payback, "FIXED_OPS", 0)            # (the threshold: PAYBACK_EVALS itself)
    i = simulate(e, 20.0, **kw)                              # never paid: interpreted throughout
    monkeypatch.setattr(payback, "PAYBACK_EVALS", n + n // 2)
    first = simulate(e, 20.0, **kw)                          # paid half-way: compiled for the rest
    second = simulate(e, 20.0, **kw)                         # paid before: compiled from the start
    assert i.metadata["loop_engine"] == "interpreted" and "compiled_after" not in i.stats["raw"]
    assert first.metadata["loop_engine"] == "compiled" and first.metadata["options"]["compiled"] is True
    assert 0 < first.stats["raw"]["compiled_after"] < n
    assert any("pay for its compile" in x for x in first.metadata["notes"])
    assert second.metadata["loop_engine"] == "compiled" and second.stats["raw"]["compiled_after"] == 0
    for r in (i, first, second):
        assert r.stats["rhs_evals"] == n and r.stats["steps"] == c.stats["steps"]
        assert np.array_equal(r.q, c.q) and np.array_equal(r.qd, c.qd)


def test_rhs_cost_counts_instructions_and_the_linear_solve():
    from mechdsl.eom.codegen import casadi_functions

    sx = casadi_functions(pendulum(), names=("ode",))["ode"]
    assert sx.is_a("SXFunction") and crk.rhs_cost(sx) == sx.n_instructions()
    mx = casadi_functions(chain(3), names=("ode",))["ode"]      # M qdd = bias solved numerically (QR)
    assert not mx.is_a("SXFunction")
    assert crk.rhs_cost(mx) > 3 ** 3 + mx.n_instructions()


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_no_compile_opts_out(tmp_path, monkeypatch, capsys):
    import json

    from mechdsl.cli import main

    from pathlib import Path

    monkeypatch.chdir(tmp_path)

    model = mechdsl.examples.path("pendulum")
    out = tmp_path / "p.csv"
    assert main(["simulate", str(model), "--t-end", "150", "--points", "11", "--no-compile", "-o", str(out),
                 "--no-progress"]) == 0
    meta = json.loads((tmp_path / "p.json").read_text())["metadata"]
    assert meta["compiled"] == "off (requested)" and meta["method"] != "dop853"
    assert main(["simulate", str(model), "--compiled", "--no-compile"]) == 2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cvodes_adams_compiled_holds_no_dense_jacobian(tmp_path, monkeypatch):
    """Functional iteration never evaluates the Jacobian: the library holds the forward
    derivative only (it used to compile the dense Jacobian: 774 kB of C at N = 12)."""
    import ctypes

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    e = chain(3)
    r = simulate(e, 2.0, method="cvodes-adams", compiled=True, rtol=1e-10, atol=1e-10, points=11)
    vm = simulate(e, 2.0, method="cvodes-adams", compiled=False, rtol=1e-10, atol=1e-10, points=11)
    assert r.success
    if find_compiler() is None:
        assert any("compiled code unavailable" in w for w in r.metadata["warnings"])
        return
    assert r.metadata["options"]["compiled"] is True
    libs = list(tmp_path.glob("*.so"))
    assert len(libs) == 1
    lib = ctypes.CDLL(str(libs[0]))
    assert hasattr(lib, "fwd1_ode") and not hasattr(lib, "jac_ode")
    np.testing.assert_allclose(np.c_[r.q, r.qd], np.c_[vm.q, vm.qd], rtol=0, atol=1e-8)


def test_run_record_says_whether_compiled_code_ran():
    off = simulate(pendulum(), 1.0, compiled=False)
    assert off.metadata["run"]["compiled"] is False
    r = simulate(pendulum(), 1.0, method="dopri5")
    assert r.metadata["run"]["compiled"] is (_in_c(r) and r.metadata["loop_engine"] == "compiled")
    forced = simulate(pendulum(), 1.0, method="dopri5", compiled=True)
    assert forced.metadata["run"]["compiled"] is _in_c(forced)
    assert r.metadata["run"]["integrator"] == "crk:dopri5"


def test_jacobian_eigenvalues_of_the_second_order_form_equal_the_full_decomposition():
    from mechdsl.simulation.choose import jacobian_eigenvalues

    rng = np.random.default_rng(7)
    for n in (1, 3, 8):
        A = rng.normal(size=(n, n))
        J = np.block([[np.zeros((n, n)), np.eye(n)], [A, np.zeros((n, n))]])
        fast, full = jacobian_eigenvalues(J), np.linalg.eigvals(J)
        assert len(fast) == 2 * n
        for lam in full:      # every eigenvalue of J is found (and vice versa)
            assert np.abs(fast - lam).min() < 1e-9 * max(1.0, abs(lam))
        for lam in fast:
            assert np.abs(full - lam).min() < 1e-9 * max(1.0, abs(lam))
    damped = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.eye(2), -0.5 * np.eye(2)]])
    np.testing.assert_allclose(np.sort_complex(jacobian_eigenvalues(damped)), np.sort_complex(np.linalg.eigvals(damped)))


@pytest.mark.slow
def test_twelve_link_chain_compiled_loop_equals_scipy_dop853_on_the_virtual_machine():
    import re
    from pathlib import Path

    import mechdsl

    text = mechdsl.examples.path("nlink_pendulum").read_text()
    m = mechdsl.loads(re.sub(r"parameter Integer N = \d+", "parameter Integer N = 12", text))
    r = m.simulate(t_end=5, rtol=1e-8, method="dop853")
    ref = m.simulate(t_end=5, rtol=1e-8, method="scipy-dop853")
    assert r.success and ref.success
    _in_c(r)
    assert r.stats["steps"] == ref.stats["steps"]
    np.testing.assert_allclose(np.c_[r.q, r.qd], np.c_[ref.q, ref.qd], rtol=0, atol=1e-9)


def test_structurally_zero_accelerations_free_particle():
    """xdot = (qd, 0): the output of ode is sparse; the loop reads it densified.  x = x0 + v t."""
    q, qd, t, p = ca.SX.sym("q", 1), ca.SX.sym("qd", 1), ca.SX.sym("t"), ca.SX.sym("p", 0)
    e = E.from_lagrangian("Free", ["x"], [], [], q, qd, t, p, 0.5 * qd[0] ** 2, 0 * q[0], q0=[1.0], qd0=[0.25])
    r = simulate(e, 4.0, method="dopri5", rtol=1e-10, atol=1e-10, points=9)
    assert r.success
    _in_c(r)
    np.testing.assert_allclose(r.q[:, 0], 1.0 + 0.25 * r.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.qd[:, 0], 0.25, rtol=0, atol=1e-12)


def test_concurrent_runs_share_one_library_and_give_the_same_numbers():
    from concurrent.futures import ThreadPoolExecutor

    e = chain(2)
    one = simulate(e, 2.0, method="dop853", rtol=1e-9, atol=1e-9, points=21)
    starts = [{"theta1": 0.5 + 0.1 * k} for k in range(4)]
    alone = [simulate(e, 2.0, method="dop853", rtol=1e-9, atol=1e-9, points=21, x0=s).q for s in starts]
    with ThreadPoolExecutor(4) as ex:
        together = list(ex.map(lambda s: simulate(e, 2.0, method="dop853", rtol=1e-9, atol=1e-9, points=21,
                                                   x0=s).q, starts))
    for a, b in zip(alone, together):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13)
    assert not np.allclose(alone[0], one.q)      # the starts differ: the runs are not copies


@pytest.mark.parametrize("method", list(PAIRS))
def test_compiled_false_runs_the_named_loop_method_in_python(method, monkeypatch):
    """`--method dop853 --no-compile` (compiled=False) never compiles: it used to build the
    loop anyway while the metadata said "off (requested)". It runs scipy's same method, and
    says so; the numbers are that method's (x = cos(w t))."""
    def no_build(*a, **k):
        raise AssertionError("compiled=False built the compiled loop")

    monkeypatch.setattr(crk, "library", no_build)
    e = oscillator(3.0)
    r = simulate(e, 2.0, method=method, compiled=False, rtol=1e-10, atol=1e-12, points=21)
    assert r.success and r.metadata["method"] == PAIRS[method]
    assert r.metadata["options"]["compiled"] is False and r.metadata["compiled"] == "off (requested)"
    assert "compiled = false" in r.metadata["method_reason"]
    np.testing.assert_allclose(r.q[:, 0], np.cos(3.0 * r.t), rtol=0, atol=1e-7)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_auto_whose_loop_cannot_be_built_says_erk_runs(monkeypatch, tmp_path):
    """auto picks the stepping loop, the build fails (a "compiler" that fails: `false`): the run is
    erk and its reason says so (it kept the reason of the loop it did not run).  (A cache path
    that is a file no longer fails the build: the cache is then not used and the library is
    built in a private folder, mechdsl.eom.cachefiles.)"""
    if find_compiler() is None:
        pytest.skip("needs a C compiler: without one auto never picks the stepping loop")
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", "false")
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setattr(crk, "_RUNTIME", {})
    monkeypatch.setattr(runtime_lib, "PACKAGED", str(tmp_path / "none"))     # no runtime built at install time
    r = simulate(pendulum(theta0=2.5), 300.0, rtol=1e-8, atol=1e-8, points=11)
    assert r.success and r.metadata["method"] == "erk"
    assert r.metadata["compiled"] == "no: auto (the compiled loop could not be built)"
    assert "could not be built" in r.metadata["method_reason"]
    assert any("compiled stepping loop unavailable" in w for w in r.metadata["warnings"])
