"""Issue 23, part 2: a parameter declared in degrees means degrees on every path.  A disk rolls
down an incline of slope alpha (declared `unit = "deg"`, 30 in the file); every way of setting
alpha to 45 must give s(t) = g sin(45 deg) t^2 / 3 (the closed form of rolling without
slipping), to 1e-9 relative: a scene modifier, --set, with_params, p={...}, mech sweep --grid,
sweep grids and tables, the samplers; bare numbers (the declared unit) and explicit units
(45 deg, deg(45), 0.785... rad) alike.  Start values of a coordinate declared in degrees too."""
import math

import numpy as np
import pytest

import mechdsl
from constraint_cases import DISK, DISK_ODE
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError

G = 9.81
T_END = 1.0
TIGHT = dict(rtol=1e-12, atol=1e-12)
EXPLICIT = ["45 deg", "45deg", "deg(45)", f"{math.pi / 4!r} rad"]


def closed_form(t, alpha_deg=45.0):
    return G * math.sin(math.radians(alpha_deg)) * np.asarray(t) ** 2 / 3


def check(s, t):
    assert np.asarray(s)[-1] == pytest.approx(closed_form(t)[-1], rel=1e-9)


@pytest.fixture(scope="module")
def ode():
    return mechdsl.loads(DISK_ODE)


@pytest.fixture(scope="module")
def dae():
    return mechdsl.loads(DISK)


def test_the_file_value_and_a_scene_modifier(ode):
    r = ode.simulate(T_END, points=3, **TIGHT)
    assert r["s"][-1] == pytest.approx(closed_form(T_END, 30.0), rel=1e-9)
    scene = DISK_ODE + "scene Steep\n  model RollingDiskODE(alpha = 45);\n  stop_time = 1;\nend Steep;\n"
    r = mechdsl.loads(scene, scene="Steep").simulate(points=3, **TIGHT)
    check(r["s"], r.t)


@pytest.mark.parametrize("value", [45, 45.0, np.float64(45), "45"] + EXPLICIT + [mechdsl.deg(45), mechdsl.rad(math.pi / 4)])
def test_with_params(ode, value):
    m = ode.with_params(alpha=value)
    assert m.parameters["alpha"] == pytest.approx(math.pi / 4, rel=1e-15)
    r = m.simulate(T_END, points=3, **TIGHT)
    check(r["s"], r.t)


@pytest.mark.parametrize("value", [45, "45 deg", mechdsl.deg(45)])
def test_parameter_dict_and_the_constrained_model(ode, dae, value):
    check(ode.simulate(T_END, points=3, p={"alpha": value}, **TIGHT)["s"], [0, T_END])
    r = dae.with_params(alpha=value).simulate(T_END, points=3, reactions=True, **TIGHT)
    check(r["s"], r.t)
    assert r["lambda[rolling]"][-1] == pytest.approx(2 * G * math.sin(math.pi / 4) / 3, rel=1e-9)


@pytest.mark.parametrize("value", ["45"] + EXPLICIT)
def test_command_line_set(tmp_path, value, capsys):
    src = tmp_path / "disk.mech"
    src.write_text(DISK)
    out = tmp_path / "o.csv"
    assert main(["simulate", str(src), "--t-end", "1", "--points", "3", "--rtol", "1e-12", "--atol", "1e-12",
                 "--set", f"alpha={value}", "-o", str(out), "--no-progress"]) == 0
    rows = np.genfromtxt(out, delimiter=",", names=True)
    check(rows["s"], rows["time"])


def test_wrong_kind_of_unit_is_a_usage_error(ode, tmp_path, capsys):
    with pytest.raises(UsageError, match="alpha is declared in deg"):
        ode.with_params(alpha="1 m")
    src = tmp_path / "disk.mech"
    src.write_text(DISK_ODE)
    assert main(["simulate", str(src), "--t-end", "1", "--set", "alpha=2 kg", "--no-progress"]) == 2
    assert "declared in deg" in capsys.readouterr().err


def test_start_values_of_a_coordinate_in_degrees(ode, tmp_path):
    """`turn` is declared in degrees: turn.start=90 is 90 degrees (pi/2 in the results, which are SI)."""
    for m in (ode.with_params(**{"turn.start": 90}), ode.with_params(**{"turn.start": "90 deg"}),
              ode.with_params(**{"turn.start": "1.5707963267948966 rad"})):
        assert m.eom.start()[0][1] == pytest.approx(math.pi / 2, rel=1e-15)
    src = tmp_path / "disk.mech"
    src.write_text(DISK_ODE)
    out = tmp_path / "o.csv"
    assert main(["simulate", str(src), "--t-end", "1", "--points", "2", "--set", "turn.start=90,turn.speed=30",
                 "-o", str(out), "--no-progress"]) == 0
    rows = np.genfromtxt(out, delimiter=",", names=True)
    assert rows["turn"][0] == pytest.approx(math.pi / 2, rel=1e-15)
    assert rows["derturn"][0] == pytest.approx(math.pi / 6, rel=1e-15)


def test_sweep_grid_table_and_samplers(ode):
    """Each run against the closed form at its own alpha, read as degrees."""
    from mechdsl.sample import normal, uniform
    from mechdsl.sweep import table

    for params in ({"alpha": [30, 45]}, table({"alpha": [30, 45]}), uniform({"alpha": (40, 50)}, n=2, seed=1),
                   normal({"alpha": (45, 3)}, n=2, seed=1)):
        ds = ode.sweep(params=params, t_end=T_END, points=3, **TIGHT)
        alpha = ds["alpha"].values                       # the swept values as given, in their declared unit
        assert np.all((alpha > 20) & (alpha < 60))
        for k, a in enumerate(alpha):
            assert ds["s"].values[k, -1] == pytest.approx(closed_form(T_END, a)[()], rel=1e-9)


