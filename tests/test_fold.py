"""Issue 24 item 7: the default ``casadi()["ode"]`` (parameters as the input p) with the
parameters' arithmetic folded into a few combinations (mechdsl.eom.fold).  The folded ode must
give the same accelerations and the same derivatives with respect to every input, p included
(an optimizer that estimates parameters differentiates with respect to p), as an independent
derivation and as the unfolded ode the simulator integrates."""
import casadi as ca
import numpy as np
import pytest

import mechdsl
from conftest import MODELS
from mechdsl.eom.codegen import build_ode
from mechdsl.eom.fold import fold_parameters


def hand_cart_pole():
    """Lagrange's equations of the cart-pole written out by hand, the parameters (M, m, l, g)
    symbolic: (x, F, p) -> xdot."""
    x, F, p = ca.SX.sym("x", 4), ca.SX.sym("F"), ca.SX.sym("p", 4)
    M, m, l, g = p[0], p[1], p[2], p[3]
    c, s = ca.cos(x[1]), ca.sin(x[1])
    A = ca.blockcat([[M + m, -m * l / 2 * c], [-m * l / 2 * c, m * l ** 2 / 3]])
    b = ca.vertcat(F - m * l / 2 * s * x[3] ** 2, m * g * l / 2 * s)
    return ca.Function("hand", [x, F, p], [ca.vertcat(x[2], x[3], ca.solve(A, b))])


def _jacobians(f, args):
    """Values and Jacobians with respect to every input of ``f`` at the numbers ``args``."""
    syms = [ca.SX.sym(f"a{i}", f.sparsity_in(i)) for i in range(f.n_in())]
    out = f(*syms)
    J = ca.Function("J", syms, [out] + [ca.jacobian(out, s) for s in syms])
    return [np.array(v, float) for v in J(*args)]


def test_cart_pole_default_ode_and_its_derivatives_match_the_hand_derivation():
    """At random states and random parameter values (not only the model's): xdot and its
    Jacobians with respect to x, u and p against the hand-written model's, differentiated by
    CasADi independently of mechdsl's expression."""
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    assert m.eom.params == ("M", "m", "l", "g")
    ode, hand = m.casadi()["ode"], hand_cart_pole()
    rng = np.random.default_rng(24)
    for _ in range(20):
        x, F, p = rng.uniform(-3, 3, 4), rng.uniform(-20, 20), rng.uniform(0.3, 3.0, 4) * [1, 1, 1, 10]
        got = _jacobians(ode, [0.0, x, F, p])          # xdot, d/dt, d/dx, d/du, d/dp
        want = _jacobians(hand, [x, F, p])             # xdot, d/dx, d/dF, d/dp
        for a, b in zip([got[0], got[2], got[3], got[4]], want):
            np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11 * np.abs(b).max(initial=1.0))


def test_cart_pole_default_ode_is_leaner():
    """The folded ode has fewer virtual-machine instructions than before the fold (43), and its
    reverse derivative (what IPOPT's exact Hessian differentiates again) too (116)."""
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    ode = m.casadi()["ode"]
    assert ode.n_instructions() <= 39
    assert ode.reverse(1).n_instructions() <= 101


@pytest.mark.parametrize("name", ["pendulum.mech", "bead_on_hoop.mech", "double_pendulum.mech", "heavy_top.mech"])
def test_folded_ode_equals_the_simulators_ode(name):
    """casadi()["ode"] (folded) against the ode the simulator integrates (build_ode without
    sx: never folded), values and Jacobians, at random states and parameters near the
    model's."""
    m = mechdsl.load(str(MODELS / name))
    folded, plain = m.casadi()["ode"], build_ode(m.eom)
    rng = np.random.default_rng(7)
    pv = np.asarray(m.parameter_vector(), float)
    for _ in range(10):
        args = [rng.uniform(0, 1), rng.uniform(-1, 1, folded.nnz_in(1)), rng.uniform(-1, 1, folded.nnz_in(2)),
                pv * rng.uniform(0.7, 1.4, pv.size)]
        for a, b in zip(_jacobians(folded, args), _jacobians(plain, args)):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10 * np.abs(b).max(initial=1.0))


