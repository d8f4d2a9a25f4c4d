"""The ABA as loops over per-link kernels (mechanics/chain.py, issue 16): the looped ode equals
the unrolled one to round-off at random states, for chains of identical links, chains with odd
links, per-link parameter values, joint forces, forces reaching other links, quaternion ball
joints and branched trees; its C does not grow with N; compiled big chains use it."""
from __future__ import annotations

import re

import casadi as ca
import numpy as np
import pytest

from mech_models import P, Z, coord_var, const, neg, nlink, rod_body, v3
from mechdsl import eom as eom_mod
from mechdsl.model import ir
from mechdsl.eom.codegen import build_ode, casadi_functions, jacobian_of, looped_ode
from mechdsl.mechanics import derive
from conftest import needs_cc


def rod_tree(links, *, name="tree", spring_to=None, damping=None, inputs=()):
    """Rods hanging from each other: links = [(name, parent link or 'world', options)];
    inputs: input names, the first a generalized force on every revolute joint.

    options: m (parameter name of its mass, default 'm'), L (IR length, default P('l')),
    axis (joint axis, default z), kind ('revolute' | 'ball': a quaternion spherical joint)."""
    params = {"m": 1.0, "l": 1.0, "g": 9.81, "c": 0.3, "k": 15.0}
    bodies, points, joints, coords, forces = [], [ir.Point("world", "world")], [], [], []
    for nm, parent, o in links:
        mname = o.get("m", "m")
        params.setdefault(mname, 1.0 + 0.1 * len(params))
        b, pts = rod_body(nm, P(mname), o.get("L", P("l")))
        if o.get("kind") == "ball":      # a rod turning about its own axis too: a thick rod
            I = ir.Op("mul", (P(mname), const(0.02)))
            b = ir.Body(nm, "rigid", mass=b.mass, com=b.com, inertia=((b.inertia[0][0], Z, Z), (Z, I, Z),
                                                                      (Z, Z, b.inertia[2][2])))
        bodies.append(b)
        points += pts
        pp, pb = ("world", "world") if parent == "world" else (f"{parent}.b", parent)
        if o.get("kind") == "ball":
            vs = tuple(coord_var(r, f"{nm}.{r}") for r in ("q0", "q1", "q2", "q3"))
            joints.append(ir.Joint(f"j_{nm}", "spherical", pp, f"{nm}.a", pb, nm, variables=vs,
                                   options=(("parametrization", "quaternion"),)))
            starts = (0.9, 0.3, -0.2, 0.25)
            coords += [ir.Coordinate(f"{nm}.{r}", start=const(s)) for r, s in zip(("q0", "q1", "q2", "q3"), starts)]
        else:
            joints.append(ir.Joint(f"j_{nm}", "revolute", pp, f"{nm}.a", pb, nm, axis=v3(*o.get("axis", (0, 0, 1))),
                                   variables=(coord_var("phi", f"{nm}.phi"),)))
            coords.append(ir.Coordinate(f"{nm}.phi", start=const(0.2)))
            if damping:
                forces.append(ir.GeneralizedForce(f"d_{nm}", f"{nm}.phi",
                                                  ir.Op("mul", (neg(P(damping)), ir.Speed(f"{nm}.phi")))))
    forces.append(ir.Gravity("gravity", (Z, neg(P("g")), Z)))
    if spring_to:
        points.append(ir.Point("anchor", "world", v3(0.5, 0.3, 0.0)))
        forces.append(ir.SpringDamper("spr", "spring", "anchor", f"{spring_to}.b", k=P("k"), c=const(0.0),
                                      l0=const(0.0)))
    for nm, _, _ in links if inputs else ():
        forces.append(ir.GeneralizedForce(f"u_{nm}", f"{nm}.phi", P(inputs[0])))
    parameters = tuple(ir.Parameter(k, v) for k, v in params.items()) + tuple(
        ir.Parameter(u, 0.5, input=True) for u in inputs)
    return ir.Model(name, parameters=parameters, coordinates=tuple(coords), bodies=tuple(bodies),
                    points=tuple(points), joints=tuple(joints), forces=tuple(forces))


def chain(N, prefix="r", parent="world", **opts):
    out = []
    for i in range(1, N + 1):
        o = {k: (v(i) if callable(v) else v) for k, v in opts.items()}
        out.append((f"{prefix}{i}", parent if i == 1 else f"{prefix}{i - 1}", o))
    return out


def agree(e, states=5, seed=0, tol=1e-12):
    """The looped ode against the unrolled one at random states; returns the plan's segment lengths."""
    assert e.route == "aba"
    plan = e.qdd_loop
    assert plan is not None
    f_loop = plan.ode(e)
    f_unrolled = build_ode(e)
    assert f_loop.is_a("MXFunction") and f_unrolled.is_a("SXFunction")
    rng = np.random.default_rng(seed)
    pv = np.asarray(e.param_values, float) * rng.uniform(0.8, 1.2, len(e.param_values))
    uv = rng.uniform(-1, 1, e.u_sym.numel())
    for _ in range(states):
        x = np.r_[rng.uniform(-2, 2, e.n), rng.uniform(-2, 2, e.n)]
        a = np.array(f_loop(0.7, x, uv, pv)).ravel()
        b = np.array(f_unrolled(0.7, x, uv, pv)).ravel()
        assert np.all(np.isfinite(b))
        assert np.max(np.abs(a - b)) <= tol * max(1.0, np.max(np.abs(b))), np.max(np.abs(a - b))
    return [len(s.links) for s in plan.segments]


def test_identical_links_loop_and_agree():
    e = derive(nlink(12))
    # the first link hangs from the world origin (its offset is 0, the others' is -l): its own segment
    assert agree(e) == [1, 11]


