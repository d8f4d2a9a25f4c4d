"""Model.fit and mech fit (issue 28): estimates recover known parameters from noisy synthetic
data within their reported standard errors (coverage near the nominal level over repeated
trials with a fixed seed), identifiability named in the model's terms (a pendulum's mass; g
and L from angles alone: only g/L; a double pendulum's masses: only m1/m2), several
experiments with their own starts, bounds, and bad data as located errors with nothing
written."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError, UsageError

from conftest import MODELS

PENDULUM = MODELS / "pendulum.mech"
TIGHT = dict(rtol=1e-10, atol=1e-10)

OSCILLATOR = """
model Oscillator "a damped mass on a spring"
  parameter Real m(unit = "kg") = 1;
  parameter Real k(unit = "N/m", min = 0) = 4;
  parameter Real c(unit = "N.s/m", min = 0) = 0.3;
  coordinate Real x(start = 1, speed = 0, unit = "m");
equation
  kinetic = 1/2*m*der(x)^2;
  potential = 1/2*k*x^2;
  dissipation = 1/2*c*der(x)^2;
end Oscillator;
"""

DOUBLE = """
model DoublePendulum2 "two uniform rods hinged in series, each with its own length and mass"
  parameter Real m1(unit = "kg", min = 0) = 1;
  parameter Real m2(unit = "kg", min = 0) = 0.5;
  parameter Real l1(unit = "m", min = 0) = 1;
  parameter Real l2(unit = "m", min = 0) = 0.7;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Rod rod1(m = m1, L = l1, axis = {0, -1, 0});
  Rod rod2(m = m2, L = l2, axis = {0, -1, 0});
  Revolute j1(parent = world, child = rod1.a, axis = {0, 0, 1}, phi(start = 1.2, speed = 0));
  Revolute j2(parent = rod1.b, child = rod2.a, axis = {0, 0, 1}, phi(start = -0.5, speed = 0));
  output Real x1(unit = "m") = rod1.b.x;
  output Real y1(unit = "m") = rod1.b.y;
  output Real x2(unit = "m") = rod2.b.x;
  output Real y2(unit = "m") = rod2.b.y;
end DoublePendulum2;
"""


def _noisy(r, columns, sigma, rng):
    return {"time": r.t, **{c: r[c] + sigma * rng.standard_normal(r.t.size) for c in columns}}


@pytest.fixture(scope="module")
def pendulum():
    return mechdsl.load(PENDULUM, model="Pendulum")


def test_pendulum_length_and_gravity_and_its_mass_cannot_be_found(pendulum):
    truth = pendulum.simulate(3.0, points=301, **TIGHT)
    data = _noisy(truth, ("x", "y"), 0.01, np.random.default_rng(1))
    f = pendulum._with_real({"L": 0.8, "g": 9.0}).fit(data, params=["L", "g", "m"], **TIGHT)
    assert f.success and f.names == ("L", "g", "m") and f.units == {"L": "m", "g": "m/s2", "m": "kg"}
    for n, v in (("L", 1.0), ("g", 9.81)):
        assert abs(f.estimates[n] - v) < 3 * f.standard_errors[n]
    assert f.standard_errors["L"] < 2e-3
    (c,) = f.unidentifiable
    assert c.names == ("m",) and "do not depend" in c.text
    assert f.estimates["m"] == 1.0 and math.isinf(f.standard_errors["m"])     # held where it started
    assert f.sigma == pytest.approx(0.01, rel=0.15) and f.degrees_of_freedom == 600
    assert "m (the measured outputs do not depend on it)" in f.table()
    assert abs(f.correlation[0, 1]) <= 1 and f.correlation[0, 0] == 1


def test_only_g_over_L_from_the_angle(pendulum):
    truth = pendulum.simulate(3.0, points=301, **TIGHT)
    data = _noisy(truth, ("theta",), 0.01, np.random.default_rng(2))
    f = pendulum._with_real({"L": 0.8, "g": 9.0}).fit(data, params=["g", "L"], **TIGHT)
    (c,) = f.unidentifiable
    assert set(c.names) == {"g", "L"} and c.determinable == "g/L" and c.unit == "1/s2"
    assert abs(c.value - 9.81) < 3 * c.standard_error and c.standard_error < 0.05
    assert f.estimates["g"] / f.estimates["L"] == pytest.approx(c.value, rel=1e-12)
    assert "only g/L can" in f.table()


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_lengths_and_only_the_mass_ratio():
    m = mechdsl.loads(DOUBLE)
    truth = m.simulate(1.5, points=301, **TIGHT)
    data = _noisy(truth, ("x1", "y1", "x2", "y2"), 0.003, np.random.default_rng(3))
    f = m._with_real({"l1": 0.9, "l2": 0.8, "m1": 1.3, "m2": 0.4}).fit(data, params=["l1", "l2", "m1", "m2"],
                                                                          rtol=1e-9, atol=1e-9)
    for n, v in (("l1", 1.0), ("l2", 0.7)):
        assert abs(f.estimates[n] - v) < 3 * f.standard_errors[n]
    (c,) = f.unidentifiable
    assert c.text == "m1*m2" and c.determinable == "m1/m2" and c.unit == ""
    assert abs(c.value - 2.0) < 3 * c.standard_error


def _coverage(trials, seed):
    """z = (estimate - truth) / standard error of k and c of the oscillator over ``trials``
    noisy data sets (noise 0.02 m on 60 samples), each fit from a start 20% off."""
    m = mechdsl.loads(OSCILLATOR)
    truth = m.simulate(6.0, points=60, **TIGHT)
    rng = np.random.default_rng(seed)
    start = m._with_real({"k": 4.8, "c": 0.24})
    z = []
    for _ in range(trials):
        f = start.fit(_noisy(truth, ("x",), 0.02, rng), params=["k", "c"], **TIGHT)
        assert f.success
        z += [(f.estimates["k"] - 4.0) / f.standard_errors["k"], (f.estimates["c"] - 0.3) / f.standard_errors["c"]]
    return np.array(z)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_standard_errors_cover_the_truth_fast():
    """Ten data sets: the sum of z^2 over 20 estimates lies in chi2(20)'s central 99.8%."""
    z = _coverage(10, seed=7)
    assert 5.9 < float(z @ z) < 45.3, z


