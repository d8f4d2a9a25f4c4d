"""FMI export (issue 29): FMUs of representative models checked with fmpy against mech simulate.

The default run: the pendulum (FMI 2 and 3, model exchange with fmpy's CVode and
co-simulation), a constrained model (the four-bar: the index-1 ODE, drift projected), a
contact model (the bouncing ball to rest, in co-simulation and as model exchange with event
indicators; the falling rod, a fixation), parameters set through the FMU (as --set),
inputs driven through it (as --input), directional derivatives against finite
differences, the binary run from C without Python, determinism and bad input.  Every
shipped model, both versions: tests/test_export_matrix.py (slow)."""
from __future__ import annotations

import os
import subprocess
import zipfile

import numpy as np
import pytest

import mechdsl
from fmpy.validation import validate_fmu
from mechdsl.diagnostics import MechError, UsageError

from conftest import MODELS, needs_cc
from fmu_util import assert_agree, reference, run_fmu, state_names

pytestmark = needs_cc


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """Exported once per module: name -> (model, path)."""
    folder = tmp_path_factory.mktemp("fmus")
    made = {}

    def get(name, file, version=2, **load):
        if name not in made:
            m = mechdsl.load(MODELS / file, **load)
            path = folder / f"{name}.fmu"
            m.export_fmu(path, fmi_version=version)
            made[name] = (m, path)
        return made[name]
    return get


@pytest.mark.parametrize("version", [2, 3])
def test_pendulum_model_exchange_and_co_simulation_match_mech_simulate(fmus, version):
    m, path = fmus(f"pendulum{version}", "pendulum.mech", version)
    assert validate_fmu(str(path)) == []
    ref = reference(m, 3.0, 0.01)
    for kind in ("ModelExchange", "CoSimulation"):
        X, res = run_fmu(path, m, kind, 3.0, 0.01, output=["E"])
        assert_agree(X, ref, f"pendulum FMI {version} {kind}")
        # the output: the energy stays at its start value (a conservative model)
        assert np.ptp(res["E"]) < 1e-7


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_constrained_model_index1_ode_with_projection(fmus):
    """The four-bar (3 coordinates, 5 constraints of which 2 independent, two start values
    made consistent): both interfaces match; the states stay on the constraints."""
    import casadi as ca

    m, path = fmus("four_bar", "four_bar.mech")
    assert validate_fmu(str(path)) == []
    ref = reference(m, 2.0, 0.01)
    eom = m.eom
    g = ca.Function("g", [eom.q, eom.p], [eom.g])
    for kind in ("ModelExchange", "CoSimulation"):
        X, res = run_fmu(path, m, kind, 2.0, 0.01, output=["mechdsl.projections", "F_close[1]"])
        assert_agree(X, ref, f"four_bar {kind}")
        drift = max(float(np.max(np.abs(np.array(g(x[:3], m.parameter_values))))) for x in X)
        assert drift < 1e-8, f"{kind}: the constraints drift by {drift:.3g}"
        assert np.all(np.isfinite(res["F_close[1]"]))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_constrained_drift_stays_bounded_at_loose_tolerances(fmus):
    """The four-bar over 20 s at loose tolerances: the FMU projects when the drift passes half
    of mechdsl.drift_bound, so the constraints stay at the level of one step's error; with the
    projection switched off (a bound no drift reaches) the same run drifts off by far more."""
    import casadi as ca

    m, path = fmus("four_bar", "four_bar.mech")
    eom = m.eom
    g = ca.Function("g", [eom.q, eom.p], [eom.g])
    for kind, tol in (("ModelExchange", 1e-6), ("CoSimulation", 1e-5)):
        drift, projections = {}, {}
        for bound in (0.0, 1e3):                  # 0: the default rule; 1e3: never projects
            import fmpy

            res = fmpy.simulate_fmu(str(path), fmi_type=kind, stop_time=20.0, output_interval=0.01,
                                    relative_tolerance=tol, start_values={"mechdsl.drift_bound": bound},
                                    output=state_names(m) + ["mechdsl.projections"])
            X = np.array([[row[s] for s in state_names(m)] for row in res])
            drift[bound] = max(float(np.max(np.abs(np.array(g(x[:eom.n], m.parameter_values))))) for x in X)
            projections[bound] = res["mechdsl.projections"][-1]
        assert projections[0.0] > 0 and projections[1e3] == 0, (kind, projections)
        assert drift[0.0] < 3 * tol, f"{kind}: drift {drift[0.0]:.3g} at tolerance {tol:g}"
        assert drift[1e3] > 50 * drift[0.0], (kind, drift)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("fmi_type", ["CoSimulation", "ModelExchange"])
