"""Models used as component types (`Link l1(L = 2);`): names, modifiers, scenes, nesting, errors,
and the physics of composed models against independent references."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError

from test_mech_nlink import sympy_nlink

LINK = """
model Link "a uniform rod, the part of a chain"
  parameter Real L(unit = "m") = 1;
  parameter Real m(unit = "kg") = 1;
  coordinate Real q(start = 0, unit = "rad");
  Rod rod(m = m, L = L, axis = {0, -1, 0});
  output Real tipx(unit = "m") = rod.b.x;
end Link;
"""

CHAIN = LINK + """
model Chain
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Link l1(q(start = pi/2));
  Link l2;
  Link l3;
  Revolute j1(parent = world, child = l1.rod.a, axis = {0, 0, 1}, phi = l1.q);
  Revolute j2(parent = l1.rod.b, child = l2.rod.a, axis = {0, 0, 1}, phi = l2.q);
  Revolute j3(parent = l2.rod.b, child = l3.rod.a, axis = {0, 0, 1}, phi = l3.q);
  output Real x3(unit = "m") = l3.tipx;
end Chain;

scene Heavy
  model Chain(l1(m = 3), l2.L = 2);
  stop_time = 0.5;
end Heavy;
"""

OSC = """
model Osc "a mass on a spring to the ground, written as T and V"
  parameter Real m(unit = "kg") = 1;
  parameter Real k(unit = "N/m") = 4;
  coordinate Real x(start = 0, unit = "m");
equation
  kinetic = m/2*der(x)^2;
  potential = k/2*x^2;
end Osc;

model Pair "two oscillators coupled by a spring written in the parent"
  parameter Real c(unit = "N/m") = 3;
  Osc a(x(start = 0.1));
  Osc b;
equation
  potential = c/2*(a.x - b.x)^2;
end Pair;

model Nested "instances of a model that has instances"
  Pair left(c = 1);
  Pair right(a(k = 9));
end Nested;
"""


def _qdd(m, x):
    ode = m.casadi()["ode"]
    n = len(m.coordinates)
    return np.array(ode(0.0, x, [], m.parameter_values)).ravel()[n:]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_chain_of_link_instances_matches_sympy_mechanics():
    """Three Link instances joined by revolute joints == sympy.physics.mechanics (Kane) at random states."""
    m = mechdsl.loads(CHAIN, model="Chain")
    assert m.coordinates == ("l1.q", "l2.q", "l3.q")
    ref = sympy_nlink(3)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, u = rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 3)
        np.testing.assert_allclose(_qdd(m, np.r_[q, u]), ref(q, u), rtol=1e-10, atol=1e-10)


def test_modifiers_from_parent_scene_and_api_reach_the_instance():
    m = mechdsl.loads(CHAIN, scene="Heavy")
    p = m.parameters
    assert p["l1.m"] == 3 and p["l2.L"] == 2 and p["l3.L"] == 1 and p["l1.L"] == 1
    base = mechdsl.loads(CHAIN, model="Chain")
    same = base.with_params(**{"l1.m": 3.0, "l2.L": 2.0})
    x = np.r_[0.3, -0.2, 0.5, 0.1, 0.4, -0.3]
    np.testing.assert_allclose(_qdd(m, x), _qdd(same, x), rtol=1e-13)
    assert not np.allclose(_qdd(m, x), _qdd(base, x))
    r = base.simulate(0.1, points=3)
    assert r.q[0, 0] == pytest.approx(math.pi / 2)  # the start value set through `l1(q(start = pi/2))`


def test_coupled_oscillator_instances_frequencies_closed_form():
    """Two Osc instances coupled in the parent: w^2 = k/m and (k + 2c)/m."""
    m = mechdsl.loads(OSC, model="Pair")
    w = m.linearize(at="equilibrium").modes().frequencies
    np.testing.assert_allclose(w, [math.sqrt(4.0), math.sqrt(4.0 + 2 * 3.0)], rtol=1e-10)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_nested_instances_names_and_modifiers():
    m = mechdsl.loads(OSC, model="Nested")
    assert m.coordinates == ("left.a.x", "left.b.x", "right.a.x", "right.b.x")
    p = m.parameters
    assert p["left.c"] == 1 and p["right.c"] == 3 and p["right.a.k"] == 9 and p["left.a.k"] == 4
    # the two pairs are independent: frequencies of each, from the closed form of a 2x2 problem
    w = m.linearize(at="equilibrium").modes().frequencies
    K_right = np.array([[9 + 3, -3], [-3, 4 + 3]])
    expected = sorted([2.0, math.sqrt(4 + 2)] + list(np.sqrt(np.linalg.eigvalsh(K_right))))
    np.testing.assert_allclose(w, expected, rtol=1e-10)


def test_instance_in_extends_and_extends_in_instance():
    text = LINK + """
