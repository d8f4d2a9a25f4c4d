"""E508/E509: physically impossible mass properties are model errors, also when parameters change."""
from __future__ import annotations

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import MechError

from conftest import MODELS

SHAPES = """
model S
  parameter Real a = 1;
  parameter Real b = 1;
  parameter Real c = 1;
  coordinate Real q(start = 0);
  Box box(m = 2, size = {a, b, c});
  Cylinder cyl(m = 3, R = a, L = b);
  Disk disk(m = 1, R = c);
  Rod rod(m = 1, L = a);
  Revolute j1(parent = world, child = box, axis = {0, 0, 1}, phi = q);
  Fixed f1(parent = box, child = cyl);
  Fixed f2(parent = box, child = disk);
  Fixed f3(parent = box, child = rod.a);
end S;
"""


def test_with_params_negative_mass_is_a_model_error():
    m = mechdsl.load(MODELS / "pendulum.mech", model="Pendulum")
    with pytest.raises(MechError) as e:
        m.with_params(m=-1.0)
    assert [d.code for d in e.value.diagnostics] == ["E508"]
    assert "bob" in e.value.diagnostics[0].message
    m.with_params(m=2.0)  # a positive mass is fine


def test_cli_set_negative_mass_exit_1(tmp_path, capsys):
    rc = main(["simulate", str(MODELS / "pendulum.mech"), "--model", "Pendulum", "--set", "m=-1",
               "--t-end", "0.1", "-o", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    assert rc == 1 and "error[E508]" in err and "Traceback" not in err
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("seed", range(5))
def test_shape_helpers_give_realizable_inertia(seed):
    """The shape formulas (box, cylinder, disk, rod) pass the triangle inequality at any size: an
    independent property of real mass distributions, checked on random, very unequal sizes."""
    rng = np.random.default_rng(seed)
    a, b, c = 10.0 ** rng.uniform(-3, 3, size=3)
    mechdsl.loads(SHAPES).with_params(a=a, b=b, c=c)  # raises E509 if a formula were wrong


def test_thin_disk_is_on_the_boundary_not_rejected():
    """A thin disk has I3 = I1 + I2 exactly: the boundary of the triangle inequality is allowed."""
    text = SHAPES.replace("parameter Real c = 1;", "parameter Real c = 1e-9;")
    mechdsl.loads(text)