def test_contacts_bounce_to_rest(fmus, fmi_type):
    """The bouncing ball: impacts in the FMU's step (co-simulation), or at the events of fmpy's
    CVode on the FMU's event indicators (FMI 2 model exchange), until the contact becomes
    persistent; both as mech simulate, every impact and the close at rest counted."""
    m, path = fmus("bouncing_ball", "bouncing_ball.mech")
    md = zipfile.ZipFile(path).read("modelDescription.xml").decode()
    assert "<CoSimulation" in md and "<ModelExchange" in md and 'numberOfEventIndicators="1"' in md
    r = m.simulate(5.0, points=501, rtol=1e-11, atol=1e-12)
    X, res = run_fmu(path, m, fmi_type, 5.0, 0.01, output=["mechdsl.events"])
    assert_agree(X, np.c_[r.q, r.qd], f"bouncing ball, {fmi_type}")
    assert res["mechdsl.events"][-1] == len(r.events)        # every impact, and the close at rest
    assert abs(X[-1, 1]) < 1e-9 and X[-1, 0] == pytest.approx(0.1, abs=1e-8)      # at rest on the floor


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_model_exchange_with_a_fixation_and_a_rod_landing_on_either_end(fmus):
    """FMI 2 model exchange of contacts: the rod that bounces on either end and settles flat
    (two contacts, simultaneous impacts), and the rod caught by a fixation at its time (a time
    event the FMU announces); both as mech simulate."""
    for name, model, t_end in (("falling_rod", None, 3.0), ("caught_rod", "CaughtRod", 1.0)):
        m, path = fmus(name, "falling_rod.mech", model=model)
        ref = reference(m, t_end, 0.01)
        X, _ = run_fmu(path, m, "ModelExchange", t_end, 0.01)
        assert_agree(X, ref, f"{name} model exchange")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_parameters_set_through_the_fmu_change_the_run_as_set_does(fmus):
    """A parameter (pendulum L), one that moves a start value (the ball's drop height h: the
    state's start is calculated) and one that dependent parameters follow (kepler's e: rp, vp)."""
    cases = [("pendulum2", "pendulum.mech", {"L": 0.5, "g": 3.0}, 2.0),
             ("bouncing_ball", "bouncing_ball.mech", {"h": 2.0, "e": 0.6}, 2.0),
             ("kepler", "kepler.mech", {"e": 0.3, "M": 2.0}, 3.0)]
    for name, file, values, t_end in cases:
        m, path = fmus(name, file)
        ref = reference(m.with_params(**values), t_end, 0.01)      # what --set does (commands/_common.py)
        X, _ = run_fmu(path, m, "CoSimulation", t_end, 0.01, start_values=values)
        assert_agree(X, ref, f"{name} with {values}")
        assert np.max(np.abs(X - reference(m, t_end, 0.01))) > 1e-3          # the values did change the run
    m, path = fmus("pendulum2", "pendulum.mech")
    X, _ = run_fmu(path, m, "ModelExchange", 2.0, 0.01, start_values={"L": 0.5})
    assert_agree(X, reference(m.with_params(L=0.5), 2.0, 0.01), "pendulum ME with L = 0.5")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_calculated_values_cannot_be_set(fmus):
    import fmpy

    m, path = fmus("kepler", "kepler.mech")
    for values in ({"rp": 0.3}, {"fs.x": 0.3}):         # a dependent parameter; a start computed from parameters
        with pytest.raises(Exception):
            fmpy.simulate_fmu(str(path), start_values=values, stop_time=0.1)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_inputs_driven_through_the_fmu_as_input_does(fmus):
    """cart_pole's force F: a table held between samples (--input F=file.csv, zero-order hold)."""
    from mechdsl.simulation.drive import table

    m, path = fmus("cart_pole", "cart_pole.mech")
    times, values = [0.0, 0.5, 1.0, 2.0], [1.0, -2.0, 0.5, 0.5]
    ref = reference(m, 2.0, 0.01, inputs={"F": table(times, values, "zoh")})
    # model exchange: fmpy's input signal (the two rows at a jump time make it a step)
    signal = np.array([(0.0, 1.0), (0.5, 1.0), (0.5, -2.0), (1.0, -2.0), (1.0, 0.5), (2.0, 0.5)],
                      dtype=[("time", float), ("F", float)])
    X, _ = run_fmu(path, m, "ModelExchange", 2.0, 0.01, input=signal)
    assert_agree(X, ref, "cart_pole model exchange with a table input")
    # co-simulation: a master that sets F before every communication step (the table's value there)
    X = _co_simulate(path, m, 2.0, 0.01, lambda t: values[int(np.searchsorted(times, t + 1e-12, "right")) - 1])
    assert_agree(X, ref, "cart_pole co-simulation with a table input")
    X, _ = run_fmu(path, m, "CoSimulation", 2.0, 0.01, start_values={"F": 3.0})      # --input F=3.0
    assert_agree(X, reference(m, 2.0, 0.01, inputs={"F": 3.0}), "cart_pole with a constant input")


