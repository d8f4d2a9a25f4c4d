"""Model.fit(method="ipopt") and mech fit --method ipopt (issue 28): IPOPT over the run's CasADi
graph reaches the estimates Levenberg-Marquardt reaches on synthetic noisy data (the same
least-squares minimum, so the same numbers to the solvers' tolerance), honours a declared
bound (the free parameter then at the minimum with the bounded one held at its bound, found
independently by a one-parameter fit), and refuses a constrained model by name."""
from __future__ import annotations

import json

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError

from conftest import MODELS
from test_fit import DOUBLE, OSCILLATOR, TIGHT, _pendulum_csv


def _close(a, b, rel):
    return all(abs(a[k] - b[k]) <= rel * abs(b[k]) for k in b)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_same_estimates_as_lm():
    d = mechdsl.loads(DOUBLE)
    r = d.simulate(2.0, points=201, **TIGHT)
    rng = np.random.default_rng(2)
    data = {"time": r.t, **{c: r[c] + 0.002 * rng.standard_normal(r.t.size) for c in ("x1", "y1", "x2", "y2")}}
    start = d._with_real({"l1": 0.9, "l2": 0.8})
    lm = start.fit(data, params=["l1", "l2", "g"], method="lm", **TIGHT)
    ip = start.fit(data, params=["l1", "l2", "g"], method="ipopt", **TIGHT)
    assert ip.success and "IPOPT" in ip.message and ip.iterations > 0
    assert ip.initial == lm.initial and ip.estimates != ip.initial
    assert _close(ip.estimates, lm.estimates, 1e-7)
    assert _close(ip.standard_errors, lm.standard_errors, 1e-5)
    for n, v in (("l1", 1.0), ("l2", 0.7), ("g", 9.81)):
        assert abs(ip.estimates[n] - v) < 4 * ip.standard_errors[n], n


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pendulum_parameters_and_a_start_value():
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    r = m.simulate(2.0, points=101, **TIGHT)
    rng = np.random.default_rng(1)
    data = {"time": r.t, **{c: r[c] + 0.005 * rng.standard_normal(r.t.size) for c in ("x", "y")}}
    start = m._with_real({"L": 0.8})
    kw = dict(params=["L", "g"], starts=["theta"], **TIGHT)
    lm, ip = start.fit(data, method="lm", **kw), start.fit(data, method="ipopt", **kw)
    assert ip.success and _close(ip.estimates, lm.estimates, 1e-7)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_declared_bound_holds_and_the_rest_is_optimal():
    """k's declared max (3.5) lies below the truth (4): IPOPT stops k on it, and c where a fit
    of c alone with k = 3.5 puts it."""
    m = mechdsl.loads(OSCILLATOR.replace('"N/m", min = 0', '"N/m", min = 0, max = 3.5').replace("= 4;", "= 3;"))
    truth = mechdsl.loads(OSCILLATOR).simulate(6.0, points=60, **TIGHT)
    data = {"time": truth.t, "x": truth["x"]}
    ip = m.fit(data, params=["k", "c"], method="ipopt", **TIGHT)
    assert ip.success and ip.estimates["k"] <= 3.5 and ip.estimates["k"] == pytest.approx(3.5, rel=1e-7)
    only_c = m._with_real({"k": 3.5}).fit(data, params=["c"], **TIGHT)
    assert ip.estimates["c"] == pytest.approx(only_c.estimates["c"], rel=1e-4)     # an interior point: k a hair inside


def test_a_constrained_model_is_refused_by_name():
    m = mechdsl.load(MODELS / "four_bar.mech", model="FourBar")
    r = m.simulate(0.5, points=11)
    with pytest.raises(UsageError, match="constrained.*method='lm'"):
        m.fit({"time": r.t, "rocker_pivot.phi": r["rocker_pivot.phi"]}, params=["a"], method="ipopt")
    with pytest.raises(UsageError, match="did you mean 'ipopt'"):
        m.fit({"time": r.t, "rocker_pivot.phi": r["rocker_pivot.phi"]}, params=["a"], method="ipot")


def test_mech_fit_method_ipopt(tmp_path, capsys):
    data = _pendulum_csv(tmp_path, points=41)
    outs = {}
    for method in ("lm", "ipopt"):
        out = tmp_path / f"{method}.json"
        rc = main(["fit", str(MODELS / "pendulum.mech"), "--model", "Pendulum", "--data", data, "--fit", "L,g",
                   "--start", "L=0.8", "--rtol", "1e-10", "--atol", "1e-10", "--method", method, "-o", str(out)])
        assert rc == 0, capsys.readouterr().err
        outs[method] = json.loads(out.read_text())
    assert "IPOPT" in outs["ipopt"]["message"] and outs["ipopt"]["success"]
    assert _close(outs["ipopt"]["estimates"], outs["lm"]["estimates"], 1e-7)
    rc = main(["fit", str(MODELS / "pendulum.mech"), "--model", "Pendulum", "--data", data, "--fit", "L",
               "--method", "newton"])
    assert rc == 2 and "ipopt" in capsys.readouterr().err