@pytest.mark.parametrize("grid", ["alpha=30,45", "alpha=30,45 deg", "alpha=30 deg:45 deg:2",
                                  f"alpha=0.5235987755982988 rad,{math.pi / 4!r} rad"])
def test_command_line_sweep(tmp_path, grid, capsys):
    src = tmp_path / "disk.mech"
    src.write_text(DISK_ODE)
    out = tmp_path / "sweep.csv"
    assert main(["sweep", str(src), "--grid", grid, "--t-end", "1", "--points", "3", "--rtol", "1e-12",
                 "--atol", "1e-12", "-o", str(out), "--no-progress"]) == 0
    import pandas as pd

    df = pd.read_csv(out)
    last = df[(df["run"] == 1) & (df["time"] == 1.0)]
    assert float(last["s"].iloc[0]) == pytest.approx(closed_form(T_END)[()], rel=1e-9)
    assert float(last["alpha"].iloc[0]) == pytest.approx(45.0, rel=1e-12)


def test_command_line_samplers(tmp_path, capsys):
    import pandas as pd

    src = tmp_path / "disk.mech"
    src.write_text(DISK_ODE)
    for opt in (["--uniform", "alpha=40:50"], ["--uniform", "alpha=40 deg:50 deg"], ["--normal", "alpha=45:3"],
                ["--normal", "alpha=0.785398 rad:3 deg"]):
        out = tmp_path / "mc.csv"
        assert main(["sweep", str(src), *opt, "--samples", "2", "--t-end", "1", "--points", "3", "--rtol", "1e-12",
                     "--atol", "1e-12", "-o", str(out), "--no-progress", "--force"]) == 0
        df = pd.read_csv(out)
        last = df[df["time"] == 1.0]
        assert np.all((last["alpha"] > 30) & (last["alpha"] < 60))
        for a, sv in zip(last["alpha"], last["s"]):
            assert sv == pytest.approx(closed_form(T_END, a)[()], rel=1e-9)


def test_tables_show_the_declared_unit(ode):
    from mechdsl.frontend.dump import dump_model

    text = dump_model(ode.model)
    assert "alpha = 30 [deg]" in text
    assert "alpha = 45 [deg]" in dump_model(ode.with_params(alpha=45).model)


DEPENDENT = DISK_ODE.replace('  parameter Real J(unit = "kg.m2") = 1 "inertia of an idle wheel";', '''  parameter Real J(unit = "kg.m2") = 1 "inertia of an idle wheel";
  parameter Real base(unit = "deg") = 45;
  parameter Real L(unit = "mm") = 250;
  parameter Real Lm(unit = "mm") = L "the same length, in the same unit";
  parameter Real w(unit = "deg/s") = 10;''').replace(
    'parameter Real alpha(unit = "deg") = 30 "slope";', 'parameter Real alpha(unit = "deg") = base "slope";').replace(
    'coordinate Real turn(start = 0, speed = 0, unit = "deg")', 'coordinate Real turn(start = base/3, speed = w, unit = "deg")')


def test_a_value_computed_from_parameters_with_units_is_not_converted_again():
    """alpha(unit = "deg") = base, base = 45 deg: alpha is 45 degrees (it was read as 45 deg x
    pi/180 = 0.785 deg, the slope almost flat); lengths alike (250 mm, not 0.25 mm), and start
    values and speeds computed from parameters.  Bare numbers still mean the declared unit.
    with_params re-evaluates the dependents in the order they depend on each other (alpha refers
    to base, declared after it: a KeyError traceback before)."""
    m = mechdsl.loads(DEPENDENT)
    p = dict(zip(m.eom.params, m.parameter_values))
    assert p["alpha"] == pytest.approx(math.pi / 4, rel=1e-15)
    assert p["Lm"] == pytest.approx(0.25, rel=1e-15)
    r = m.simulate(T_END, points=3, **TIGHT)
    check(r["s"], r.t)
    assert r["turn"][0] == pytest.approx(math.radians(15), rel=1e-15)
    assert r["der(turn)"][0] == pytest.approx(math.radians(10), rel=1e-15)
    r = m.with_params(base=60).simulate(T_END, points=3, **TIGHT)            # alpha follows base
    assert r["s"][-1] == pytest.approx(closed_form(T_END, 60.0)[()], rel=1e-9)


@pytest.mark.slow_cases('deg(base/deg(1))')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("value", ["45", "deg(45)", "rad(pi/4)", "deg(90)/2", "base", "deg(base/deg(1))"])
def test_explicit_units_in_the_file(value):
    """deg(x) and rad(x) in a .mech file: the number in that unit, an angle (as `45 deg` on the
    command line); a scene modifier and the declaration alike."""
    src = DEPENDENT.replace('parameter Real base(unit = "deg") = 45;', 'parameter Real base(unit = "deg") = deg(45);')
    scene = src + f"scene Steep\n  model RollingDiskODE(alpha = {value});\n  stop_time = 1;\nend Steep;\n"
    r = mechdsl.loads(scene, scene="Steep").simulate(points=3, **TIGHT)
    check(r["s"], r.t)
    decl = src.replace('parameter Real alpha(unit = "deg") = base "slope";', f'parameter Real alpha(unit = "deg") = {value};')
    r = mechdsl.loads(decl).simulate(T_END, points=3, **TIGHT)
    check(r["s"], r.t)


def test_a_unit_function_of_a_length_is_a_located_error(tmp_path, capsys):
    path = tmp_path / "disk.mech"
    path.write_text(DEPENDENT.replace('Real base(unit = "deg") = 45;', 'Real base(unit = "deg") = deg(L);'))
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}:" in err and "error[E402]: deg() takes a number, got a value in m" in err
