"""Crossing singular configurations: formulation "augmented" (mechdsl.dae.augmented).

The independent check is the N-four-bar of IFToMM A02 (models/nfourbar.mech): with equal
rods it is a chain of parallelograms, so every crank turns by the same angle theta (from
the upward vertical) and the couplers translate; the motion is that of one degree of
freedom with

    T = (N + 1) (1/2) (m l^2 / 3) theta'^2 + N (1/2) m l^2 theta'^2
    V = (N + 1) m g (l / 2) cos(theta) + N m g l cos(theta),

integrated here with scipy at tolerance 1e-12.  The cranks pass horizontal (theta = pi/2 +
k pi) about once every 0.5 s, where the loop constraints' Jacobian loses rank.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mechdsl
from dae_models import parallelogram_eom, parallelogram_singular_time
from mechdsl.cli import main
from mechdsl.dae import simulate_dae
from mechdsl.dae.augmented import augmented_ode, project_positions, project_velocities, PENALTY
from mechdsl.dae.dof import dof_report
from mechdsl.dae.projection import project
from mechdsl.dae.constrained_system import ConstrainedSystem
import mechdsl.examples

MODEL = mechdsl.examples.path("nfourbar")
M_ROD, L_ROD, GRAV, V0 = 1.0, 1.0, 9.81, 1.0


def reference_theta(N: int, t_end: float):
    """theta(t) of the 1-DOF parallelogram chain (dense output), theta(0) = 0, theta'(0) = v0/l."""
    inertia = ((N + 1) / 3 + N) * M_ROD * L_ROD**2
    weight = ((N + 1) / 2 + N) * M_ROD * GRAV * L_ROD            # V = weight cos(theta)
    sol = solve_ivp(lambda t, y: [y[1], weight * np.sin(y[0]) / inertia], (0.0, t_end), [0.0, V0 / L_ROD],
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    return sol.sol


def passages(theta, t_end: float) -> np.ndarray:
    """Times at which theta passes pi/2 + k pi (theta increases monotonically here)."""
    from scipy.optimize import brentq

    ts = np.linspace(0.0, t_end, 4001)
    th = theta(ts)[0]
    out = []
    for k in range(int((th[-1] - np.pi / 2) // np.pi) + 1):
        level = np.pi / 2 + k * np.pi
        i = int(np.argmax(th > level))
        out.append(brentq(lambda t: theta(t)[0] - level, ts[i - 1], ts[i], xtol=1e-13))
    return np.array(out)


def nfourbar(N: int):
    return mechdsl.load(MODEL, scene="A02").with_params(N=N)


def check_against_reference(model, r, N: int, angle_tol: float):
    coords = model.eom.coords
    theta = reference_theta(N, r.t[-1])
    th, w = theta(r.t)
    cranks = [i for i, c in enumerate(coords) if c.startswith("ground[")]
    couplers = [i for i, c in enumerate(coords) if c.startswith("left[")]
    assert len(cranks) == N + 1 and len(couplers) == N
    # every crank turns by -theta (phi about +z), every coupler by +theta relative to its crank
    assert np.max(np.abs(r.q[:, cranks] + th[:, None])) < angle_tol
    assert np.max(np.abs(r.q[:, couplers] - th[:, None])) < angle_tol
    assert np.max(np.abs(r.qd[:, cranks] + w[:, None])) < 2 * angle_tol      # speeds (up to ~6.7 rad/s)
    # the first crank's tip (the benchmark's point B0)
    assert np.max(np.abs(r["x_top"] - L_ROD * np.sin(th))) < 2 * angle_tol
    assert np.max(np.abs(r["y_top"] - L_ROD * np.cos(th))) < 2 * angle_tol
    return theta


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("N", [2, 3])
def test_nfourbar_crosses_every_singular_configuration_like_the_one_dof_reference(N):
    model = nfourbar(N)
    # the scene: 20 s, 2001 points, augmented; checked against the one-dof reference (no estimate)
    r = model.simulate(rtol=1e-9, atol=1e-11, error_estimate="off")
    assert r.metadata["formulation"] == "augmented"
    assert r.success, r.message
    assert r.t[-1] == pytest.approx(20.0)
    theta = check_against_reference(model, r, N, angle_tol=3e-6)
    # it passed ~20 singular configurations, each reported once, near the reference time
    expected = passages(theta, 20.0)
    assert len(expected) >= 18
    got = np.array([e["time"] for e in r.events if e["kind"] == "singular"])
    assert len(got) == len(expected)
    assert np.max(np.abs(got - expected)) < 2e-3
    assert r.stats["min_singular_ratio"] < 1e-2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_energy_and_drift_stay_bounded_through_the_passages():
    r = nfourbar(3).simulate(rtol=1e-9, atol=1e-11, error_estimate="off")
    again = nfourbar(3).simulate(rtol=1e-9, atol=1e-11, error_estimate="off")
    np.testing.assert_array_equal(r.q, again.q)              # deterministic
    assert [e["time"] for e in r.events] == [e["time"] for e in again.events]
    E = r["energy"]
    scale = np.max(np.abs(r["kinetic_energy"]))
    assert np.max(np.abs(E - E[0])) < 1e-7 * scale
    assert r.stats["drift_ok"]
    assert r.stats["max_constraint_drift"] <= r.stats["drift_bound"]
    assert r.stats["max_velocity_drift"] <= r.stats["drift_bound"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_accuracy_follows_the_tolerance():
    errs = []
    for tol in (1e-6, 1e-9):
        model = nfourbar(2)
        r = model.simulate(rtol=tol, atol=tol * 1e-2, points=201, error_estimate="off")   # vs the reference
        th = reference_theta(2, 20.0)(r.t)[0]
        errs.append(np.max(np.abs(r.q[:, 0] + th)))
    assert errs[1] < 1e-2 * errs[0] and errs[1] < 2e-6


def test_independent_parallelogram_crosses_its_flat_position():
    """The four-bar of tests/dae_models (Lagrange's equations in absolute angles, written
    independently of the mechanics) passes the flat position where the other formulations stop."""
    t_star = parallelogram_singular_time()
    r = simulate_dae(parallelogram_eom(), 3.0, formulation="augmented", rtol=1e-10, atol=1e-12, points=301)
    assert r.success, r.message
    theta = reference_theta(1, 3.0)
    th1 = np.pi / 2 - theta(r.t)[0]          # absolute crank angle from the x axis
    assert np.max(np.abs(r.q[:, 0] - th1)) < 1e-6
    assert np.max(np.abs(r.q[:, 2] - th1)) < 1e-6 and np.max(np.abs(r.q[:, 1])) < 1e-6
    first = min(e["time"] for e in r.events if e["kind"] == "singular")
    assert abs(first - t_star) < 2e-3


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_default_projection_still_refuses_at_the_first_passage():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = nfourbar(2).simulate(formulation="projection", rtol=1e-10, atol=1e-12)
    assert not r.success and r.failure.cause == "singular configuration"
    t_first = passages(reference_theta(2, 2.0), 2.0)[0]
    assert abs(r.failure.time - t_first) < 1e-4


def _system(N):
    e = nfourbar(N).eom
    pv = np.array(e.param_values, float)
    q0, _ = e.start(pv)
    s = ConstrainedSystem.build(e, pv, dof_report(e, q0, 0.0, pv).independent)
    s.fix_row_scale(q0, 0.0)
    return e, pv, s


def test_augmented_accelerations_equal_the_kkt_solution_at_random_states():
    import casadi as ca

    e, pv, s = _system(3)
    dae = augmented_ode(s, s.row_scale)
    f = ca.Function("f", [dae["x"], dae["t"], dae["p"]], [dae["ode"]])
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = rng.uniform(-3, 3, e.n)
        qd = rng.uniform(-2, 2, e.n)
        ab = rng.uniform(0, 5, 2)
        if np.linalg.svd(s.scaled_G(q, 0.0), compute_uv=False)[-1] < 0.05:
            continue                                  # (near a singular configuration they differ)
        a = np.array(f(np.r_[q, qd], 0.0, np.r_[pv, ab]), float).ravel()[e.n:]
        a_kkt, _ = s.accel(q, qd, 0.0, *ab)
        assert np.max(np.abs(a - a_kkt)) < 1e-9 * max(1.0, np.max(np.abs(a_kkt)))


def test_penalty_projections_equal_the_kkt_projections_and_stay_bounded_at_the_singularity():
    e, pv, s = _system(2)
    A = PENALTY * s.row_scale**2
    rng = np.random.default_rng(3)
    crank = np.array([c.startswith("ground[") for c in e.coords])
    for th in (0.4, 1.2, np.pi / 2 - 1e-3, np.pi / 2):
        q = np.where(crank, -th, th) + 1e-6 * rng.standard_normal(e.n)
        qd = np.where(crank, -2.0, 2.0) + 1e-6 * rng.standard_normal(e.n)
        qa = project_positions(s, q, 0.0, A, 1e-13)
        va = project_velocities(s, qa, qd, 0.0, A, 1e-13)
        assert np.max(np.abs(s.g(qa, 0.0))) < 1e-12
        # bounded: no jump (at the crossing the projected point lies on any of the crossing
        # branches, 1e-6 away; measured 6e-4 change of a speed of 2 there)
        assert np.max(np.abs(qa - q)) < 1e-5 and np.max(np.abs(va - qd)) < (1e-4 if th < 1.5 else 2e-3)
        if th < np.pi / 2:
            assert np.max(np.abs(s.gdot(qa, va, 0.0))) < 1e-12
        else:   # at the crossing the near-singular mode is left alone (a KKT solve divides by ~1e-6 there)
            assert np.max(np.abs(s.gdot(qa, va, 0.0))) <= np.max(np.abs(s.gdot(qa, qd, 0.0)))
        if th < 1.5:      # regular: the M-orthogonal projections of the KKT route
            qk, vk = project(s, q, qd, 0.0, 1e-13)
            assert np.max(np.abs(qa - qk)) < 1e-10 and np.max(np.abs(va - vk)) < 1e-9


SCENE_N2 = """scene Short "N = 2, 5 s"
  model NFourBar(N = 2);
  formulation = "augmented";
  stop_time = 5;
  points = 51;
end Short;
"""


def test_cli_honours_the_scene_formulation(tmp_path, capsys):
    """`mech simulate` used to ignore the scene's formulation (the API honoured it): the run
    stopped at the first singular configuration."""
    src = tmp_path / "nfb.mech"
    text = MODEL.read_text()
    src.write_text(text[:text.index("scene A02")] + SCENE_N2)
    code = main(["simulate", str(src), "-o", str(tmp_path / "out.csv")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "t = 0 .. 5 s (51 points)" in out and "FAILED" not in out


@pytest.mark.slow
def test_a02_scene_runs_its_20_seconds():
    """The shipped scene as described: N = 40, 20 s, 2001 points.  IFToMM A02's high-precision
    bound is 1e-3 on the position of B0 (lim.ii.udc.es/mbsbenchmark/dist/A02/A02_specification.xml);
    the 1-DOF reference here is exact, so the bound is much tighter."""
    model = mechdsl.load(MODEL, scene="A02")
    r = model.simulate()
    assert r.success, r.message
    assert len(r.t) == 2001 and r.t[-1] == pytest.approx(20.0)
    theta = check_against_reference(model, r, 40, angle_tol=2e-5)
    assert len([e for e in r.events if e["kind"] == "singular"]) == len(passages(theta, 20.0))
    E = r["energy"]
    assert np.max(np.abs(E - E[0])) < 1e-6 * np.max(np.abs(r["kinetic_energy"]))
    assert r.stats["drift_ok"]


def _massless_z(tied: bool):
    """A pendulum bob (x, y) on a unit rod and a coordinate z without inertia, tied to x
    (z = x) or free."""
    import casadi as ca

    from mechdsl.eom import from_lagrangian

    q, qd, t, p = ca.SX.sym("q", 3), ca.SX.sym("qd", 3), ca.SX.sym("t"), ca.SX.sym("p", 0)
    g = [0.5 * (q[0] ** 2 + q[1] ** 2 - 1)] + ([q[2] - q[0]] if tied else [])
    return from_lagrangian("Massless", ("x", "y", "z"), (), [], q, qd, t, p, 0.5 * (qd[0] ** 2 + qd[1] ** 2),
                           9.81 * q[1], g=ca.vertcat(*g), q0=[1, 0, 1], constraint_names=["rod", "tie"][:len(g)])


def test_a_coordinate_without_inertia_held_by_a_constraint_is_fine():
    a = simulate_dae(_massless_z(True), 2.0, formulation="augmented", rtol=1e-10, atol=1e-10, points=5)
    b = simulate_dae(_massless_z(True), 2.0, formulation="projection", rtol=1e-10, atol=1e-10, points=5)
    assert a.success and np.max(np.abs(a.q - b.q)) < 1e-8
    assert np.max(np.abs(a.q[:, 2] - a.q[:, 0])) < 1e-9


def test_a_coordinate_without_inertia_nothing_holds_is_e840():
    from mechdsl.diagnostics import MechError

    from mechdsl.simulation import formulate, solve
    from mechdsl.simulation.settings import from_kwargs

    with pytest.raises(MechError) as start:          # the start check of every run (as Model.simulate)
        simulate_dae(_massless_z(False), 1.0, formulation="augmented", points=3)
    assert start.value.first.code == "E743"
    with pytest.raises(MechError) as err:            # the augmented formulation's own check, past it
        solve(formulate(_massless_z(False), from_kwargs(1.0, formulation="augmented", points=3)))
    assert err.value.first.code == "E840" and "along z" in err.value.first.message
    assert "projection" in err.value.first.help