def _co_simulate(path, m, t_end, dt, u):
    """The co-simulation FMU stepped by hand (FMI 2): input F = u(t) set at each communication
    point, the states read after each step; (points, 2n)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")
    by = {v.name: v.valueReference for v in md.modelVariables}
    states = [by[s] for s in state_names(m)]
    fmu.instantiate()
    fmu.setupExperiment(tolerance=1e-11, startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    steps = int(round(t_end / dt))
    rows = [fmu.getReal(states)]
    for k in range(steps):
        fmu.setReal([by["F"]], [u(k * dt)])
        fmu.doStep(currentCommunicationPoint=k * dt, communicationStepSize=dt)
        rows.append(fmu.getReal(states))
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows)


def _slave(path, name="cs"):
    """(FMU2Slave instantiated and initialized at t = 0 with tolerance 1e-11, value references by name)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(tolerance=1e-11, startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_input_derivatives_drive_a_ramp_between_communication_points(fmus):
    """FMI 2 co-simulation (canInterpolateInputs): the master gives F and dF/dt at each
    communication point; the FMU follows the ramp F = 1 + 2 t inside the step, as mech simulate
    does with inputs={"F": u(t)}.  Held constant instead (no derivative), it does not."""
    m, path = fmus("cart_pole", "cart_pole.mech")
    ref = reference(m, 1.0, 0.05, inputs={"F": lambda t: 1.0 + 2.0 * t})
    for with_derivative in (True, False):
        fmu, by = _slave(path, f"ramp{with_derivative}")
        states = [by[s] for s in state_names(m)]
        rows = [fmu.getReal(states)]
        for k in range(20):
            t = 0.05 * k
            fmu.setReal([by["F"]], [1.0 + 2.0 * t])
            if with_derivative:
                fmu.setRealInputDerivatives([by["F"]], [1], [2.0])
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=0.05)
            rows.append(fmu.getReal(states))
        fmu.terminate()
        fmu.freeInstance()
        if with_derivative:
            assert_agree(np.array(rows), ref, "cart_pole with F = 1 + 2 t through input derivatives")
        else:
            assert np.max(np.abs(np.array(rows) - ref)) > 1e-4       # the ramp held: a different run


