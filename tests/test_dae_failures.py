"""A constrained run that cannot go on stops with a coded failure, says when and why, and
keeps its results up to there (issue 12/18 DAE items).

Scenarios: a Cartesian pendulum (1 kg, 1 m, g = 9.81, released at rest horizontally) with
a generalized force sqrt(1.5 - t) on x, which is nan for t > 1.5 s; the shipped four-bar
(models/four_bar.mech) with a crank of length a = 1e-12 m, which hung for minutes in the
projection stepping on main (each integrator call could take 500000 steps, and a failing
interval was halved 12 times).
"""
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from dae_models import _syms
from mechdsl.dae import simulate_dae
from mechdsl.eom import from_lagrangian

ROOT = Path(__file__).resolve().parents[1]


def nan_pendulum():
    coords, params = ("x", "y"), ("m", "g", "L")
    q, qd, t, p, P = _syms(coords, params)
    T = 0.5 * P["m"] * ca.dot(qd, qd)
    V = P["m"] * P["g"] * q[1]
    Q = ca.vertcat(ca.sqrt(1.5 - t), 0)          # nan after t = 1.5
    g = 0.5 * (q[0] ** 2 + q[1] ** 2 - P["L"] ** 2)
    return from_lagrangian("NanPendulum", coords, params, [1.0, 9.81, 1.0], q, qd, t, p, T, V, Q=Q, g=g,
                           q0=[1.0, 0.0], qd0=[0.0, 0.0], constraint_names=["rod"])


@pytest.mark.parametrize("formulation", ["projection", "baumgarte", "partitioning",
                                         pytest.param("ggl", marks=pytest.mark.slow)])
def test_nonfinite_equations_fail_with_time_and_coordinate(formulation):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate_dae(nan_pendulum(), 3.0, points=31, formulation=formulation)
    assert not r.success
    f = r.failure
    assert f.cause == "non-finite state"
    assert f.time == pytest.approx(1.5, abs=1e-6)
    assert "der(der(x))" in f.detail and "E825" in f.detail
    assert r.metadata["failure_code"] == "E825"
    # results up to there are kept, and they are finite
    assert r.t[-1] == pytest.approx(1.5, abs=1e-6) and len(r.t) == 16
    assert np.all(np.isfinite(r.q)) and np.all(np.isfinite(r.qd))


def test_nonfinite_state_error_names_the_first_bad_output():
    from mechdsl.dae.stepper import NonFiniteError

    e = NonFiniteError(1.25, "der(y)")
    assert e.t == 1.25 and "der(y)" in str(e)


@pytest.mark.slow
def test_four_bar_with_a_tiny_crank_ends_with_a_coded_failure():
    """main: no end after minutes.  Now a failure (E824) within seconds, in a subprocess so
    that a regression cannot hang the test run."""
    code = textwrap.dedent(f"""
        import time, mechdsl
        m = mechdsl.load({str(ROOT / "models" / "four_bar.mech")!r}).with_params(a=1e-12)
        c = time.process_time()
        r = m.simulate(10.0, points=501)
        print(r.success, r.metadata.get("failure_code"), round(time.process_time() - c, 2))
        print(r.failure)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    first, failure = out.stdout.strip().splitlines()[:2]
    ok, code_, cpu = first.split()
    assert ok == "False" and code_ == "E824"
    assert float(cpu) < 20.0          # a bound on the work, generous for a shared machine (measured 1.5 s)
    assert "steps" in failure