model HeavyLink
  extends Link(m = 5);
end HeavyLink;
model One
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  HeavyLink h(L = 2);
  Revolute j(parent = world, child = h.rod.a, axis = {0, 0, 1}, phi = h.q);
end One;
model OneMore
  extends One(h(L = 3));
end OneMore;
"""
    m = mechdsl.loads(text, model="OneMore")
    assert m.parameters["h.m"] == 5 and m.parameters["h.L"] == 3
    # a uniform rod pivoted at one end: qdd = -(3 g / 2 L) sin q
    q = 0.7
    assert _qdd(m, np.r_[q, 0.0])[0] == pytest.approx(-1.5 * 9.81 / 3 * math.sin(q), rel=1e-12)


@pytest.mark.parametrize("snippet, code", [
    ("Link l(foo = 1);", "E204"),
    ("Link l; output Real y = l.nothing;", "E201"),
    ("Link l; output Real y = l;", "E201"),
    ("Link l[2, 2];", "E301"),            # arrays of instances have one dimension (test_lang_instance_arrays.py)
    ("parameter Link l;", "E215"),
    ("Link l; Link l;", "E202"),
    ("Link l = 3;", "E214"),
])
def test_instance_errors(snippet, code):
    text = LINK + f"model M\n  {snippet}\n  coordinate Real z(start = 0);\nequation\n  kinetic = der(z)^2/2;\nend M;\n"
    with pytest.raises(MechError) as e:
        mechdsl.loads(text, model="M")
    assert code in [d.code for d in e.value.diagnostics]


def test_instance_cycle_is_reported():
    text = "model A\n  B b;\n  coordinate Real z(start = 0);\nequation\n  kinetic = der(z)^2/2;\nend A;\n" \
           "model B\n  A a;\nend B;\n"
    with pytest.raises(MechError) as e:
        mechdsl.loads(text, model="A")
    assert [d.code for d in e.value.diagnostics] == ["E207"]


def test_cli_check_and_simulate_with_instances(tmp_path, capsys):
    f = tmp_path / "chain.mech"
    f.write_text(CHAIN)
    assert main(["check", str(f)]) == 0
    out = capsys.readouterr().out
    assert "Link: a part of Chain (checked there)" in out and "Chain: 3 bodies, 3 joints" in out
    csv = tmp_path / "out.csv"
    assert main(["simulate", str(f), "--scene", "Heavy", "--points", "5", "-o", str(csv)]) == 0
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:7] == ["time", "l1.q", "l2.q", "l3.q", "der(l1.q)", "der(l2.q)", "der(l3.q)"]


@pytest.mark.parametrize("k, m, L", [(2.0, 1.0, 1.0), (5.0, 2.0, 0.7)])
def test_shipped_coupled_pendulums_modes_closed_form(k, m, L):
    """models/coupled_pendulums.mech (two SwingingBob instances and a spring):
    w1^2 = g/L (in phase), w2^2 = g/L + 2k/m (in opposition)."""
    from conftest import MODELS

    model = mechdsl.load(MODELS / "coupled_pendulums.mech", model="CoupledPendulums")
    model = model.with_params(k=k, **{"left.m": m, "right.m": m, "left.L": L, "right.L": L})
    modes = model.linearize(at="equilibrium").modes()
    g = 9.81
    np.testing.assert_allclose(modes.frequencies, [math.sqrt(g / L), math.sqrt(g / L + 2 * k / m)], rtol=1e-10)
    s1, s2 = (np.asarray(modes.shapes)[:, i] for i in range(2))
    assert s1[1] / s1[0] == pytest.approx(1.0, rel=1e-9)     # in phase
    assert s2[1] / s2[0] == pytest.approx(-1.0, rel=1e-9)    # in opposition
