"""Joint reactions by recursive Newton-Euler after the forward dynamics, against closed
forms; loop closures: residuals vanish on the joint's own motion and the multipliers are
the reaction components of the cut joint."""
from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mech_models import coord_var, joint_chain, mat, point, t_expr, v3, IA
from mechdsl.model import ir
from mechdsl.diagnostics import MechError
from mechdsl.model.exprs import const
from mechdsl.mechanics import derive
import mechdsl.examples


def pendulum(prescribed=None, inertia=None):
    """A bob hanging from the world pivot by a massless rod of length L (child point above it)."""
    m, L = 1.7, 1.3
    var = coord_var("phi", "phi") if prescribed is None else ir.JointVar("phi", prescribed)
    body = (ir.Body("bob", "point", mass=const(m)) if inertia is None else
            ir.Body("bob", "rigid", mass=const(m), inertia=mat(inertia)))
    outs = tuple(ir.Output(f"{w[0]}{i}", ir.ReactionRef("j", w, i)) for w in ("force", "torque") for i in range(3))
    return ir.Model("Pend", coordinates=() if prescribed is not None else (ir.Coordinate("phi"),), bodies=(body,),
                    points=(point("world", "world"), point("bob", "bob"), point("bob.pivot", "bob", (0, L, 0))),
                    joints=(ir.Joint("j", "revolute", "world", "bob.pivot", "world", "bob", axis=v3(0, 0, 1),
                                     variables=(var,)),),
                    forces=(ir.Gravity("g", v3(0, -9.81, 0)),), outputs=outs), m, L


def reactions(e, q, qd, t=0.0):
    f = ca.Function("r", [e.q, e.qd, e.t, e.p], [ca.vertcat(*[e.outputs[k] for k in
                                                            ("f0", "f1", "f2", "t0", "t1", "t2")])])
    return np.array(f(q, qd, t, e.param_values)).ravel()


@pytest.mark.parametrize("route", ["auto", "lagrange"])
def test_pendulum_rod_tension(route):
    model, m, L = pendulum()
    e = derive(model, route=route)
    for phi, w in [(0.0, 0.0), (0.7, 1.5), (2.8, -2.2)]:
        r = reactions(e, [phi], [w])
        # child joint frame = bob axes: +y points from the bob to the pivot
        assert r[1] == pytest.approx(m * 9.81 * np.cos(phi) + m * L * w ** 2, rel=1e-13)
        assert abs(r[0]) < 1e-12 and abs(r[2]) < 1e-12 and np.abs(r[3:]).max() < 1e-12


def test_driving_torque_of_a_prescribed_joint():
    # phi = t + 0.4 sin(2 t); rigid bob (inertia Izz = 0.3 about its centre): the joint torque
    # is (Izz + m L^2) phi'' + m g L sin(phi)
    model, m, L = pendulum(prescribed=t_expr(0.0, 1.0, 2.0, 0.4), inertia=((0.1, 0, 0), (0, 0.2, 0), (0, 0, 0.3)))
    e = derive(model)
    for t in (0.0, 0.7, 2.1):
        phi = t + 0.4 * np.sin(2 * t)
        phid = 1 + 0.8 * np.cos(2 * t)
        phidd = -1.6 * np.sin(2 * t)
        r = reactions(e, [], [], t)
        assert r[5] == pytest.approx((0.3 + m * L ** 2) * phidd + m * 9.81 * L * np.sin(phi), rel=1e-12, abs=1e-12)
        assert r[1] == pytest.approx(m * 9.81 * np.cos(phi) + m * L * phid ** 2, rel=1e-12)
        assert r[0] == pytest.approx(m * L * phidd + m * 9.81 * np.sin(phi), rel=1e-12, abs=1e-12)


def test_reaction_force_balance_of_a_fixed_body():
    # a body welded to the world carries its weight: force (0, m g, 0) in its frame (the
    # frame is the world's at zero), torque = r_com x (-m g) moved to the joint point
    body = ir.Body("B", "rigid", mass=const(2.0), com=v3(0.3, 0.0, 0.1), inertia=mat(IA))
    outs = tuple(ir.Output(f"{w[0]}{i}", ir.ReactionRef("weld", w, i)) for w in ("force", "torque") for i in range(3))
    model = ir.Model("Weld", bodies=(body,), points=(point("world", "world"), point("B", "B")),
                     joints=(ir.Joint("weld", "fixed", "world", "B", "world", "B"),),
                     forces=(ir.Gravity("g", v3(0, -9.81, 0)),), outputs=outs)
    e = derive(model)
    f = ca.Function("r", [e.t, e.p], [ca.vertcat(*[e.outputs[k] for k in ("f0", "f1", "f2", "t0", "t1", "t2")])])
    r = np.array(f(0.0, e.param_values)).ravel()
    assert np.allclose(r[:3], [0, 2 * 9.81, 0], atol=1e-13)
    assert np.allclose(r[3:], -np.cross([0.3, 0.0, 0.1], [0, -2 * 9.81, 0]), atol=1e-13)


