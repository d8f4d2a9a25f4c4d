"""Notebook displays, sympy equations, tables with units and plots that read (mechdsl.output.display,
mechdsl.output.plot)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from sympy.core.function import AppliedUndef

import mechdsl
from mechdsl.diagnostics import UsageError
from mechdsl.output.result import Result

from conftest import CHECKOUT, MODELS, TESTS  # noqa: E402


def _load(name, **kw):
    return mechdsl.load(MODELS / f"{name}.mech", **kw)


def _by_name(expr):
    return {s.name: s for s in expr.free_symbols}


# ----------------------------------------------------------------------------- reprs


def test_model_displays_parameters_coordinates_counts_and_formulation():
    m = _load("double_pendulum")
    h = m._repr_html_()
    for text in ("DoublePendulum", "scene Chaos", "j1.phi", "j2.phi", "1.5708", "kg", "m/s2", "bodies",
                 "ODE in minimal coordinates"):
        assert text in h
    md = m._repr_markdown_()
    assert "| j1.phi | 1.5708 | rad |" in md and "| l | 1 | m |" in md


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_result_displays_summary_and_a_small_plot():
    r = _load("pendulum").simulate(1.0, points=21)
    h = r._repr_html_()
    assert "data:image/png;base64," in h and "status" in h and "ok" in h
    assert "| points | 21 |" in r._repr_markdown_()


def test_equilibrium_and_linearization_show_the_closed_form_frequency():
    m = _load("pendulum")
    eq = m.equilibria()[0]
    assert "stable" in eq._repr_html_() and "| theta | 0 |" in eq._repr_markdown_()
    lin = m.linearize()
    w = math.sqrt(m.parameters["g"] / m.parameters["L"])       # small oscillations: sqrt(g/L)
    md = lin._repr_markdown_()
    row = next(line for line in md.splitlines() if line.startswith("| 1 | oscillatory"))
    assert float(row.split("|")[3]) == pytest.approx(w, rel=1e-5)
    assert "<caption" in lin._repr_html_() and "frequency [Hz]" in lin._repr_html_()


# ----------------------------------------------------------------------------- equations


def test_lagrange_equation_of_the_pendulum_is_the_textbook_one():
    m = _load("pendulum")
    eqs = m.equations()
    assert len(eqs) == 1 and eqs.form == "lagrange"
    s = _by_name(eqs[0].lhs)
    (th,) = eqs[0].lhs.atoms(AppliedUndef)                      # theta(t)
    t = list(th.free_symbols)[0]
    mass, L, g = s["m"], s["L"], s["g"]
    textbook = mass * L**2 * sp.diff(th, t, 2) + mass * g * L * sp.sin(th)
    assert sp.simplify(eqs[0].lhs - eqs[0].rhs - textbook) == 0
    assert eqs._repr_latex_().startswith("$$\\begin{aligned}")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_double_pendulum_lagrange_equations_agree_with_the_numeric_dynamics_at_random_states():
    import casadi as ca

    m = _load("double_pendulum")
    eqs = m.equations()
    eom = m.eom
    f = ca.Function("a", [eom.q, eom.qd, eom.t, eom.p], [ca.solve(eom.M, eom.bias)])
    rng = np.random.default_rng(5)
    funcs = sorted({a for e in eqs for a in e.lhs.atoms(AppliedUndef)}, key=str)     # the two angles of t
    t = list(funcs[0].free_symbols)[0]
    params = {n: v for n, v in m.parameters.items()}
    for _ in range(3):
        q, qd = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
        qdd = np.array(f(q, qd, 0.0, m.parameter_values)).ravel()
        for e in eqs:
            expr = e.lhs - e.rhs
            for fn, a, b, c in zip(funcs, q, qd, qdd):
                expr = expr.subs(sp.diff(fn, t, 2), c).subs(sp.diff(fn, t), b).subs(fn, a)
            expr = expr.subs({s: params[s.name] for s in expr.free_symbols if s.name in params})
            assert float(expr) == pytest.approx(0.0, abs=1e-9)


def test_hamilton_equations_of_the_pendulum():
    m = _load("pendulum")
    eqs = m.equations(form="hamilton")
    assert len(eqs) == 2
    H = eqs.extra["H"]
    s = _by_name(H)
    p, th, mass, L, g = s["p_theta"], s["theta"], s["m"], s["L"], s["g"]
    assert sp.simplify(H - (p**2 / (2 * mass * L**2) - mass * g * L * sp.cos(th))) == 0
    assert sp.simplify(eqs[0].rhs - p / (mass * L**2)) == 0
    assert sp.simplify(eqs[1].rhs + mass * g * L * sp.sin(th)) == 0
    with pytest.raises(UsageError):
        m.equations(form="newton")


# ----------------------------------------------------------------------------- tables


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_to_pandas_and_to_xarray_carry_units():
    import pandas  # noqa: F401 - the test extra installs it
    import xarray  # noqa: F401 - the test extra installs it
    r = _load("slider_crank").simulate(0.2, points=11)
    df = r.to_pandas()
    assert df.index.name == "time" and len(df) == 11
    u = df.attrs["units"]
    assert (u["time"], u["j1.phi"], u["j3.s"], u["der(j3.s)"], u["energy"]) == ("s", "rad", "m", "m/s", "J")
    assert df["j3.s"].to_numpy() == pytest.approx(r["j3.s"])
    ds = r.to_xarray()
    assert ds["j1.phi"].attrs["units"] == "rad" and ds["time"].attrs["units"] == "s"
    assert ds["der(j1.phi)"].values == pytest.approx(r["der(j1.phi)"])


# ----------------------------------------------------------------------------- plots


def _draw(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_plot_puts_angles_and_lengths_on_separate_labelled_axes_with_legends_outside():
    r = _load("slider_crank").simulate(0.3, points=31)
    fig = r.plot(drift=True)
    renderer = _draw(fig)
    labels = [a.get_ylabel() for a in fig.axes]
    assert labels == ["angle [rad]", "length [m]", "energy [J]", "energy drift [J]"]
    assert fig.axes[-1].get_xlabel() == "time [s]"
    for ax in fig.axes:
        leg = ax.get_legend()
        assert leg is not None
        assert leg.get_window_extent(renderer).x0 >= ax.get_window_extent(renderer).x1 - 1   # outside the data
    E = r["energy"]
    drift_line = fig.axes[-1].get_lines()[0]
    assert drift_line.get_ydata() == pytest.approx(E - E[0])


def test_colours_do_not_repeat_past_ten_curves():
    from mechdsl.output.plot import colours

    n = 40
    t = np.linspace(0, 1, 5)
    r = Result(t=t, q=np.outer(t, np.arange(n)), qd=np.zeros((5, n)), coordinates=tuple(f"q{i}" for i in range(n)))
    fig = r.plot()
    used = [ln.get_color() for ln in fig.axes[0].get_lines()]
    assert len(used) == n and len(set(used)) == n
    assert len(set(colours(200))) == 200


def test_plot_of_unknown_signal_is_a_usage_error():
    r = _load("pendulum").simulate(0.1, points=3)
    with pytest.raises(UsageError, match="no signal named 'nope'"):
        r.plot("nope")
    fig = r.plot("x", "y")                          # outputs: both lengths, one axis
    assert [a.get_ylabel() for a in fig.axes] == ["length [m]"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_plot_command_still_writes_a_file(tmp_path):
    from mechdsl.cli import main

    out = tmp_path / "p.png"
    assert main(["simulate", str(MODELS / "pendulum.mech"), "--t-end", "0.2", "--plot", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_progress_bar_outside_a_notebook_is_the_text_one():
    from mechdsl.output.display import in_notebook, notebook_bar

    assert not in_notebook() and notebook_bar(total=1) is None


def test_api_reference_is_up_to_date():
    import importlib.util

    spec = importlib.util.spec_from_file_location("api_doc", TESTS / "api_doc.py")
    api_doc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(api_doc)
    assert (CHECKOUT / "docs" / "api.md").read_text(encoding="utf-8") == api_doc.generate(), \
        "docs/api.md is stale: run PYTHONPATH=src python tests/api_doc.py"
