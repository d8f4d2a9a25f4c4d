"""Issue 17: arrays of model instances (`Link links[N]` with `for` + connect) and indexed start
overrides (`q[2].start`, `links[2].q.start`) through with_params and --set. A chain of N
user-defined links has the same equations as the shipped chain of primitives
(models/nlink_pendulum.mech) at random states."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError
from reach_util import accelerations, evaluator

SHIPPED = Path(__file__).parents[1] / "models" / "nlink_pendulum.mech"

CHAIN = """
model Link "a uniform rod on its hinge, a part of a chain"
  parameter Real L(unit = "m") = 1;
  parameter Real m(unit = "kg") = 1;
  coordinate Real q(start = 0, unit = "rad");
  Rod rod(m = m, L = L, axis = {0, -1, 0});
  Revolute j(axis = {0, 0, 1}, phi = q);
end Link;

model Chain "the same chain, written once with an array of Link instances"
  parameter Integer N = 3;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Link links[N](each m = 1, each L = 1, q(start = {if i == 1 then pi/2 else 0 for i in 1:N}));
  output Real tip_x(unit = "m") = links[N].rod.b.x;
equation
  connect(world, links[1].j, links[1].rod.a);
  for i in 2:N loop
    connect(links[i - 1].rod.b, links[i].j, links[i].rod.a);
  end for;
end Chain;
"""


@pytest.mark.parametrize("n", [1, 3, 5])
def test_chain_of_instances_equals_the_shipped_chain(n):
    mine = mechdsl.loads(CHAIN, model="Chain").with_params(N=n)
    ref = mechdsl.load(SHIPPED).with_params(N=n)
    assert mine.coordinates == tuple(f"links[{i}].q" for i in range(1, n + 1))
    a, b = accelerations(mine.eom), accelerations(ref.eom)
    ea, eb = mine.eom, ref.eom
    ta, tb = evaluator(ea, ea.T, ea.V, ea.outputs["tip_x"]), evaluator(eb, eb.T, eb.V, eb.outputs["tip_x"])
    rng = np.random.default_rng(n)
    for _ in range(3):
        q, qd = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
        assert a(q, qd) == pytest.approx(b(q, qd), rel=1e-10, abs=1e-10)
        for x, y in zip(ta(q, qd), tb(q, qd)):
            assert x == pytest.approx(y, rel=1e-12, abs=1e-12)


def test_split_and_each_modifiers_and_element_overrides():
    text = CHAIN.replace("each m = 1, each L = 1", "m = {1, 2, 3}, each L = 0.5")
    m = mechdsl.loads(text, model="Chain")
    assert m.parameters["links[2].m"] == 2.0 and m.parameters["links[3].L"] == 0.5
    m2 = m.with_params(**{"links[2].q.start": 0.7, "links[3].m": 5.0})
    starts = {c.name: c.start.value for c in m2.model.coordinates}
    assert starts == pytest.approx({"links[1].q": np.pi / 2, "links[2].q": 0.7, "links[3].q": 0.0})
    assert m2.parameters["links[3].m"] == 5.0


def test_indexed_start_override_of_a_coordinate_array(tmp_path):
    ref = mechdsl.load(SHIPPED)
    m = ref.with_params(**{"q[2].start": 0.4, "q[3].speed": -1.0})
    got = [(c.start, c.speed) for c in m.model.coordinates]
    assert got[1][0].value == pytest.approx(0.4) and got[2][1].value == pytest.approx(-1.0)
    assert got[0][0].value == pytest.approx(np.pi / 2)
    with pytest.raises(MechError) as err:
        ref.with_params(**{"q[7].start": 1.0})
    assert "E204" in str(err.value)
    out = tmp_path / "r.csv"
    assert main(["simulate", str(SHIPPED), "--set", "q[2].start=0.4", "--t-end", "0.01", "--points", "2",
                 "-o", str(out), "--no-progress"]) == 0
    header, first = out.read_text().splitlines()[:2]
    cols = header.split(",")
    assert float(first.split(",")[cols.index("q[2]")]) == pytest.approx(0.4)


@pytest.mark.parametrize("change, code", [
    (("links[N](", "links[N, 2]("), "E301"),
    (("connect(world, links[1].j", "connect(world, links[4].j"), "E303"),
    (("links[N].rod.b.x", "links.rod.b.x"), "E303"),
])
def test_instance_array_errors(change, code):
    with pytest.raises(MechError) as err:
        mechdsl.loads(CHAIN.replace(*change), model="Chain")
    assert code in str(err.value)


def test_scenes_modify_elements_by_index():
    text = CHAIN + """
scene S
  model Chain(N = 4, links[2](m = 3), links[3].q(start = 0.5));
  stop_time = 0.1;
end S;
"""
    m = mechdsl.loads(text, scene="S")
    assert m.parameters["links[2].m"] == 3.0 and m.parameters["links[1].m"] == 1.0
    assert [c.start.value for c in m.model.coordinates] == pytest.approx([np.pi / 2, 0, 0.5, 0])
    shipped = SHIPPED.read_text() + "scene S\n  model NLinkPendulum(q[2](start = 0.4), q[3](speed = -1));\nend S;\n"
    got = [(c.start.value, c.speed.value) for c in mechdsl.loads(shipped, scene="S").model.coordinates]
    assert np.array(got) == pytest.approx(np.array([(np.pi / 2, 0), (0.4, 0), (0, -1)]))
    with pytest.raises(MechError) as err:
        mechdsl.loads(shipped.replace("q[2](", "q[2.5]("), scene="S")
    assert "E102" in str(err.value) and "positive integer" in str(err.value)