def test_per_link_parameter_values_are_data():
    e = derive(rod_tree(chain(10, m=lambda i: f"m{i}")))
    assert agree(e) == [1, 9]
    seg = e.qdd_loop.segments[1]
    masses = {str(col[j]) for col in seg.data for j in range(len(col))} & {f"p_{k}" for k in range(20)}
    assert len(masses) >= 9          # each link reads its own mass


def test_one_odd_link_splits_the_run():
    # link 6 is shorter (a constant length instead of l): it and the link hanging from it differ
    e = derive(rod_tree(chain(12, L=lambda i: const(0.5) if i == 6 else P("l"))))
    assert agree(e) == [1, 4, 1, 1, 5]
    segs = e.qdd_loop.segments
    assert segs[1].k2 is segs[4].k2 and segs[1].k3 is segs[4].k3     # one kernel (one C function) for both runs


def test_odd_axis_in_the_middle():
    e = derive(rod_tree(chain(11, axis=lambda i: (1, 0, 0) if i == 5 else (0, 0, 1))))
    segs = agree(e)
    assert sum(segs) == 11 and max(segs) >= 4 and len(segs) >= 3


def test_branched_tree():
    links = chain(7, "a") + chain(6, "b", parent="a3") + chain(5, "c", parent="a3")
    e = derive(rod_tree(links))
    segs = agree(e)
    assert sum(segs) == 18 and max(segs) >= 4


def test_joint_forces_and_a_force_reaching_other_links():
    # damping -c qd on every joint (tau per link), and a spring from a world anchor to the tip,
    # whose force depends on every coordinate: the tip becomes its own segment, still exact
    e = derive(rod_tree(chain(9, axis=(0.3, 0.5, 0.8)), damping="c", spring_to="r9"))
    segs = agree(e)
    assert segs[-1] == 1 and max(segs) >= 4


def test_quaternion_ball_chain():
    # three speeds per link and q'' from nu' through the quaternion map (not the identity)
    e = derive(rod_tree(chain(6, kind="ball")))
    assert e.qdd_loop.post is not None
    assert agree(e, tol=1e-11) == [1, 5]


def test_inputs_and_folded_inputs():
    e = derive(rod_tree(chain(8), inputs=("F",)))          # an input torque on every joint
    assert e.inputs == ("F",)
    assert agree(e) == [1, 7]
    folded = eom_mod.fold_inputs(e)                # p' = [p; u]: the plan maps the symbols anew
    assert agree(folded) == [1, 7]


def test_no_plan_without_a_run_or_for_a_changed_qdd():
    assert derive(nlink(3)).qdd_loop is None                 # too short to loop
    bushy = chain(4) + [lk for b in range(6) for lk in chain(2, f"b{b}x", parent="r2")]
    assert derive(rod_tree(bushy)).qdd_loop is None          # a run of 4 among 16 links: not worth it
    assert derive(rod_tree(chain(8, axis=lambda i: (0, 0, 1) if i % 2 else (1, 0, 0)))).qdd_loop is None
    e = derive(nlink(8))
    assert e.qdd_loop is not None
    assert e.qdd_loop.ode(e.replace(qdd=2 * e.qdd)) is None  # not the qdd it was made for
    assert derive(nlink(8), route="crba").qdd_loop is None


def _code_size(f):
    """Bytes of generated C without its static tables (index lists whose length is data)."""
    cg = ca.CodeGenerator("x.c", {"with_header": False, "verbose": False})
    cg.add(f)
    return len(re.sub(r"static const casadi_(int|real) [^;]*;", "", cg.dump(), flags=re.S))


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_c_code_grows_with_log_n():
    # CasADi nests mapaccum in base 8 (over groups of 8 links): 4x the links add at most one level
    small, big = derive(nlink(30)), derive(nlink(120))
    loop_small, loop_big = _code_size(small.qdd_loop.ode(small)), _code_size(big.qdd_loop.ode(big))
    unrolled_small, unrolled_big = _code_size(build_ode(small)), _code_size(build_ode(big))
    assert unrolled_big >= 3.5 * unrolled_small
    assert loop_big <= 1.6 * loop_small
    assert loop_big <= 0.3 * unrolled_big


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_looped_only_where_it_pays():
    small = derive(nlink(12))
    assert looped_ode(small) is None        # small: the unrolled C is faster and compiles fast
    assert not small.__dict__["qdd_loop"].done            # ... and its plan is not even built
    big = derive(nlink(80))
    assert looped_ode(big) is not None
    assert build_ode(big, loop=True).is_a("MXFunction")
    assert build_ode(big, sx=True, loop=True).is_a("SXFunction")   # sx=True keeps an SX Function


@pytest.mark.slow
@needs_cc
def test_compiled_chain_uses_the_loops(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    e = derive(nlink(80))
    fs = casadi_functions(e, compiled=True, names=("ode", "ode_jacobian"))
    f = fs["ode"]
    assert fs.compiled and fs.looped
    assert any("per-link kernels" in n for n in fs.notes)
    assert any("forward derivative" in n for n in fs.notes)
    vm = build_ode(e)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.uniform(-2, 2, 2 * e.n)
        a, b = np.array(f(0, x, [], e.param_values)).ravel(), np.array(vm(0, x, [], e.param_values)).ravel()
        assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, np.max(np.abs(b)))
    J = np.array(fs["ode_jacobian"](0, x, [], e.param_values))
    Jv = np.array(jacobian_of(vm)(0, x, [], e.param_values))
    assert np.max(np.abs(J - Jv)) <= 1e-10 * max(1.0, np.max(np.abs(Jv)))