@pytest.mark.slow_cases('four_bar-four_bar.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("name,file", [("four_bar", "four_bar.mech"), ("bouncing_ball", "bouncing_ball.mech")])
def test_fmu_state_get_set_and_serialize(fmus, name, file):
    """Co-simulation from a saved state repeats the run: the state taken at t = 0.5 (kept, and
    serialized into bytes restored in a second instance) gives the same states to t = 1.5 as
    the run that went on, which matches mech simulate (the four-bar's constraints, the ball's
    impacts: the dense step kept ahead and the contact modes are part of the state)."""
    m, path = fmus(name, file)
    ref = reference(m, 1.5, 0.01)
    fmu, by = _slave(path)
    states = [by[s] for s in state_names(m)] + [by["mechdsl.steps"]]

    def run(f, k0, k1):
        rows = []
        for k in range(k0, k1):
            f.doStep(currentCommunicationPoint=0.01 * k, communicationStepSize=0.01)
            rows.append(f.getReal(states))
        return np.array(rows)

    first = run(fmu, 0, 50)
    saved = fmu.getFMUstate()
    data = fmu.serializeFMUstate(saved)
    on = run(fmu, 50, 150)
    assert_agree(np.r_[first, on][:, :-1], ref[1:], f"{name}: the run that went on")
    fmu.setFMUstate(saved)
    again = run(fmu, 50, 150)
    fmu.freeFMUstate(saved)
    other, _ = _slave(path, "restored")
    other.setFMUstate(other.deSerializeFMUstate(data))
    restored = run(other, 50, 150)
    for rows, what in ((again, "set back"), (restored, "deserialized in another instance")):
        assert np.max(np.abs(rows[:, :-1] - on[:, :-1])) <= 1e-12, f"{name}: {what}"
        assert rows[-1, -1] - rows[0, -1] == on[-1, -1] - on[0, -1], f"{name}: {what}: the same steps"
    for f in (fmu, other):
        f.terminate()
        f.freeInstance()


def _directional(path, m, x, u=None):
    """The FMU's directional derivatives (all states and inputs known, all derivatives and
    outputs unknown) column by column, and the same by central differences of its own
    derivatives and outputs."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model

    md = read_model_description(str(path))
    unzipped = extract(str(path))
    fmu = FMU2Model(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="jvp")
    fmu.instantiate()
    fmu.setupExperiment()
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    by = {v.name: v.valueReference for v in md.modelVariables}
    states = [by[s] for s in state_names(m)]
    inputs = [by[i.name] for i in m.inputs]
    ders = [by[f"der({c})"] for c in m.coordinates] + [by[f"der(der({c}))"] for c in m.coordinates]
    outs = [by[o] for o in m.eom.outputs]
    known, unknown = states + inputs, ders + outs
    u = np.zeros(len(inputs)) if u is None else np.asarray(u, float)

    import ctypes

    nx = len(states)

    def evaluate(z):
        fmu.setContinuousStates((ctypes.c_double * nx)(*z[:nx]), nx)
        if inputs:
            fmu.setReal(inputs, list(z[nx:]))
        dx = (ctypes.c_double * nx)()
        fmu.getDerivatives(dx, nx)
        return np.r_[list(dx), fmu.getReal(outs) if outs else []]

    z0 = np.r_[x, u]
    J_ad, J_fd = np.zeros((len(unknown), len(known))), np.zeros((len(unknown), len(known)))
    for j in range(len(known)):
        evaluate(z0)
        seed = np.zeros(len(known))
        seed[j] = 1.0
        J_ad[:, j] = fmu.getDirectionalDerivative(unknown, known, list(seed))
        h = 1e-6 * max(1.0, abs(z0[j]))
        zp, zm = z0.copy(), z0.copy()
        zp[j] += h
        zm[j] -= h
        J_fd[:, j] = (evaluate(zp) - evaluate(zm)) / (2 * h)
    fmu.terminate()
    fmu.freeInstance()
    return J_ad, J_fd


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_directional_derivatives_against_finite_differences(fmus):
    rng = np.random.default_rng(29)
    for name, file in (("double_pendulum", "double_pendulum.mech"), ("cart_pole", "cart_pole.mech"),
                       ("four_bar", "four_bar.mech")):
        m, path = fmus(name, file)
        q0, qd0 = m.eom.start(m.parameter_values)
        x = np.r_[q0, qd0] + rng.uniform(-0.5, 0.5, 2 * m.eom.n)
        if m.eom.m:      # on the constraints: the consistent start of mech simulate
            r = m.simulate(0.1, points=2)
            x = np.r_[r.q[-1], r.qd[-1]]
        J_ad, J_fd = _directional(path, m, x, rng.uniform(-1, 1, m.eom.nu))
        assert np.all(np.isfinite(J_ad))
        assert np.max(np.abs(J_ad - J_fd)) <= 1e-5 * max(1.0, np.max(np.abs(J_ad))), name
        md = zipfile.ZipFile(path).read("modelDescription.xml").decode()
        assert 'providesDirectionalDerivative="true"' in md


DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...) {
  (void)e; (void)n; (void)s; (void)c; fprintf(stderr, "%s\n", m);
}
int main(int argc, char **argv) {
  fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
  fmi2Component c = fmi2Instantiate("c", fmi2CoSimulation, argv[1], "", &cb, fmi2False, fmi2False);
  int nvr = argc - 2;
  fmi2ValueReference vr[16];
  fmi2Real v[16];
  for (int i = 0; i < nvr; i++) vr[i] = (fmi2ValueReference)atoi(argv[i + 2]);
  if (!c || fmi2SetupExperiment(c, fmi2True, 1e-10, 0.0, fmi2True, 1.0) || fmi2EnterInitializationMode(c)
      || fmi2ExitInitializationMode(c)) return 1;
  for (int k = 1; k <= 100; k++) {
    if (fmi2DoStep(c, (k - 1) * 0.01, 0.01, fmi2True) != fmi2OK) return 2;
    fmi2GetReal(c, vr, (size_t)nvr, v);
    for (int i = 0; i < nvr; i++) printf("%.17g%c", v[i], i + 1 < nvr ? ' ' : '\n');
  }
  fmi2FreeInstance(c);
  return 0;
}
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_fmu_runs_from_c_alone(fmus, tmp_path):
    """Built from the FMU's own sources with a plain C driver (no Python, CasADi or mechdsl)
    it gives fmpy's co-simulation numbers; the shipped binary needs only the C library."""
    from fmpy import read_model_description

    from mechdsl.eom.codegen import find_compiler

    m, path = fmus("pendulum2", "pendulum.mech")
    md = read_model_description(str(path))
    src = tmp_path / "src"
    with zipfile.ZipFile(path) as zf:
        names = [n for n in zf.namelist() if n.startswith("sources/")]
        zf.extractall(tmp_path, names + [n for n in zf.namelist() if n.startswith("binaries/")])
    (tmp_path / "sources" / "driver.c").write_text(DRIVER)
    src = tmp_path / "sources"
    cc = find_compiler()
    c_files = sorted(p.name for p in src.glob("*.c"))
    subprocess.run([cc, "-O0", "-std=gnu11", "-I.", *c_files, "-o", "driver", "-lm"], cwd=src, check=True)
    by = {v.name: v.valueReference for v in md.modelVariables}
    vrs = [str(by[n]) for n in state_names(m)]
    out = subprocess.run([str(src / "driver"), md.guid, *vrs], capture_output=True, text=True, check=True).stdout
    X = np.array([[float(v) for v in line.split()] for line in out.splitlines()])
    Y, _ = run_fmu(path, m, "CoSimulation", 1.0, 0.01)
    assert np.max(np.abs(X - Y[1:])) < 1e-9
    binary = next(tmp_path.glob("binaries/linux64/*.so"))
    dyn = subprocess.run(["readelf", "-d", str(binary)], capture_output=True, text=True, check=True).stdout
    needed = {line.split("[")[1].split("]")[0] for line in dyn.splitlines() if "(NEEDED)" in line}
    assert needed and all(n.startswith(("libc.so", "libm.so", "ld-linux")) for n in needed), needed   # the C library


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_export_is_deterministic(tmp_path):
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    a, b = tmp_path / "a.fmu", tmp_path / "b.fmu"
    m.export_fmu(a)
    m.export_fmu(b)
    assert a.read_bytes() == b.read_bytes()
    md = zipfile.ZipFile(a).read("modelDescription.xml").decode()
    for name, unit in (("j1.phi", "rad"), ("der(j1.phi)", "rad/s"), ("der(der(j1.phi))", "rad/s2"), ("m", "kg")):
        assert f'name="{name}"' in md and f'unit="{unit}"' in md
    assert 'causality="parameter" variability="tunable"' in md and 'description="mass of each rod"' in md


BOUNDED = """model Bounded "a mass on a spring, pushed"
  parameter Real m(unit = "kg", min = 0.1, max = 10) = 1 "mass";
  parameter Real k(unit = "N/m", min = 0) = 4 "stiffness";
  input Real F(unit = "N", min = -5, max = 5) = 0 "push";
  coordinate Real x(start = 0.2, unit = "m");
equation
  kinetic = 1/2*m*der(x)^2;
  potential = 1/2*k*x^2;
  force(x) = F;
end Bounded;
"""


def test_parameters_and_inputs_carry_unit_bounds_and_description(tmp_path):
    from fmpy import read_model_description

    m = mechdsl.loads(BOUNDED, filename="bounded.mech")
    path = tmp_path / "bounded.fmu"
    m.export_fmu(path, fmi_type="cs")
    by = {v.name: v for v in read_model_description(str(path)).modelVariables}
    for name, causality, unit, lo, hi, start, doc in (("m", "parameter", "kg", 0.1, 10, 1, "mass"),
                                                      ("k", "parameter", "N/m", 0, None, 4, "stiffness"),
                                                      ("F", "input", "N", -5, 5, 0, "push")):
        v = by[name]
        assert (v.causality, v.unit, v.description) == (causality, unit, doc), name
        for got, want in ((v.min, lo), (v.max, hi), (v.start, start)):
            assert (got is None) == (want is None) and (want is None or float(got) == pytest.approx(want)), name
    assert by["m"].variability == "tunable"


def test_bad_input_is_refused_and_nothing_is_written(tmp_path, monkeypatch):
    ball = mechdsl.load(MODELS / "bouncing_ball.mech")
    with pytest.raises(UsageError, match="does not exist"):
        ball.export_fmu(tmp_path / "missing" / "ball.fmu")
    with pytest.raises(UsageError, match="--fmi-type"):
        ball.export_fmu(tmp_path / "ball.fmu", fmi_type="model-exchange")
    with pytest.raises(UsageError, match=r"\.fmu"):
        ball.export_fmu(tmp_path / "ball.zip")
    with pytest.raises(UsageError, match="FMI version"):
        ball.export_fmu(tmp_path / "ball.fmu", fmi_version=1)
    foreign = tmp_path / "mine.fmu"
    foreign.write_bytes(b"not mechdsl's")
    with pytest.raises(UsageError, match="--force"):
        ball.export_fmu(foreign)
    assert foreign.read_bytes() == b"not mechdsl's"
    monkeypatch.setenv("CC", "no-such-compiler-here")           # fails while building: nothing half-written
    with pytest.raises(MechError) as e:
        mechdsl.load(MODELS / "pendulum.mech").export_fmu(tmp_path / "p.fmu")
    assert e.value.diagnostics[0].code == "E893"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.fmu"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_command_line(tmp_path, capsys):
    from mechdsl.cli import main

    out = tmp_path / "ball.fmu"
    assert main(["export", str(MODELS / "bouncing_ball.mech"), "--fmu", str(out), "--fmi-version", "3"]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out} (FMI 3.0: model exchange, co-simulation" in text
    assert validate_fmu(str(out)) == []
    md = zipfile.ZipFile(out).read("modelDescription.xml").decode()
    assert '<EventIndicator valueReference=' in md and 'mechdsl.event_indicator[floor]' in md
    assert main(["export", str(MODELS / "pendulum.mech"), "--fmu", str(tmp_path / "no" / "p.fmu")]) == 2
    assert main(["export", str(MODELS / "pendulum.mech"), "--fmu", str(out), "--set", "L=2"]) == 0   # its own: replaced
    assert 'name="L"' in zipfile.ZipFile(out).read("modelDescription.xml").decode()
    assert os.path.getsize(out) > 10_000


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_fmi3_event_indicator_variables_read_as_the_indicators(fmus):
    """FMI 3 model exchange of the falling rod (two contacts): the ``mechdsl.event_indicator[...]``
    variables read in one fmi3GetFloat64 call, in any order and mixed with a state, are the values
    fmi3GetEventIndicators gives (the indicators are evaluated once per call)."""
    from ctypes import POINTER, c_double

    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model

    m, path = fmus("falling_rod3", "falling_rod.mech", version=3)
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ind = sorted((n for n in vr if n.startswith("mechdsl.event_indicator[")), key=vr.get)   # in indicator order
    assert len(ind) == 2 and md.numberOfEventIndicators == 2
    state = state_names(m)[0]
    fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="rod")
    fmu.instantiate()
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        e, x0 = np.zeros(2), np.zeros(len(state_names(m)))
        fmu.getEventIndicators(e.ctypes.data_as(POINTER(c_double)), e.size)
        fmu.getContinuousStates(x0.ctypes.data_as(POINTER(c_double)), x0.size)
        got = np.array(fmu.getFloat64([vr[ind[1]], vr[state], vr[ind[0]], vr[ind[1]]]))
    finally:
        fmu.terminate()
        fmu.freeInstance()
    assert np.all(e > 0.0), e                                  # both ends above the floor at the start
    np.testing.assert_allclose(got[[0, 2]], e[[1, 0]], rtol=1e-15, atol=0)
    np.testing.assert_allclose(got[3], got[0], rtol=1e-15, atol=0)
    np.testing.assert_allclose(got[1], x0[0], rtol=1e-15, atol=0)
