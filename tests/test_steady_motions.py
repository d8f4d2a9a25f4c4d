"""Issue 17: steady motions (relative equilibria of the Routh-reduced system) against closed forms:
the heavy top's slow and fast precession, the conical pendulum, circular orbits in a central field."""
import math

import numpy as np
import pytest
import sympy as sp

import mechdsl
from mechdsl.analysis.steady import steady_motions

from conftest import MODELS

TOP = dict(m=1.0, l=0.5, g=9.81, I1=0.12, I3=0.2)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_heavy_top_slow_and_fast_precession():
    """m g l = phi' (I3 w3 - A phi' cos th), A = I1 + m l^2: two roots for a given nutation and spin."""
    model = mechdsl.load(MODELS / "heavy_top.mech", model="HeavyTop")
    th, w3 = 0.6, 20.0
    A, I3, mgl = TOP["I1"] + TOP["m"] * TOP["l"]**2, TOP["I3"], TOP["m"] * TOP["g"] * TOP["l"]
    found = steady_motions(model.eom, {"tip.theta": th, "p_tip.psi": I3 * w3},
                           ignorable=["tip.phi", "tip.psi"], max_guesses=30)
    c = math.cos(th)
    disc = math.sqrt((I3 * w3)**2 - 4 * A * c * mgl)
    slow, fast = (I3 * w3 - disc) / (2 * A * c), (I3 * w3 + disc) / (2 * A * c)
    assert [s.speeds["der(tip.phi)"] for s in found] == pytest.approx([slow, fast], rel=1e-9)
    for s in found:
        assert s.values["tip.theta"] == pytest.approx(th, abs=1e-12)
        phid = s.speeds["der(tip.phi)"]
        assert s.speeds["der(tip.psi)"] + phid * c == pytest.approx(w3, rel=1e-12)      # the pinned spin
        # Routh's reduced potential, independently in sympy: V_R'' at the momenta of the motion
        T, pphi, ppsi = sp.symbols("theta p_phi p_psi")
        VR = mgl * sp.cos(T) + (pphi - ppsi * sp.cos(T))**2 / (2 * A * sp.sin(T)**2) + ppsi**2 / (2 * I3)
        d2 = float(sp.diff(VR, T, 2).subs({T: th, pphi: s.momenta["p_tip.phi"], ppsi: s.momenta["p_tip.psi"]}))
        assert s.hessian_eigenvalues == pytest.approx([d2], rel=1e-8)
        assert float(sp.diff(VR, T).subs({T: th, pphi: s.momenta["p_tip.phi"], ppsi: s.momenta["p_tip.psi"]})) \
            == pytest.approx(0, abs=1e-9)
        assert s.stable is True
        # the reduced linear system oscillates at sqrt(V_R''/A) (nutation about the steady motion)
        assert np.max(np.abs(s.linear_eigenvalues.imag)) == pytest.approx(math.sqrt(d2 / A), rel=1e-8)


CONICAL = """
model Conical "a spherical pendulum in its polar angles"
  parameter Real m = 0.8;
  parameter Real L = 1.3;
  parameter Real g = 9.81;
  coordinate Real th(start = 0.5, unit = "rad");
  coordinate Real ph(start = 0, speed = 2, unit = "rad");
equation
  kinetic = 1/2*m*L^2*(der(th)^2 + sin(th)^2*der(ph)^2);
  potential = -m*g*L*cos(th);
end Conical;
"""


@pytest.mark.parametrize("th", [0.3, 0.9, 1.3])
def test_conical_pendulum(th):
    """phi'^2 = g / (L cos th), both senses; nutation about it at w^2 = (g/L)(1 + 3 cos^2 th)/cos th."""
    m, L, g = 0.8, 1.3, 9.81
    found = steady_motions(mechdsl.loads(CONICAL).eom, {"th": th})
    rate = math.sqrt(g / (L * math.cos(th)))
    assert [s.speeds["der(ph)"] for s in found] == pytest.approx([-rate, rate], rel=1e-9)
    for s in found:
        assert s.stable is True
        assert s.momenta["p_ph"] == pytest.approx(m * L**2 * math.sin(th)**2 * s.speeds["der(ph)"], rel=1e-12)
        w2 = g / L * (1 + 3 * math.cos(th)**2) / math.cos(th)
        assert np.max(np.abs(s.linear_eigenvalues.imag)) == pytest.approx(math.sqrt(w2), rel=1e-8)


