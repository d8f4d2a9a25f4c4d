"""Models that cannot be derived give coded diagnostics (MechError, E7xx), never tracebacks."""
from __future__ import annotations

import dataclasses

import pytest

from mech_models import coord_var, joint_chain, point, v3
from mechdsl.model import ir
from mechdsl.diagnostics import MechError
from mechdsl.model.exprs import const
from mechdsl.mechanics import derive


def code_of(model):
    with pytest.raises(MechError) as ex:
        derive(model)
    return ex.value.first.code


def replace_joint(model, name, **changes):
    joints = tuple(dataclasses.replace(j, **changes) if j.name == name else j for j in model.joints)
    return dataclasses.replace(model, joints=joints)


def test_joint_errors():
    m = joint_chain("revolute")
    assert code_of(replace_joint(m, "jA", kind="hinge")) == "E700"
    assert code_of(replace_joint(m, "jA", kind="cylindrical")) == "E701"            # lacks 's'
    s = joint_chain("spherical")
    assert code_of(replace_joint(s, "jA", options=(("sequence", "zzx"),))) == "E704"
    assert code_of(replace_joint(s, "jA", options=(("parametrization", "rodrigues"),))) == "E703"
    assert code_of(replace_joint(m, "jA", axis=v3(0, 0, 0))) == "E706"
    assert code_of(replace_joint(m, "jA", child="B.c")) == "E712"


def test_topology_errors():
    m = joint_chain("revolute")
    lonely = dataclasses.replace(m, bodies=m.bodies + (ir.Body("C", "rigid", mass=const(1.0)),),
                                 points=m.points + (point("C", "C"),))
    assert code_of(lonely) == "E711"
    twice = dataclasses.replace(m, joints=m.joints + (dataclasses.replace(m.joints[1], name="jB2"),))
    assert code_of(twice) == "E709"


def test_moving_frame_depending_on_state_and_speed_dependent_variable():
    m = joint_chain("revolute")
    bad = replace_joint(m, "jA", variables=(ir.JointVar("phi", ir.Speed("jB.phi")),))
    assert code_of(bad) == "E708"
    frame = ((ir.ONE, ir.ZERO, ir.ZERO), (ir.ZERO, ir.ONE, ir.ZERO), (ir.ZERO, ir.ZERO, ir.ONE))
    f = joint_chain("revolute", frame=(frame, (ir.Coord("jB.phi"), ir.ZERO, ir.ZERO)))
    assert code_of(f) == "E705"


def test_singular_models():
    # a free joint variable that moves nothing
    massless = ir.Model("M", coordinates=(ir.Coordinate("a"),), bodies=(ir.Body("F", "frame"),),
                        points=(point("world", "world"), point("F", "F")),
                        joints=(ir.Joint("j", "revolute", "world", "F", "world", "F",
                                         variables=(coord_var("phi", "a"),)),))
    assert code_of(massless) == "E730"
    # a coordinate that drives nothing and has no kinetic energy
    m = joint_chain("revolute", second=False)
    extra = dataclasses.replace(m, coordinates=m.coordinates + (ir.Coordinate("loose"),))
    assert code_of(extra) == "E731"


def test_unknown_names_in_outputs_and_forces():
    m = joint_chain("revolute")
    assert code_of(dataclasses.replace(m, outputs=(ir.Output("x", ir.PointPos("nowhere", 0)),))) == "E707"
    assert code_of(dataclasses.replace(m, outputs=(ir.Output("R", ir.BodyRot("ghost", 0, 0)),))) == "E715"
    assert code_of(dataclasses.replace(m, forces=(ir.GeneralizedForce("Q", "nope", const(1.0)),))) == "E720"
    assert code_of(dataclasses.replace(m, outputs=(ir.Output("r", ir.ReactionRef("nojoint", "force", 0)),))) == "E752"
    t = dataclasses.replace(m, terms=(ir.Term("potential", ir.EnergyRef("kinetic")),))
    assert code_of(t) == "E723"