def test_constrained_models_ode_is_folded_and_equal():
    """four_bar.mech: the index-1 ode casadi() returns is folded (fewer instructions than the
    unfolded Function of the same constrained system) and equal to it."""
    m = mechdsl.load(str(MODELS / "four_bar.mech"))
    folded = m.casadi()["ode"]
    fs = m.casadi()
    fs.sx = False                                      # the same set's ode, unfolded
    plain = fs._build_own("ode")
    assert folded.n_instructions() < plain.n_instructions()
    rng = np.random.default_rng(3)
    r = m.simulate(0.01, points=2)
    x0 = np.r_[r.q[0], r.qd[0]]
    pv = np.asarray(m.parameter_vector(), float)
    for _ in range(5):
        args = [0.0, x0 + rng.uniform(-1e-3, 1e-3, x0.size), np.zeros(folded.nnz_in(2)), pv]
        a, b = np.array(folded(*args), float), np.array(plain(*args), float)
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10 * np.abs(b).max(initial=1.0))


def _ode(expr, t, x, u, p):
    return ca.Function("ode", [t, x, u, p], [expr], ["t", "x", "u", "p"], ["xdot"])


def test_fold_gathers_parameter_factors_and_keeps_derivatives():
    t, x, u, p = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 3)
    k = (ca.cos(x[0]) * (p[0] * (p[1] / 2))) / (p[0] + p[1])
    e = ca.vertcat(x[1], (k * x[1] - (p[2] * (ca.sin(x[0]) * p[0])) * (p[1] / 2)) / (p[0] * p[1] ** 2 / 12
                                                                                     + p[0] * (p[1] / 2) ** 2) + u)
    f = _ode(e, t, x, u, p)
    g = fold_parameters(f)
    assert g is not f and g.n_instructions() < f.n_instructions()
    rng = np.random.default_rng(11)
    for _ in range(10):
        args = [0.0, rng.uniform(-2, 2, 2), rng.uniform(-1, 1), rng.uniform(0.5, 2, 3)]
        for a, b in zip(_jacobians(g, args), _jacobians(f, args)):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(initial=1.0))


def test_fold_handles_any_operation_and_keeps_what_is_not_leaner():
    """A parameter inside a function (sin, a comparison) is carried through unchanged; an ode
    without parameters, or one the fold cannot shorten, is returned as it is."""
    t, x, u, p = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("p", 2)
    e = ca.vertcat(x[1], ca.sin(p[0] * x[0]) * (p[1] * 3) * x[1] + ca.if_else(x[0] > p[1], p[0], 0) * x[0])
    f = _ode(e, t, x, u, p)
    g = fold_parameters(f)
    rng = np.random.default_rng(2)
    for _ in range(10):
        args = [0.0, rng.uniform(-2, 2, 2), 0.0, rng.uniform(0.5, 2, 2)]
        for a, b in zip(_jacobians(g, args), _jacobians(f, args)):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    plain = _ode(ca.vertcat(x[1], -ca.sin(x[0])), t, x, u, ca.SX.sym("p", 0))
    assert fold_parameters(plain) is plain
    simple = _ode(ca.vertcat(x[1], p[0] * ca.sin(x[0])), t, x, u, p)
    assert fold_parameters(simple) is simple


def test_derivatives_are_built_with_common_subexpressions_merged():
    """eom.specialize.shared_derivatives: the default ode's derivative Functions that IPOPT evaluates
    (forward in 5 directions: the constraint Jacobian; forward over reverse in 3: the exact
    Hessian) have fewer instructions than CasADi builds for the same expressions by default,
    and the same values at random arguments (seeds included)."""
    m = mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")
    ode = m.casadi()["ode"]
    ins = ode.sx_in()
    plain = ca.Function("plain", ins, ode.call(ins))          # the same expressions, CasADi's defaults
    rng = np.random.default_rng(2024)
    for make in (lambda f: f.forward(5), lambda f: f.reverse(1).forward(3), lambda f: f.reverse(1)):
        ours, theirs = make(ode), make(plain)
        assert ours.n_instructions() < theirs.n_instructions()
        for _ in range(5):
            args = [rng.uniform(0.3, 2.0, theirs.sparsity_in(i).nnz()) for i in range(theirs.n_in())]
            args = [ca.DM(theirs.sparsity_in(i), a) for i, a in enumerate(args)]
            a = np.concatenate([np.ravel(np.array(v, float)) for v in ours.call(args)])
            b = np.concatenate([np.ravel(np.array(v, float)) for v in theirs.call(args)])
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
