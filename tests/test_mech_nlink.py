"""N-link pendulum of uniform slender rods: accelerations against sympy.physics.mechanics
(Kane's method, an independent derivation) at random states; routes agree; SX size linear."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mech_models import nlink
from mechdsl.mechanics import derive


def sympy_nlink(N, m=1.0, L=1.0, g=9.81):
    """qdd(q, u) of the N-link pendulum by sympy.physics.mechanics.KanesMethod."""
    import sympy as sp
    import sympy.physics.mechanics as me

    q = me.dynamicsymbols(f"q1:{N + 1}")
    u = me.dynamicsymbols(f"u1:{N + 1}")
    Nf = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(Nf, 0)
    prev, P = Nf, O
    bodies, loads = [], []
    for i in range(N):
        A = prev.orientnew(f"A{i}", "Axis", [q[i], prev.z])
        A.set_ang_vel(prev, u[i] * prev.z)
        G = P.locatenew(f"G{i}", -L / 2 * A.y)
        G.v2pt_theory(P, Nf, A)
        Pn = P.locatenew(f"P{i}", -L * A.y)
        Pn.v2pt_theory(P, Nf, A)
        I = me.inertia(A, m * L ** 2 / 12, 0, m * L ** 2 / 12)
        bodies.append(me.RigidBody(f"B{i}", G, A, m, (I, G)))
        loads.append((G, -m * g * Nf.y))
        prev, P = A, Pn
    kd = [q[i].diff() - u[i] for i in range(N)]
    km = me.KanesMethod(Nf, q_ind=q, u_ind=u, kd_eqs=kd)
    km.kanes_equations(bodies, loads)
    f = sp.lambdify([q, u], [km.mass_matrix, km.forcing], "numpy")

    def qdd(qv, uv):
        M, F = f(qv, uv)
        return np.linalg.solve(np.array(M, float), np.array(F, float).ravel())

    return qdd


def rhs(e):
    return ca.Function("f", [e.q, e.qd, e.p], [e.qdd])


def m_bias(e):
    return ca.Function("mb", [e.q, e.qd, e.p], [e.M, e.bias])


# N = 5 (sympy.mechanics' own derivation takes 1.8 s of CPU) is slow; by default N = 1 .. 4 against
# sympy.mechanics, and test_nlink_routes_agree[6] checks six links between the three routes
@pytest.mark.slow_cases('3', '4')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("N", [1, 2, 3, 4, pytest.param(5, marks=pytest.mark.slow)])
def test_nlink_matches_sympy_mechanics(N):
    e = derive(nlink(N))
    assert e.route == "aba"
    f = rhs(e)
    ref = sympy_nlink(N)
    rng = np.random.default_rng(N)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, N)
        qd = rng.uniform(-2, 2, N)
        a = np.array(f(q, qd, e.param_values)).ravel()
        b = ref(q, qd)
        assert np.max(np.abs(a - b)) <= 1e-10 * max(1.0, np.max(np.abs(b))), (a, b)


@pytest.mark.parametrize("N", [1, 3, 6])
def test_nlink_routes_agree(N):
    e = derive(nlink(N))
    el = derive(nlink(N), route="lagrange")
    ec = derive(nlink(N), route="crba")
    assert el.route == "lagrange" and ec.route == "crba" and ec.qdd is None
    f = rhs(e)
    rng = np.random.default_rng(10 + N)
    for _ in range(4):
        q, qd = rng.uniform(-3, 3, N), rng.uniform(-2, 2, N)
        a = np.array(f(q, qd, e.param_values)).ravel()
        for other in (e, el, ec):
            M, b = m_bias(other)(q, qd, e.param_values)
            M = np.array(M)
            assert np.allclose(M, M.T, atol=1e-14)
            x = np.linalg.solve(M, np.array(b).ravel())
            assert np.max(np.abs(x - a)) <= 1e-10 * max(1.0, np.max(np.abs(a)))
        # the CRBA mass matrix equals d2T/dqd2 of the Lagrange route
        M1 = np.array(m_bias(e)(q, qd, e.param_values)[0])
        M2 = np.array(m_bias(el)(q, qd, e.param_values)[0])
        assert np.max(np.abs(M1 - M2)) < 1e-12


def test_nlink_expression_size_linear():
    sizes = {N: rhs(derive(nlink(N))).n_instructions() for N in (10, 20, 40)}
    per = [(sizes[20] - sizes[10]) / 10, (sizes[40] - sizes[20]) / 20]
    assert abs(per[0] - per[1]) <= 0.02 * per[0], sizes


def test_nlink_energy_outputs_and_start():
    e = derive(nlink(3))
    q0, qd0 = e.start()
    assert np.allclose(q0, [np.pi / 2, 0, 0]) and np.allclose(qd0, 0)
    out = ca.Function("o", [e.q, e.qd, e.t, e.p], [e.outputs["x_tip"], e.outputs["E"], e.T, e.V])
    x, E, T, V = (float(v) for v in out(q0, qd0, 0.0, e.param_values))
    assert x == pytest.approx(3.0, abs=1e-14)        # all links horizontal along +x
    assert T == pytest.approx(0.0, abs=1e-15) and V == pytest.approx(0.0, abs=1e-12) and E == pytest.approx(T + V)
    # hanging down at rest: V = -m g (0.5 + 1.5 + 2.5)
    _, E, T, V = (float(v) for v in out([0, 0, 0], [0, 0, 0], 0.0, e.param_values))
    assert V == pytest.approx(-9.81 * 4.5)
    assert e.point_position("link3.b").shape == (3, 1)