@pytest.mark.slow
def test_standard_errors_cover_the_truth_at_the_nominal_level():
    """Fifty data sets (100 estimates): |z| < 1 for about 68% of them (55..81: +-2.8 binomial
    standard deviations), |z| < 2 for at least 88%, the mean of z^2 near 1."""
    z = _coverage(50, seed=11)
    inside = int(np.sum(np.abs(z) < 1))
    assert 55 <= inside <= 81, inside
    assert np.mean(np.abs(z) < 2) >= 0.88
    assert 0.65 < float(np.mean(z ** 2)) < 1.4


def test_several_experiments_with_their_own_starts(pendulum):
    """Two releases from other angles: L and g shared, each start angle its own (theta@1, theta@2)."""
    rng = np.random.default_rng(4)
    tables, exps = [], []
    for th in (0.5, 1.2):
        r = pendulum.simulate(2.0, points=101, x0={"theta": th}, **TIGHT)
        tables.append(_noisy(r, ("x", "y"), 0.005, rng))
        exps.append({"x0": {"theta": th + 0.05}})
    f = pendulum._with_real({"L": 0.9}).fit(tables, params=["L", "g"], starts=["theta"], experiments=exps, **TIGHT)
    assert f.names == ("L", "g", "theta@1", "theta@2") and f.unidentifiable == []
    for n, v in (("L", 1.0), ("g", 9.81), ("theta@1", 0.5), ("theta@2", 1.2)):
        assert abs(f.estimates[n] - v) < 4 * f.standard_errors[n], n


def test_bounds_from_the_declared_max_and_given():
    m = mechdsl.loads(OSCILLATOR.replace('"N/m", min = 0', '"N/m", min = 0, max = 3.5').replace("= 4;", "= 3;"))
    truth = mechdsl.loads(OSCILLATOR).simulate(6.0, points=60, **TIGHT)
    data = {"time": truth.t, "x": truth["x"]}
    f = m.fit(data, params=["k"], **TIGHT)
    assert f.estimates["k"] == pytest.approx(3.5)            # k = 4 lies beyond the declared max
    f = m.fit(data, params=["k"], bounds={"k": (1.0, 3.2)}, **TIGHT)
    assert f.estimates["k"] == pytest.approx(3.2)
    with pytest.raises(UsageError, match="outside its bounds"):
        m.fit(data, params=["k"], bounds={"k": (3.5, 5)}, **TIGHT)


