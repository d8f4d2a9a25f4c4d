"""The compiled constrained system: equations against the reference, linear algebra, index.

References: Andrews' squeezer as printed in the IVP Test Set (Mazzia, Magherini, Iavernaro;
../shared/references, copied in tests/references/README.md) -- its force vector f is compared with the bias we
derive from T, V and Q by automatic differentiation.
"""
import casadi as ca
import numpy as np
import pytest

from dae_models import andrews_eom, andrews_mass_forces, pendulum_eom
from mechdsl.dae import dae_index, guarded_idas
from mechdsl.dae.ggl import ggl_dae, raw_index3_dae
from mechdsl.dae.constrained_system import ConstrainedSystem
from mechdsl.diagnostics import MechError


def test_andrews_lagrange_terms_match_reference_forces():
    e = andrews_eom()
    P = {k: e.p[i] for i, k in enumerate(e.params)}
    M_ref, f_ref, _ = andrews_mass_forces(e.q, e.qd, P)
    F = ca.Function("F", [e.q, e.qd, e.p], [e.M - M_ref, e.bias - f_ref, f_ref])
    rng = np.random.default_rng(3)
    for _ in range(5):
        dM, df, f = F(rng.normal(size=7), 50 * rng.normal(size=7), e.param_values)
        assert np.max(np.abs(np.array(dM))) < 1e-15
        assert np.max(np.abs(np.array(df))) <= 1e-12 * max(1.0, np.max(np.abs(np.array(f))))


def test_andrews_start_values_are_consistent():
    e = andrews_eom()
    s = ConstrainedSystem.build(e)
    q0, qd0 = e.start()
    assert np.max(np.abs(s.g(q0, 0.0))) < 1e-15
    # the reference's consistent accelerations and multipliers (y0[14:27])
    from dae_models import andrews_data

    y0 = np.array([float(v) for v in andrews_data()["y0"]])
    a, lam = s.accel(q0, qd0, 0.0)
    assert np.allclose(a, y0[14:21], rtol=1e-9, atol=1e-6)
    assert np.allclose(lam, y0[21:27], rtol=1e-9, atol=1e-9)


def test_symbolic_kkt_solve_agrees_with_pivoted_dense_solve():
    e = andrews_eom()
    s = ConstrainedSystem.build(e)
    q0, _ = e.start()
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = q0 + 0.5 * rng.normal(size=7)
        qd = 100 * rng.normal(size=7)
        a, lam = s.accel(q, qd, 0.0)
        M, G = s.M(q, 0.0), s.G(q, 0.0)
        K = np.block([[M, G.T], [G, np.zeros((6, 6))]])
        gamma = -np.array(ca.Function("gam", [e.q, e.qd, e.t, e.p], [s.sym["gamma"]])(q, qd, 0.0, e.param_values)).ravel()
        bias = np.array(ca.Function("b", [e.q, e.qd, e.t, e.p], [e.bias])(q, qd, 0.0, e.param_values)).ravel()
        x = np.linalg.solve(K, np.concatenate([bias, -gamma]))
        assert np.linalg.norm(a - x[:7]) <= 1e-10 * np.linalg.norm(x[:7])
        assert np.linalg.norm(lam - x[7:]) <= 1e-10 * np.linalg.norm(x[7:])


def _pendulum_forms():
    e = pendulum_eom()
    s = ConstrainedSystem.build(e)
    q0, qd0 = e.start()
    a0, lam0 = s.accel(q0, qd0, 0.0)
    return e, s, q0, qd0, a0, lam0


def test_index_of_the_three_forms():
    e, s, q0, qd0, a0, lam0 = _pendulum_forms()
    x0 = np.concatenate([q0, qd0])
    assert dae_index(raw_index3_dae(s), x0, np.concatenate([a0, lam0]), e.param_values) == 3
    assert dae_index(ggl_dae(s), x0, np.concatenate([a0, lam0, [0.0]]), e.param_values) == 2
    S = s.sym
    v = ca.SX.sym("v", 2)
    a = ca.SX.sym("a", 2)
    lam = ca.SX.sym("lam", 1)
    sub = lambda z: ca.substitute(z, S["qd"], v)  # noqa: E731
    index1 = {"x": ca.vertcat(S["q"], v), "z": ca.vertcat(a, lam), "p": S["p"], "t": S["t"],
              "ode": ca.vertcat(v, a),
              "alg": ca.vertcat(ca.mtimes(S["M"], a) - sub(S["bias"]) + ca.mtimes(S["G"].T, lam),
                                ca.mtimes(S["G"], a) - sub(S["gamma"]))}
    assert dae_index(index1, x0, np.concatenate([a0, lam0]), e.param_values) == 1