def _central(potential):
    return mechdsl.loads(f"""
model Central "a particle in a central field, polar coordinates"
  parameter Real m = 1.5;
  parameter Real k = 2;
  coordinate Real r(start = 1);
  coordinate Real ph(start = 0, speed = 1, unit = "rad");
equation
  kinetic = 1/2*m*(der(r)^2 + r^2*der(ph)^2);
  potential = {potential};
end Central;
""")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_circular_orbit_kepler_is_stable_with_the_orbital_frequency():
    """V = -k/r: r* = h^2/(m k) for the angular momentum h; radial frequency = orbital frequency."""
    m, k, h = 1.5, 2.0, 1.7
    (s,) = steady_motions(_central("-k/r").eom, {"p_ph": h}, max_guesses=30)
    r = h**2 / (m * k)
    assert s.values["r"] == pytest.approx(r, rel=1e-10)
    assert s.speeds["der(ph)"] == pytest.approx(h / (m * r**2), rel=1e-10)
    assert s.stable is True
    assert s.hessian_eigenvalues == pytest.approx([k / r**3], rel=1e-8)        # V_R'' = -2k/r^3 + 3h^2/(m r^4)
    assert np.max(np.abs(s.linear_eigenvalues.imag)) == pytest.approx(h / (m * r**2), rel=1e-8)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_steady_table_units_of_a_length_and_an_angle():
    """r in m, ph in deg: der(ph) in rad/s, p_ph = m r^2 ph' in kg.m2/s, V_R'' (r alone) in N/m."""
    from mechdsl.commands.equilibrium import format_steady, steady_units
    from mechdsl.model.units import motion_units

    assert motion_units("deg") == ("rad/s", "kg.m2/s") and motion_units("mm") == ("m/s", "kg.m/s")
    assert motion_units("") == ("", "")
    model = _central("-k/r")
    (s,) = steady_motions(model.eom, {"p_ph": 1.7}, max_guesses=30)
    units = {"r": "m", "ph": "rad"}
    assert steady_units([s], units) == ({"r": "m", "der(ph)": "rad/s", "p_ph": "kg.m2/s"}, "N/m")
    text = format_steady("Central", {"p_ph": 1.7}, [s], units)
    assert "r [m]" in text and "der(ph) [rad/s]" in text and "Hessian of V_R [N/m]" in text
    assert steady_units([s], {}) == ({"r": "", "der(ph)": "", "p_ph": ""}, "")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_circular_orbit_in_an_inverse_cube_field_is_unstable():
    """V = -k/(2 r^2) ... falls as fast as the centrifugal term: take V = -k/r^3, unstable for any h."""
    m, k, h = 1.5, 2.0, 1.7
    (s,) = steady_motions(_central("-k/r^3").eom, {"p_ph": h}, guesses={"r": 2.0}, max_guesses=20)
    r = 3 * k * m / h**2                  # V'(r) = 3k/r^4 = h^2/(m r^3)
    assert s.values["r"] == pytest.approx(r, rel=1e-10)
    assert s.stable is False and "positive real part" in s.reason
    assert s.hessian_eigenvalues[0] == pytest.approx(-12 * k / r**5 + 3 * h**2 / (m * r**4), rel=1e-8)


def test_pins_are_checked():
    model = mechdsl.loads(CONICAL)
    with pytest.raises(mechdsl.UsageError, match="need 1 pin"):
        steady_motions(model.eom, {})
    with pytest.raises(mechdsl.UsageError, match="ignorable"):
        steady_motions(model.eom, {"ph": 1.0})
    with pytest.raises(mechdsl.UsageError, match="cannot pin"):
        steady_motions(model.eom, {"der(th)": 1.0})


def test_no_ignorable_coordinate_is_a_model_error():
    model = mechdsl.load(MODELS / "pendulum.mech")
    with pytest.raises(mechdsl.MechError) as info:
        steady_motions(model.eom, {})
    assert info.value.diagnostics[0].code == "E912"


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_steady(capsys, tmp_path):
    from mechdsl.cli import main

    top = str(MODELS / "heavy_top.mech")
    out = tmp_path / "steady.json"
    assert main(["equilibrium", top, "--model", "HeavyTop", "--steady", "tip.theta=0.6,p_tip.psi=4",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 steady motions" in text and "1.36942" in text and "11.7293" in text and "stable" in text
    # every column says its unit: angles rad, speeds rad/s, momenta kg.m2/s, V_R'' N.m/rad
    for head in ("tip.theta [rad]", "der(tip.phi) [rad/s]", "p_tip.psi [kg.m2/s]", "Hessian of V_R [N.m/rad]"):
        assert head in text
    import json

    data = json.loads(out.read_text())
    assert data["units"] == {"tip.theta": "rad", "der(tip.phi)": "rad/s", "der(tip.psi)": "rad/s",
                             "p_tip.phi": "kg.m2/s", "p_tip.psi": "kg.m2/s"}
    assert data["hessian_unit"] == "N.m/rad"
    assert data["count"] == 2 and data["steady_motions"][0]["speeds"]["der(tip.phi)"] == pytest.approx(1.3694173, 1e-6)
    assert main(["equilibrium", top, "--model", "HeavyTop", "--steady", "tip.phi=1,p_tip.psi=4"]) == 2
    assert "ignorable" in capsys.readouterr().err


def test_sleeping_top_at_the_euler_singularity_is_reported_not_a_crash(capsys):
    """Pinning both spin rates finds the top upright (theta = 0) and hanging (theta = pi), where
    phi and psi turn about one axis: the ignorables' block of M is singular, Routh's reduced
    potential is undefined.  Found before: an internal error (LinAlgError) from the CLI.  The
    motions are real (the residual of the equations at constant speeds is zero); their stability
    is reported as not decided, with the reason."""
    from mechdsl.cli import main

    model = mechdsl.load(MODELS / "heavy_top.mech", model="HeavyTop")
    found = steady_motions(model.eom, {"der(tip.phi)": 0.5, "der(tip.psi)": 0.5}, max_guesses=30)
    thetas = sorted(abs(s.values["tip.theta"]) for s in found)
    assert thetas == pytest.approx([0.0, math.pi], abs=1e-9)
    for s in found:
        assert s.stable is None and "singular" in s.reason and s.residual <= 1e-8
    # p_psi = I3 (phi' cos theta + psi'): 0.2 * 1 upright
    upright = min(found, key=lambda s: abs(s.values["tip.theta"]))
    assert upright.momenta["p_tip.psi"] == pytest.approx(TOP["I3"] * 1.0, rel=1e-12)
    assert main(["equilibrium", str(MODELS / "heavy_top.mech"), "--model", "HeavyTop",
                 "--steady", "der(tip.phi)=0.5,der(tip.psi)=0.5"]) == 0
    assert "not decided" in capsys.readouterr().out
