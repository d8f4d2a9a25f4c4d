"""`mech equations`: the printed (sympy) Lagrange equations hold on the numeric equations of
motion at random states; text, LaTeX, structure and --hamiltonian forms."""
from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

from mechdsl.cli import main
from mechdsl.mechanics import derive
from mechdsl.mechanics.printing import format_equations, lagrange_equations
import mechdsl.examples

MODELS = str(mechdsl.examples.folder())


def load_ir(name):
    from mechdsl.api import load_model_ir

    return load_model_ir(os.path.join(MODELS, f"{name}.mech"))


def residual_check(model, seed=0):
    """acceleration terms + rest - Q = 0 at (q, qd, qdd) of the CasADi equations."""
    import sympy as sp

    sm, T, V, D, Q, eqs = lagrange_equations(model)
    from mechdsl.eom import fold_inputs

    e = fold_inputs(derive(model))      # inputs (cart_pole's F) at their defaults, as trailing parameters
    t = sm.t
    qs = sm.coords
    a, b, c = (sp.symbols(f"{k}0:{len(qs)}") for k in ("a", "b", "c"))
    rep = {}
    for i, x in enumerate(qs):
        rep[sp.diff(x, t, 2)] = a[i]
    exprs = [(acc + rest - Qi).subs(rep).subs({sp.diff(x, t): b[i] for i, x in enumerate(qs)})
             .subs({x: c[i] for i, x in enumerate(qs)}) for acc, rest, Qi in eqs]
    params = {p.name: p.value for p in model.parameters}
    psub = {sp.Symbol(k, real=True): params[v] for k, v in sm.names.items() if v in params}
    f = sp.lambdify([a, b, c, t], [x.subs(psub) for x in exprs], "numpy")
    mb = ca.Function("mb", [e.q, e.qd, e.t, e.p], [e.M, e.bias])
    rng = np.random.default_rng(seed)
    for _ in range(3):
        q, qd, tt = rng.uniform(-2, 2, e.n), rng.uniform(-2, 2, e.n), rng.uniform(0, 3)
        M, bias = (np.array(x) for x in mb(q, qd, tt, e.param_values))
        qdd = np.linalg.solve(M, bias.ravel())
        r = np.array(f(qdd, qd, q, tt), float)
        assert np.abs(r).max() < 1e-9 * max(1, np.abs(qdd).max()), r


@pytest.mark.slow_cases('double_pendulum')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("name", ["double_pendulum", "cart_pole", "bead_on_hoop", "two_masses_spring"])
def test_printed_equations_hold(name):
    residual_check(load_ir(name))


def test_printed_equations_with_forces_and_terms():
    from test_mech_forces import rod_pendulum

    residual_check(rod_pendulum(follower=0.7, torque=0.3, gen=1.0, kappa=2.0, beta=0.4, J=0.1))


def test_text_form_of_the_pendulum():
    text = format_equations(load_ir("pendulum"))
    lines = [ln.strip() for ln in text.splitlines()]
    assert "T = m*L^2*der(theta)^2/2" in lines
    assert "V = -L*g*m*cos(theta)" in lines
    assert "theta:  m*L^2*der(der(theta)) + L*g*m*sin(theta) = 0" in lines


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_text_latex_and_structure(capsys, tmp_path):
    assert main(["equations", os.path.join(MODELS, "double_pendulum.mech")]) == 0
    out = capsys.readouterr().out
    assert "j1.phi:" in out and "j2.phi:" in out and "T = " in out
    assert main(["equations", os.path.join(MODELS, "double_pendulum.mech"), "--latex"]) == 0
    out = capsys.readouterr().out
    assert out.count("\\begin{align}") == 1 and "\\ddot{\\phi}_{j1}" in out
    src = open(os.path.join(MODELS, "nlink_pendulum.mech")).read().replace("Integer N = 3", "Integer N = 9")
    p = tmp_path / "n9.mech"
    p.write_text(src)
    assert main(["equations", str(p)]) == 0
    out = capsys.readouterr().out
    assert "9 coordinates (more than 6)" in out and out.count("operations") == 9


def test_cli_hamiltonian_and_errors(capsys, tmp_path):
    rc = main(["equations", os.path.join(MODELS, "pendulum.mech"), "--hamiltonian"])
    out, err = capsys.readouterr()
    assert rc == 0 and "Traceback" not in out + err
    try:
        import mechdsl.analysis.hamilton  # noqa: F401
    except ImportError:
        assert out.startswith("note: ") and len(out.strip().splitlines()) == 1
    bad = tmp_path / "bad.mech"
    bad.write_text("model X\n  parameter Real = ;\nend X;\n")
    assert main(["equations", str(bad)]) == 1
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_quaternion_equations_hold_up_to_the_norm_multiplier():
    """For a quaternion joint the printed Lagrange equations hold with a multiplier along q:
    their residual at the numeric accelerations is parallel to q."""
    import sympy as sp

    from test_mech_rigid import body_model

    model = body_model("quaternion")
    sm, T, V, D, Q, eqs = lagrange_equations(model)
    e = derive(model)
    t, qs = sm.t, sm.coords
    a, b, c = (sp.symbols(f"{k}0:4") for k in ("a", "b", "c"))
    exprs = []
    for acc, rest, Qi in eqs:
        x = (acc + rest - Qi).subs({sp.diff(v, t, 2): a[i] for i, v in enumerate(qs)})
        x = x.subs({sp.diff(v, t): b[i] for i, v in enumerate(qs)}).subs({v: c[i] for i, v in enumerate(qs)})
        exprs.append(x)
    f = sp.lambdify([a, b, c], exprs, "numpy")
    rhs = ca.Function("f", [e.q, e.qd, e.p], [e.qdd])
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        qd = rng.normal(size=4)
        qd -= q * (q @ qd)
        qdd = np.array(rhs(q, qd, e.param_values)).ravel()
        r = np.array(f(qdd, qd, q), float)
        assert np.abs(r - q * (q @ r)).max() < 1e-10 * max(1.0, np.abs(r).max())
        assert np.abs(r).max() > 1e-6          # the multiplier is not trivially zero