def test_a_parameter_declared_in_degrees_is_estimated_in_degrees():
    m = mechdsl.loads("""
model Tilted
  parameter Real a(unit = "deg") = 20 "slope";
  parameter Real m(unit = "kg") = 1;
  parameter Real g(unit = "m/s2") = 9.81;
  coordinate Real s(start = 0, speed = 0, unit = "m");
equation
  kinetic = 1/2*m*der(s)^2;
  potential = -m*g*sin(a)*s;
end Tilted;
""")
    t = np.linspace(0, 1, 21)
    data = {"time": t, "s": 0.5 * 9.81 * math.sin(math.radians(30)) * t ** 2}     # s = g sin(a) t^2 / 2
    f = m.fit(data, params=["a"], **TIGHT)
    assert f.units["a"] == "deg" and f.estimates["a"] == pytest.approx(30, rel=1e-7)


def _csv(path, text):
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("text, code, line, col", [
    ("time,x,yy\n0,1,0\n0.1,0.99,-0.05\n", "E771", 1, 8),
    ("time,x,y\n0,1,0\n0.1,nan,-0.05\n", "E773", 3, 5),
    ("time,x,y\n0,1,0\n0.1,,-0.05\n", "E773", 3, 5),
    ("time,x,y\n-1,1,0\n0.1,0.9,-0.05\n", "E772", 2, 1),
    ("time,x,y\n0,1,0\n0,0.9,-0.05\n", "E772", 3, 1),
    ("x,y\n1,0\n", "E772", 1, 1),
    ("time,x,y\n", "E772", 1, 1),
])
def test_bad_data_files_are_located_errors(pendulum, tmp_path, text, code, line, col):
    path = _csv(tmp_path / "d.csv", text)
    with pytest.raises(MechError) as e:
        pendulum.fit(path, params=["L"])
    d = e.value.first
    assert (d.code, d.span.file, d.span.line, d.span.col) == (code, path, line, col)