def test_idas_refuses_the_raw_index3_form():
    e, s, q0, qd0, a0, lam0 = _pendulum_forms()
    x0 = np.concatenate([q0, qd0])
    with pytest.raises(MechError) as info:
        guarded_idas("raw", raw_index3_dae(s), x0, np.concatenate([a0, lam0]), e.param_values, 0.0, [1.0],
                     {"calc_ic": False}, allowed_index=2, what="the index-3 form")
    d = info.value.first
    assert d.code == "E823" and "index is 3" in d.message
    # index 2 without suppress_algebraic is refused too; with it, the GGL system passes
    z0 = np.concatenate([a0, lam0, [0.0]])
    with pytest.raises(MechError):
        guarded_idas("ggl", ggl_dae(s), x0, z0, e.param_values, 0.0, [1.0], {"calc_ic": False}, allowed_index=2)
    F, index = guarded_idas("ggl", ggl_dae(s), x0, z0, e.param_values, 0.0, [1.0],
                            {"calc_ic": False, "suppress_algebraic": True}, allowed_index=2)
    assert index == 2


def test_the_linear_algebra_routes_agree(monkeypatch):
    """n + m up to SX_KKT_MAX: symbolic solve; above: Cholesky + Schur complement in SX when M is
    positive definite, else numeric QR per call (MX). All three agree with a pivoted dense solve."""
    import mechdsl.dae.constrained_system as S

    e = andrews_eom()
    q0, _ = e.start()
    rng = np.random.default_rng(7)
    states = [(q0 + 0.3 * rng.normal(size=7), 30 * rng.normal(size=7)) for _ in range(5)]
    out = {}
    for limit, schur in ((100, 60), (0, 60), (0, 0)):
        monkeypatch.setattr(S, "SX_KKT_MAX", limit)
        monkeypatch.setattr(S, "SCHUR_MAX_N", schur)
        s = ConstrainedSystem.build(e)
        out[s.route] = [s.accel(q, qd, 0.0, 3.0, 5.0) for q, qd in states]
    assert set(out) == {"sx", "schur", "mx"}
    s = ConstrainedSystem.build(e)
    gamma_f = ca.Function("gam", [e.q, e.qd, e.t, e.p, s.sym["alpha"], s.sym["beta"]],
                          [s.sym["gamma"] - 2 * s.sym["alpha"] * s.sym["gdot"] - s.sym["beta"] ** 2 * s.sym["g"]])
    bias_f = ca.Function("b", [e.q, e.qd, e.t, e.p], [e.bias])
    for k, (q, qd) in enumerate(states):
        M, G = s.M(q, 0.0), s.G(q, 0.0)
        K = np.block([[M, G.T], [G, np.zeros((6, 6))]])
        rhs = np.concatenate([np.array(bias_f(q, qd, 0.0, e.param_values)).ravel(),
                              np.array(gamma_f(q, qd, 0.0, e.param_values, 3.0, 5.0)).ravel()])
        x = np.linalg.solve(K, rhs)          # LAPACK, partial pivoting: the independent route
        for route in out:
            a, lam = out[route][k]
            assert np.linalg.norm(a - x[:7]) <= 1e-10 * np.linalg.norm(x[:7]), route
            assert np.linalg.norm(lam - x[7:]) <= 1e-10 * np.linalg.norm(x[7:]), route


def test_schur_route_is_not_used_with_a_singular_mass_matrix(monkeypatch):
    """A coordinate without mass (M singular, the KKT matrix still regular) needs the QR route."""
    import mechdsl.dae.constrained_system as S

    e = andrews_eom()
    zero_mass = e.replace(M=e.M * ca.diag(ca.DM([0, 1, 1, 1, 1, 1, 1])))
    monkeypatch.setattr(S, "SX_KKT_MAX", 0)
    assert S._kkt_route(zero_mass, zero_mass.param_values, 6) == "mx"
    assert S._kkt_route(e, e.param_values, 6) == "schur"
