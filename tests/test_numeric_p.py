"""mechdsl.eom.numeric_p: m.casadi()'s SX Functions, called in an MX graph with p as numbers,
call their specialization to those numbers (issue 24 item 7).  The graph must give the same
values and the same derivatives with respect to everything symbolic as the Function itself,
p given as a symbol must keep its full derivatives, and SX or numeric calls are untouched."""
import pickle

import casadi as ca
import numpy as np

import mechdsl
from conftest import MODELS
from mechdsl.eom.numeric_p import NumericP


def _cart_pole():
    return mechdsl.load(str(MODELS / "cart_pole.mech"), model="CartPole")


def _called_functions(F):
    """The Functions an MX Function calls."""
    return [F.instruction_MX(k).which_function() for k in range(F.n_instructions())
            if F.instruction_id(k) == ca.OP_CALL]


def test_mx_call_with_numeric_p_is_the_specialized_function_with_the_same_values_and_derivatives():
    m = _cart_pole()
    ode = m.casadi()["ode"]
    assert isinstance(ode, NumericP) and ode.class_name() == "SXFunction"
    plain = ca.Function(ode)                         # the Function itself, called as CasADi calls it
    x, u = ca.MX.sym("x", 4), ca.MX.sym("u")
    rng = np.random.default_rng(7)
    for pv in (m.parameter_vector(), rng.uniform(0.3, 3.0, 4) * [1, 1, 1, 10]):
        ours = ode(0, x, u, pv)
        theirs = plain(0, x, u, pv)
        F = ca.Function("F", [x, u], [ours, ca.jacobian(ours, ca.vertcat(x, u))])
        G = ca.Function("G", [x, u], [theirs, ca.jacobian(theirs, ca.vertcat(x, u))])
        called = _called_functions(ca.Function("f", [x, u], [ours]))
        assert len(called) == 1 and called[0].numel_in(3) == 0              # p built in
        assert called[0].n_instructions() < ode.n_instructions()
        for _ in range(10):
            a = [rng.uniform(-3, 3, 4), rng.uniform(-20, 20)]
            for v, w in zip(F(*a), G(*a)):
                w = np.array(w, float)
                np.testing.assert_allclose(np.array(v, float), w, rtol=1e-12, atol=1e-12 * np.abs(w).max())
    assert ode.specialized(m.parameter_vector()) is ode.specialized(m.parameter_vector())   # built once per vector


def test_symbolic_p_keeps_its_derivatives_and_sx_or_numeric_calls_go_to_the_function():
    m = _cart_pole()
    ode = m.casadi()["ode"]
    plain = ca.Function(ode)
    x, u, p = ca.MX.sym("x", 4), ca.MX.sym("u"), ca.MX.sym("p", 4)
    ours = ode(0, x, u, p)
    assert _called_functions(ca.Function("f", [x, u, p], [ours]))[0].numel_in(3) == 4   # the full Function
    J = ca.Function("J", [x, u, p], [ca.jacobian(ours, p)])
    Jp = ca.Function("Jp", [x, u, p], [ca.jacobian(plain(0, x, u, p), p)])
    rng = np.random.default_rng(8)
    for _ in range(10):
        a = [rng.uniform(-3, 3, 4), rng.uniform(-20, 20), rng.uniform(0.3, 3.0, 4)]
        want = np.array(Jp(*a), float)
        assert np.abs(want).max() > 0
        np.testing.assert_allclose(np.array(J(*a), float), want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    xs, ps = ca.SX.sym("x", 4), ca.SX.sym("p", 4)
    assert ca.depends_on(ode(0, xs, 0, ps), ps)                       # SX: the Function's own call
    num = [0.0, rng.uniform(-3, 3, 4), 1.5, m.parameter_vector()]
    np.testing.assert_array_equal(np.array(ode(*num), float), np.array(plain(*num), float))
    back = pickle.loads(pickle.dumps(ode))
    np.testing.assert_array_equal(np.array(back(*num), float), np.array(plain(*num), float))


def test_fixed_parameters_and_models_without_parameters_are_plain_functions():
    m = _cart_pole()
    assert not isinstance(m.casadi(fixed_parameters=True)["ode"], NumericP)          # p empty