# --------------------------------------------------------------------------- loop closures

KINDS = ["revolute", "prismatic", "cylindrical", "planar", "spherical", "fixed"]
EXPECTED_NAMES = {
    "revolute": ["fx", "fy", "fz", "t1", "t2"], "prismatic": ["f1", "f2", "tx", "ty", "tz"],
    "cylindrical": ["f1", "f2", "t1", "t2"], "planar": ["f3", "t1", "t2"], "spherical": ["fx", "fy", "fz"],
    "fixed": ["fx", "fy", "fz", "tx", "ty", "tz"]}


def cut_model(kind):
    """Body A on a free joint (x, y, z, Euler zyx) from the world anchor, and a cut joint of
    `kind` between the same points."""
    tree = joint_chain("free", second=False, spring=False)
    cut = ir.Joint("cut", kind, "anchor", "A.p", "world", "A", axis=v3(0.48, 0.6, 0.64), closes_loop=True)
    return ir.Model("Cut", coordinates=tree.coordinates, bodies=tree.bodies, points=tree.points,
                    joints=tree.joints + (cut,), forces=tree.forces, loops=(ir.Loop("L1", "cut", ("A",)),),
                    outputs=(ir.Output("R", ir.BodyRot("A", 0, 0)),))


@pytest.mark.parametrize("kind", KINDS)
def test_loop_closure_vanishes_on_the_joint_motion(kind):
    e = derive(cut_model(kind))
    assert list(e.constraint_names) == [f"cut.{n}" for n in EXPECTED_NAMES[kind]]
    # place A by the joint's own motion: a tree model with that joint, random variables
    tree = joint_chain(kind, second=False, spring=False)
    tree = dataclasses.replace(tree, outputs=tuple(ir.Output(f"R{i}{j}", ir.BodyRot("A", i, j))
                                                   for j in range(3) for i in range(3)))
    et = derive(tree)
    rot = ca.vertcat(*[et.outputs[f"R{i}{j}"] for j in range(3) for i in range(3)])
    pose = ca.Function("pose", [et.q], [rot, et.point_position("A.p") - et.point_position("anchor")])
    g = ca.Function("g", [e.q], [e.g, ca.jacobian(e.g, e.q)])
    rng = np.random.default_rng(7)
    for _ in range(3):
        qt = rng.uniform(-1, 1, et.n)
        Rv, p = (np.array(x) for x in pose(qt))
        R = Rv.reshape(3, 3, order="F")
        phi, theta, psi = Rotation.from_matrix(R).as_euler("ZYX")
        q = np.concatenate([p.ravel(), [phi, theta, psi]])
        res, G = (np.array(x) for x in g(q))
        assert np.abs(res).max() < 1e-13
        assert np.linalg.matrix_rank(G) == len(e.constraint_names)
        # moving off the joint's motion violates it
        res2, _ = (np.array(x) for x in g(q + rng.normal(scale=1e-3, size=6)))
        assert np.abs(res2).max() > 1e-6


