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
from mechdsl.diagnostics import MechError, UsageError
from reach_util import accelerations, evaluator
import mechdsl.examples

SHIPPED = mechdsl.examples.path("nlink_pendulum")

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


NESTED = """
model Sub
  parameter Real m(unit = "kg") = 1;
  coordinate Real q(start = 0, unit = "rad");
  Rod rod(m = m, L = 1, axis = {0, -1, 0});
  Revolute j(axis = {0, 0, 1}, phi = q);
end Sub;

model Pair "two links, an array inside a part"
  Sub subs[2];
equation
  connect(subs[1].rod.b, subs[2].j, subs[2].rod.a);
end Pair;

model Chain4 "a chain of 4 as 2 pairs: elements of an array inside an element"
  Gravity gravity(g = {0, -9.81, 0});
  Pair pairs[2];
  output Real tip_x(unit = "m") = pairs[2].subs[2].rod.b.x;
equation
  connect(world, pairs[1].subs[1].j, pairs[1].subs[1].rod.a);
  connect(pairs[1].subs[2].rod.b, pairs[2].subs[1].j, pairs[2].subs[1].rod.a);
end Chain4;
"""


def test_an_element_of_an_array_inside_an_element():
    """`pairs[2].subs[1].j` names element 1 of the array `subs` of element 2 of `pairs` (was
    E201 "has no declaration 'subs'"); the chain of 2 x 2 has the shipped chain's equations."""
    mine = mechdsl.loads(NESTED, model="Chain4")
    ref = mechdsl.load(SHIPPED).with_params(N=4)
    assert mine.coordinates == ("pairs[1].subs[1].q", "pairs[1].subs[2].q", "pairs[2].subs[1].q", "pairs[2].subs[2].q")
    a, b = accelerations(mine.eom), accelerations(ref.eom)
    ta = evaluator(mine.eom, mine.eom.outputs["tip_x"])
    tb = evaluator(ref.eom, ref.eom.outputs["tip_x"])
    rng = np.random.default_rng(4)
    for _ in range(3):
        q, qd = rng.uniform(-np.pi, np.pi, 4), rng.uniform(-2, 2, 4)
        assert a(q, qd) == pytest.approx(b(q, qd), rel=1e-10, abs=1e-10)
        assert ta(q, qd)[0] == pytest.approx(tb(q, qd)[0], rel=1e-12, abs=1e-12)
    assert mine.with_params(**{"pairs[2].subs[1].m": 3.0}).parameters["pairs[2].subs[1].m"] == 3.0
    with pytest.raises(MechError) as err:
        mechdsl.loads(NESTED.replace("pairs[2].subs[2].rod.b.x", "pairs[2].subs[3].rod.b.x"), model="Chain4")
    assert "index 3 is out of range for 'pairs[2].subs' (1..2)" in str(err.value)


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
    (("parameter Integer N = 3;", "parameter Integer N = -1;"), "E307"),   # was accepted: no instances
])
def test_instance_array_errors(change, code):
    with pytest.raises(MechError) as err:
        mechdsl.loads(CHAIN.replace(*change), model="Chain")
    assert code in str(err.value)


@pytest.mark.parametrize("mods, n, what", [
    ("m = {1, 2, 3}, each L = 1", 4, "'m' of the array 'links' has 3 entries for 4 elements"),
    ("m = {1, 2, 3}, each L = 1", 5, "'m' of the array 'links' has 3 entries for 5 elements"),
    ("each m = 1, each L = 1, q(start = {1, 0})", 3, "'start' of the array 'links' has 2 entries for 3 elements"),
], ids=["m-4", "m-5", "start-3"])
def test_a_literal_array_of_the_wrong_length_is_one_clear_error(mods, n, what):
    """A literal array modifier whose length is not the instance array's size (say after
    `--set N=...`) is not split: one E301 that says so, not one shape error per element."""
    text = CHAIN.replace("each m = 1, each L = 1, q(start = {if i == 1 then pi/2 else 0 for i in 1:N})", mods)
    with pytest.raises(MechError) as err:
        mechdsl.loads(text.replace("parameter Integer N = 3", f"parameter Integer N = {n}"), model="Chain")
    assert [d.code for d in err.value.diagnostics] == ["E301"]
    assert err.value.first.message == what and "each" in err.value.first.help


def test_a_structural_parameter_that_is_not_a_number_is_named():
    with pytest.raises(UsageError, match="value of 'N' must be a number, got 'a'"):    # said 'value'
        mechdsl.loads(CHAIN, model="Chain").with_params(N="a")


@pytest.mark.parametrize("mod, message", [
    ("links[7](m = 3)", "'links' of model 'Chain' is an array of 3 model instances; links[7] is not one"),
    ("links(m = 3)", "'links' of model 'Chain' is an array of 3 model instances"),
])
def test_a_scene_modifying_the_array_or_a_missing_element_says_so(mod, message):
    """(was "no declaration 'links[7]'" with the hint "did you mean 'links[3].q'")"""
    text = CHAIN + f"\nscene S\n  model Chain({mod});\nend S;\n"
    with pytest.raises(MechError) as err:
        mechdsl.loads(text, scene="S")
    assert err.value.first.code == "E204" and err.value.first.message == message
    assert "links[i](...) with i in 1..3" in err.value.first.help


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
