"""Rent or buy for every model (payback.py, issue 24 item 8): a model the cache has not compiled
runs interpreted (vm.c) until its interpreted evaluations have paid for its compile, then
compiled; the numbers are the same bits whichever engine ran.  Times: benchmarks/first_run.py."""
import numpy as np
import pytest

from mechdsl.eom.codegen import casadi_functions, find_compiler
from mechdsl.simulate import simulate
from mechdsl.simulation.backends import crk, payback

from sim_models import chain

needs_cc = pytest.mark.skipif(find_compiler() is None, reason="the engines are C")


def test_the_threshold_follows_the_operation_count():
    small, large = (casadi_functions(chain(n), names=("ode",), sx=True)["ode"] for n in (2, 6))
    assert small.n_instructions() < large.n_instructions()
    # compile ~ FIXED_OPS + ops, interpreting ~ ops an evaluation: more evaluations pay a small model's compile
    for f in (small, large):
        ops = f.n_instructions()
        assert payback.threshold(f) == payback.PAYBACK_EVALS + payback.PAYBACK_EVALS * payback.FIXED_OPS // ops
    assert payback.threshold(small) > payback.threshold(large) > payback.PAYBACK_EVALS


@needs_cc
def test_a_new_small_model_runs_interpreted_until_paid_then_compiled_with_the_same_bits(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    monkeypatch.setattr(crk, "_LIBS", {})
    e = chain(2)
    kw = dict(rtol=1e-9, atol=1e-9, points=41, method="dop853", error_estimate="off")
    first = simulate(e, 3.0, **kw)                      # empty cache: no gcc, the interpreter
    assert first.metadata["loop_engine"] == "interpreted"
    assert not list(tmp_path.glob("*.so"))              # nothing compiled for the model
    assert any("paid for its compile" in n for n in first.metadata["notes"])
    ode = crk.loop_ode(casadi_functions(e, names=("ode",)))
    assert payback.recorded(ode) == first.stats["rhs_evals"]      # counted towards the compile
    monkeypatch.setattr(payback, "PAYBACK_EVALS", first.stats["rhs_evals"] // 2)
    monkeypatch.setattr(payback, "FIXED_OPS", 0)
    monkeypatch.setattr(crk, "_LIBS", {})
    from mechdsl.simulation.backends import ode as O
    monkeypatch.setattr(O, "_SETUPS", {})
    paid = simulate(e, 3.0, **kw)                       # paid: compiled from the start
    assert paid.metadata["loop_engine"] == "compiled"
    assert list(tmp_path.glob("*.so"))
    forced = simulate(e, 3.0, **kw, compiled=True)
    for r in (first, paid):
        assert r.stats["steps"] == forced.stats["steps"] and r.stats["rhs_evals"] == forced.stats["rhs_evals"]
        assert np.array_equal(r.q, forced.q) and np.array_equal(r.qd, forced.qd)     # the same bits


@needs_cc
def test_a_set_up_run_again_in_the_process_buys_and_one_run_with_its_estimate_does_not(tmp_path, monkeypatch):
    from mechdsl.simulation.backends import ode as O

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    monkeypatch.setattr(crk, "_LIBS", {})
    monkeypatch.setattr(O, "_SETUPS", {})
    monkeypatch.setattr(payback, "_BOUGHT", set())
    e = chain(2)
    kw = dict(rtol=1e-8, atol=1e-8, points=21, method="dop853")         # with the default error estimate
    one = simulate(e, 2.0, **kw)              # a `mech simulate` process: the run and its companion, once each
    assert one.metadata["loop_engine"] == "interpreted" and not list(tmp_path.glob("*.so"))
    again = simulate(e, 2.0, **kw)            # the same set-up again: bought (compiled) at this run
    assert again.metadata["loop_engine"] == "compiled" and list(tmp_path.glob("*.so"))
    later = simulate(e, 2.0, **kw)            # built again compiled (payback.BOUGHT), from the start
    assert later.metadata["loop_engine"] == "compiled" and "compiled_after" not in later.stats["raw"]
    for r in (again, later):
        assert np.array_equal(r.q, one.q) and np.array_equal(r.qd, one.qd)
        assert r.metadata["accuracy"]["error_estimate"] == one.metadata["accuracy"]["error_estimate"]