def test_multipliers_are_the_reactions():
    """A rod pendulum as a free body closed by a cut revolute: the multipliers equal the
    reaction force/torque of the same pendulum as a tree, in the parent (world) frame."""
    rod = ir.Body("A", "rigid", mass=const(1.3), com=v3(0.05, -0.4, 0.02), inertia=mat(IA))
    pts = (point("world", "world"), point("anchor", "world", (0.1, 0.2, -0.3)), point("A", "A"),
           point("A.p", "A", (0.0, 0.1, 0.0)))
    grav = (ir.Gravity("g", v3(0, -9.81, 0)),)
    roles = ("x", "y", "z", "phi", "theta", "psi")
    outs = tuple(ir.Output(f"{w[0]}{i}", ir.ReactionRef("j", w, i)) for w in ("force", "torque") for i in range(3))
    cut_outs = tuple(ir.Output(f"{j}.{w[0]}{i}", ir.ReactionRef(j, w, i))
                     for j in ("cut", "f") for w in ("force", "torque") for i in range(3))
    free = ir.Model("Free", coordinates=tuple(ir.Coordinate(f"f.{r}") for r in roles), bodies=(rod,), points=pts,
                    joints=(ir.Joint("f", "free", "anchor", "A.p", "world", "A",
                                     variables=tuple(coord_var(r, f"f.{r}") for r in roles)),
                            ir.Joint("cut", "revolute", "anchor", "A.p", "world", "A", axis=v3(0, 0, 1), closes_loop=True)),
                    forces=grav, loops=(ir.Loop("L", "cut", ("A",)),), outputs=cut_outs)
    tree = ir.Model("Tree", coordinates=(ir.Coordinate("phi"),), bodies=(rod,), points=pts,
                    joints=(ir.Joint("j", "revolute", "anchor", "A.p", "world", "A", axis=v3(0, 0, 1),
                                     variables=(coord_var("phi", "phi"),)),),
                    forces=grav, outputs=outs + tuple(ir.Output(f"R{i}{j}", ir.BodyRot("A", i, j))
                                                       for i in range(3) for j in range(3)))
    ef, et = derive(free), derive(tree)
    G = ca.jacobian(ef.g, ef.q)
    gamma = ca.jtimes(ca.mtimes(G, ef.qd), ef.q, ef.qd)
    dae = ca.Function("dae", [ef.q, ef.qd, ef.p], [ef.M, ef.bias, G, gamma])
    out = ca.Function("o", [et.q, et.qd, et.p], [ca.vertcat(*[et.outputs[k] for k in
                                                            ("f0", "f1", "f2", "t0", "t1", "t2")]),
                                               ca.vertcat(*[et.outputs[f"R{i}{j}"] for i in range(3) for j in range(3)])])
    for phi, w in [(0.4, 1.2), (-1.9, 0.3)]:
        q = np.array([0, 0, 0, phi, 0, 0.0])
        qd = np.array([0, 0, 0, w, 0, 0.0])
        M, b, Gm, gm = (np.array(x) for x in dae(q, qd, ef.param_values))
        m = Gm.shape[0]
        K = np.block([[M, Gm.T], [Gm, np.zeros((m, m))]])
        sol = np.linalg.solve(K, np.concatenate([b.ravel(), -gm.ravel()]))
        lam = dict(zip(ef.constraint_names, sol[6:]))
        r, Rv = (np.array(x).ravel() for x in out([phi], [w], et.param_values))
        R = Rv.reshape(3, 3)
        F, Tq = R @ r[:3], R @ r[3:]          # child frame -> world (= parent joint frame)
        assert [lam["cut.fx"], lam["cut.fy"], lam["cut.fz"]] == pytest.approx(list(F), abs=1e-10)
        assert [lam["cut.tx"], lam["cut.ty"]] == pytest.approx(list(Tq[:2]), abs=1e-10)
        assert abs(Tq[2]) < 1e-12
        # reaction outputs of the constrained model are SX in EOM.lam: the cut joint's in its
        # child frame equals the tree's; the free joint carries nothing
        ro = ca.Function("ro", [ef.q, ef.qd, ef.p, ef.lam], [ca.vertcat(*ef.outputs.values())])
        v = np.array(ro(q, qd, ef.param_values, sol[6:])).ravel()
        assert np.allclose(v[:6], r, atol=1e-10)
        assert np.abs(v[6:]).max() < 1e-10


def test_reaction_in_model_with_explicit_constraint_is_a_diagnostic():
    model, _, _ = pendulum()
    model = dataclasses.replace(model, constraints=(ir.Constraint("c", ir.Op("sub", (ir.Coord("phi"), const(0.1)))),))
    with pytest.raises(MechError) as ex:
        derive(model)
    assert ex.value.first.code == "E751"


def test_four_bar_reaction_output_uses_multipliers():
    e = load_model("four_bar").eom
    assert e.lam is not None and e.lam.numel() == len(e.constraint_names) == 5
    assert list(e.constraint_names) == ["close.fx", "close.fy", "close.fz", "close.tx", "close.ty"]
    F = ca.vertcat(*[e.outputs[k] for k in e.outputs if k.startswith("F_close")])
    assert ca.depends_on(F, e.lam)


def load_model(name):
    import os

    import mechdsl

    path = str(mechdsl.examples.path(name))
    return mechdsl.load(path)