def test_bad_tables_and_names(pendulum):
    t = np.linspace(0, 1, 5)
    with pytest.raises(MechError, match="names no recorded signal"):
        pendulum.fit({"time": t, "z": t}, params=["L"])
    with pytest.raises(MechError, match="not a finite number"):
        pendulum.fit({"time": t, "x": np.r_[t[:4], np.inf]}, params=["L"])
    with pytest.raises(UsageError, match="not a parameter of Pendulum; did you mean 'L'"):
        pendulum.fit({"time": t, "x": t}, params=["Lx"])
    with pytest.raises(UsageError, match="weights: 'q' is not a measured column"):
        pendulum.fit({"time": t, "x": t}, params=["L"], weights={"q": 1})
    with pytest.raises(UsageError, match="experiments: 2 settings for 1 table"):
        pendulum.fit({"time": t, "x": t}, params=["L"], experiments=[{}, {}])


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_fit_writes_json_and_plot(tmp_path, capsys):
    m = mechdsl.load(PENDULUM, model="Pendulum")
    r = m.simulate(2.0, points=101, **TIGHT)
    rng = np.random.default_rng(5)
    rows = ["time,x,y"] + [f"{t!r},{x + 0.01 * rng.standard_normal()!r},{y + 0.01 * rng.standard_normal()!r}"
                           for t, x, y in zip(r.t.tolist(), r["x"].tolist(), r["y"].tolist())]
    data = _csv(tmp_path / "d.csv", "\n".join(rows) + "\n")
    out, png = tmp_path / "fit.json", tmp_path / "fit.png"
    rc = main(["fit", str(PENDULUM), "--model", "Pendulum", "--data", data, "--fit", "L,g,m", "--start", "L=0.8",
               "--rtol", "1e-10", "--atol", "1e-10", "-o", str(out), "--plot", str(png)])
    text = capsys.readouterr().out
    assert rc == 0 and "std error" in text and "m (the measured outputs do not depend on it)" in text
    assert "residual norm" in text
    doc = json.loads(out.read_text())
    assert doc["units"]["g"] == "m/s2" and doc["initial"]["L"] == 0.8 and doc["standard_errors"]["m"] is None
    assert abs(doc["estimates"]["L"] - 1.0) < 4 * doc["standard_errors"]["L"]
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_mech_fit_bad_input_writes_nothing(tmp_path, capsys):
    data = _csv(tmp_path / "d.csv", "time,x,yy\n0,1,0\n0.1,0.99,-0.05\n")
    out = tmp_path / "fit.json"
    rc = main(["fit", str(PENDULUM), "--model", "Pendulum", "--data", data, "--fit", "L", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and f"{data}:1:8: error[E771]" in err and "did you mean 'y'" in err and not out.exists()
    rc = main(["fit", str(PENDULUM), "--model", "Pendulum", "--data", data, "--fit", "Lx", "-o", str(out)])
    assert rc == 2 and "did you mean 'L'" in capsys.readouterr().err and not out.exists()


def _pendulum_csv(tmp_path, seed=5, points=101):
    m = mechdsl.load(PENDULUM, model="Pendulum")
    r = m.simulate(2.0, points=points, **TIGHT)
    rng = np.random.default_rng(seed)
    rows = ["time,x,y"] + [f"{t!r},{x + 0.01 * rng.standard_normal()!r},{y + 0.01 * rng.standard_normal()!r}"
                           for t, x, y in zip(r.t.tolist(), r["x"].tolist(), r["y"].tolist())]
    return _csv(tmp_path / "d.csv", "\n".join(rows) + "\n")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_fit_json_document(tmp_path, capsys):
    from cli_json import validate

    data = _pendulum_csv(tmp_path, points=41)
    rc = main(["fit", str(PENDULUM), "--model", "Pendulum", "--data", data, "--fit", "L,g", "--start", "L=0.9",
               "--json"])
    doc = json.loads(capsys.readouterr().out)
    validate(doc)
    res = doc["result"]
    assert rc == 0 and doc["ok"] and res["names"] == ["L", "g"] and res["units"]["L"] == "m"
    assert abs(res["estimates"]["L"] - 1.0) < 4 * res["standard_errors"]["L"] and res["unidentifiable"] == []
    bad = _csv(tmp_path / "bad.csv", "time,x\n0,1\n0.1,inf\n")
    rc = main(["fit", str(PENDULUM), "--model", "Pendulum", "--data", bad, "--fit", "L", "--json"])
    doc = json.loads(capsys.readouterr().out)
    validate(doc)
    (d,) = doc["diagnostics"]
    assert rc == 1 and doc["error"]["kind"] == "model"
    assert (d["code"], d["file"], d["line"], d["column"]) == ("E773", bad, 3, 5) and d["hint"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_fit_does_not_overwrite_without_force(tmp_path, capsys):
    data = _pendulum_csv(tmp_path, points=21)
    out, png = tmp_path / "fit.json", tmp_path / "fit.png"
    out.write_text("mine\n")
    png.write_text("mine\n")
    args = ["fit", str(PENDULUM), "--model", "Pendulum", "--data", data, "--fit", "L"]
    assert main([*args, "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_text() == "mine\n"
    assert main([*args, "--plot", str(png)]) == 2 and png.read_text() == "mine\n"
    capsys.readouterr()
    assert main([*args, "-o", str(out), "--force"]) == 0
    assert json.loads(out.read_text())["names"] == ["L"]
    capsys.readouterr()
    assert main([*args, "-o", str(out)]) == 0          # its own output: a rerun replaces it
    capsys.readouterr()
    assert main([*args, "-o", str(out), "--plot"]) == 2 and png.read_text() == "mine\n"   # bare: next to -o
    assert "fit.png" in capsys.readouterr().err
    assert main([*args, "-o", str(out), "--plot", "--force"]) == 0 and png.read_bytes()[:4] == b"\x89PNG"


def test_a_free_coordinate_is_a_straight_line_fit():
    """q'' = 0 (the equations' right side structurally zero, which CasADi's integrators refused
    until it was densified): fitting the start value and speed to samples of a line is linear
    least squares, so the estimates and standard errors equal numpy's polyfit's."""
    m = mechdsl.loads("""
model Free
  parameter Real m(unit = "kg") = 2;
  coordinate Real s(start = 0, speed = 0, unit = "m");
equation
  kinetic = 1/2*m*der(s)^2;
end Free;
""")
    rng = np.random.default_rng(8)
    t = np.linspace(0, 2, 41)
    y = 0.3 + 1.7 * t + 0.05 * rng.standard_normal(t.size)
    f = m.fit({"time": t, "s": y}, starts=["s", "der(s)"], **TIGHT)
    (b, a), cov = np.polyfit(t, y, 1, cov="unscaled")
    s2 = float(np.sum((y - a - b * t) ** 2)) / (t.size - 2)
    se = {"s": math.sqrt(s2 * cov[1, 1]), "der(s)": math.sqrt(s2 * cov[0, 0])}
    for n, v in (("s", a), ("der(s)", b)):      # the stopping rule (relative gain < 1e-10) leaves ~1e-5 se
        assert abs(f.estimates[n] - v) < 1e-4 * se[n], (n, f.estimates[n], v)
        assert f.standard_errors[n] == pytest.approx(se[n], rel=1e-6)
    assert f.units == {"s": "m", "der(s)": "m/s"}
