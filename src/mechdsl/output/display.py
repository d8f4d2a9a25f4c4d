"""Seeing results in notebooks: rich displays (``_repr_html_``, ``_repr_markdown_``,
``_repr_latex_``) of Model, Result, Equilibrium and Linearization as plain functions, which the
classes take as methods (one line each); the sympy equations of a model; tables for pandas
and xarray.  Nothing heavy is imported until a display is asked for.
"""
from __future__ import annotations

import base64
import html
import io
import sys

import numpy as np

MAX_ROWS = 40            # table rows shown before "... N more"


# --------------------------------------------------------------------------- small pieces


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.6g}"
    if isinstance(v, complex):
        return f"{v.real:.4g}{v.imag:+.4g}j"
    return str(v)


def _html_table(head, rows, caption: str = "") -> str:
    e = html.escape
    more = len(rows) - MAX_ROWS
    rows = rows[:MAX_ROWS]
    out = ['<table style="border-collapse:collapse">']
    if caption:
        out.append(f'<caption style="text-align:left;font-weight:bold">{e(caption)}</caption>')
    out.append("<tr>" + "".join(f'<th style="text-align:left;padding:2px 8px">{e(h)}</th>' for h in head) + "</tr>")
    for r in rows:
        out.append("<tr>" + "".join(f'<td style="padding:2px 8px">{e(_fmt(c))}</td>' for c in r) + "</tr>")
    if more > 0:
        out.append(f'<tr><td colspan="{len(head)}">... {more} more</td></tr>')
    return "\n".join(out + ["</table>"])


def _md_table(head, rows) -> str:
    def cell(c):
        return _fmt(c).replace("|", "\\|")
    more = len(rows) - MAX_ROWS
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows[:MAX_ROWS]]
    if more > 0:
        lines.append(f"| ... {more} more |" + " |" * (len(head) - 1))
    return "\n".join(lines)


def _matrix_html(name: str, A, names) -> str:
    A = np.atleast_2d(np.asarray(A))
    rows = [[n] + list(r) for n, r in zip(names, A)]
    return _html_table([name] + list(names), rows)


def in_notebook() -> bool:
    """True inside a Jupyter kernel (for tqdm's notebook bar)."""
    ip = sys.modules.get("IPython")
    shell = ip.get_ipython() if ip is not None and hasattr(ip, "get_ipython") else None
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})


def notebook_bar(**kw):
    """tqdm's notebook progress bar when running in Jupyter (and ipywidgets is there), else None."""
    if not in_notebook():
        return None
    try:
        from tqdm.notebook import tqdm as notebook_tqdm

        return notebook_tqdm(**kw)
    except ImportError:             # no ipywidgets: the caller uses the text bar
        return None


# --------------------------------------------------------------------------- Model


def _model_parts(m):
    from ..model.exprs import evaluate

    model = m.model
    env = {p.name: p.value for p in model.parameters}
    from ..numbers import in_unit

    # values in their declared units (a parameter declared in deg shows 30, not 0.5236)
    params = [[p.name, in_unit(p.value, p.unit), p.unit or "", p.doc] for p in model.parameters]
    coords = []
    for c in model.coordinates:
        try:
            start = evaluate(c.start, env)
        except Exception:  # noqa: BLE001 - a start value that needs more than parameters
            start = "?"
        coords.append([c.name, in_unit(start, c.unit) if start != "?" else start, c.unit or "", c.doc])
    from ..semantic.topology import counts as _counts

    n = _counts(model)
    counts = [["coordinates", len(model.coordinates)], ["parameters", len(model.parameters)],
              ["bodies", n["bodies"]], ["joints", n["joints"]],
              ["constraints", len(model.constraints) + len(model.loops)], ["contacts", len(model.contacts)],
              ["outputs", len(model.outputs)]]
    title = f"{m.name}" + (f" (scene {m.scene.name})" if m.scene is not None else "")
    return title, model.doc, counts, params, coords, m.summary()


def model_html(m) -> str:
    title, doc, counts, params, coords, summary = _model_parts(m)
    e = html.escape
    return (f"<div><b>mechdsl model {e(title)}</b>" + (f": {e(doc)}" if doc else "")
            + f"<pre>{e(summary)}</pre>"
            + '<div style="display:flex;gap:24px;flex-wrap:wrap;align-items:flex-start">'
            + _html_table(["count", ""], counts)
            + _html_table(["coordinate", "start", "unit", ""], coords, "coordinates")
            + _html_table(["parameter", "value", "unit", ""], params, "parameters") + "</div></div>")


def model_markdown(m) -> str:
    title, doc, counts, params, coords, summary = _model_parts(m)
    return "\n\n".join([f"**mechdsl model {title}**" + (f": {doc}" if doc else ""), "```\n" + summary + "\n```",
                        _md_table(["coordinate", "start", "unit", "doc"], coords),
                        _md_table(["parameter", "value", "unit", "doc"], params)])


# --------------------------------------------------------------------------- Result


def _result_rows(r):
    s = r.stats
    rows = [["model", r.metadata.get("model", "")], ["method", r.metadata.get("method", "")],
            ["status", r.message], ["time", f"{r.t[0]:g} .. {r.t[-1]:g} s" if len(r.t) else "no points"],
            ["points", len(r.t)], ["coordinates", len(r.coordinates)], ["signals", len(r.signals)]]
    for key in ("steps", "rhs_evaluations", "wall_time"):
        if key in s:
            rows.append([key.replace("_", " "), s[key]])
    if r.events:
        rows.append(["events", len(r.events)])
    return rows


def result_png(r, width: float = 6.5) -> str:
    """A small plot of the result as base64 PNG."""
    from .plot import FIGURE_METADATA

    fig = r.plot(width=width)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=72, metadata=FIGURE_METADATA[".png"])
    return base64.b64encode(buf.getvalue()).decode("ascii")


def result_html(r) -> str:
    img = f'<img alt="plot of the result" src="data:image/png;base64,{result_png(r)}">' if len(r.t) > 1 else ""
    return ('<div style="display:flex;gap:24px;align-items:flex-start"><div><b>mechdsl result</b>'
            + _html_table(["", ""], _result_rows(r)) + "</div>" + img + "</div>")


def result_markdown(r) -> str:
    return "**mechdsl result**\n\n" + _md_table(["", ""], _result_rows(r))


# --------------------------------------------------------------------------- analyses


def _equilibrium_rows(e):
    return [[c, v] for c, v in e.values.items()]


def equilibrium_html(e) -> str:
    ev = ", ".join(_fmt(v) for v in e.hessian_eigenvalues)
    return (f"<div><b>{html.escape(e.kind)} equilibrium: {html.escape(e.stability)}</b>"
            + (f"<br>{html.escape(e.reason)}" if e.reason else "")
            + _html_table(["coordinate", "value"], _equilibrium_rows(e))
            + f"<div>Hessian eigenvalues: [{html.escape(ev)}]</div></div>")


def equilibrium_markdown(e) -> str:
    ev = ", ".join(_fmt(v) for v in e.hessian_eigenvalues)
    return (f"**{e.kind} equilibrium: {e.stability}**" + (f" ({e.reason})" if e.reason else "") + "\n\n"
            + _md_table(["coordinate", "value"], _equilibrium_rows(e)) + f"\n\nHessian eigenvalues: [{ev}]")


def _mode_rows(lin):
    md = lin.modes()
    return [[j + 1, md.kinds[j] if md.kinds else "", md.frequencies[j], md.hz[j], md.damping_ratios[j]]
            for j in range(len(md))]


MODE_HEAD = ["mode", "kind", "frequency [rad/s]", "frequency [Hz]", "damping ratio"]


def linearization_html(lin) -> str:
    names = lin.matrix_coords
    state = ", ".join(f"{c} = {_fmt(v)}" for c, v in lin.values.items())
    return (f"<div><b>linearization ({html.escape(lin.kind)})</b> at {html.escape(state)}"
            + "<div>M dq'' + C dq' + K dq = B du</div>"
            + '<div style="display:flex;gap:24px;flex-wrap:wrap">'
            + "".join(_matrix_html(k, getattr(lin, k), names) for k in ("M", "C", "K")) + "</div>"
            + _html_table(MODE_HEAD, _mode_rows(lin), "modes") + "</div>")


def linearization_markdown(lin) -> str:
    names = list(lin.matrix_coords)
    parts = [f"**linearization ({lin.kind})**"]
    for k in ("M", "C", "K"):
        A = np.atleast_2d(getattr(lin, k))
        parts.append(_md_table([k] + names, [[n] + list(r) for n, r in zip(names, A)]))
    parts.append(_md_table(MODE_HEAD, _mode_rows(lin)))
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- equations


class Equations(list):
    """sympy equations (``sympy.Eq``), one per coordinate (and momentum for Hamilton's form);
    typeset in notebooks (``_repr_latex_``).  ``form`` says which; ``extra`` holds T, V, D or H.
    A constrained model's equations carry one term per multiplier, ``lambda[<name>]``
    (``multipliers`` maps each sympy symbol to that name)."""

    def __init__(self, eqs, form: str, extra: dict, multipliers: dict | None = None):
        super().__init__(eqs)
        self.form = form
        self.extra = extra
        self.multipliers = dict(multipliers or {})

    def latex(self, dots: bool = True) -> str:
        """The equations (after T, V, D or H) as one LaTeX ``aligned`` environment; ``dots=True``
        (default) writes time derivatives as dots, as the textbooks and ``mech equations --latex``
        do; ``dots=False`` as d/dt (sympy's Derivative)."""
        import sympy as sp

        if dots:
            from sympy.physics.vector.printing import vlatex as tex
        else:
            tex = sp.latex
        sub = {sp.Symbol(k): sp.Symbol(r"\lambda_{\mathrm{" + v[7:-1].replace("_", r"\_") + "}}")
               for k, v in self.multipliers.items()}
        lines = [f"{k} &= {tex(v)}" for k, v in self.extra.items()]
        lines += [tex(eq.lhs.subs(sub)) + " &= " + tex(eq.rhs.subs(sub)) for eq in self]
        return "\\begin{aligned}\n" + " \\\\\n".join(lines) + "\n\\end{aligned}"

    def _repr_latex_(self) -> str:
        return "$$" + self.latex() + "$$"

    def __repr__(self) -> str:
        n = len(self)
        shown = "; ".join(str(e) for e in self[:3]) + ("; ..." if n > 3 else "")
        return f"<{n} {self.form.capitalize()} equation{'s' * (n != 1)}: {shown}>"


def equations(m, form: str = "lagrange") -> Equations:
    """Lagrange's equations (one ``Eq(d/dt dL/dq' - dL/dq + dD/dq', Q)`` per coordinate) or
    Hamilton's (``Eq(q', dH/dp)``, ``Eq(p', -dH/dq + Q - dD/dq')``) as sympy equations."""
    import sympy as sp

    from ..diagnostics import UsageError

    if form not in ("lagrange", "hamilton"):
        raise UsageError(f"form must be 'lagrange' or 'hamilton', not {form!r}")
    if form == "lagrange":
        from ..mechanics.printing import _TooLarge, lagrange_equations, multiplier_terms

        try:
            sm, T, V, D, Q, eqs = lagrange_equations(m.model)
        except _TooLarge as e:
            raise UsageError(f"the equations of {m.name} are too large to show symbolically: {e}") from None
        extra = {"T": T, "V": V} | ({"D": D} if D != 0 else {})
        lam, names = multiplier_terms(m.model, sm)
        return Equations([sp.Eq(a + b, Qi + li) for (a, b, Qi), li in zip(eqs, lam)], form, extra, names)
    from ..analysis.hamilton import _lagrangian_for, symbolic_hamilton

    lg, _ = _lagrangian_for(m)
    h = symbolic_hamilton(lg)
    if not h["small"]:
        raise UsageError(f"Hamilton's equations of {m.name} are too large to show symbolically (M is not "
                         "inverted by sympy); `mech equations --hamiltonian` prints them in matrix form")
    qd_eqs = [sp.Eq(sp.Symbol(f"\\dot{{{c}}}", real=True), e) for c, e in zip(lg.coords, h["qd"])]
    pd_eqs = [sp.Eq(sp.Symbol(f"\\dot{{{P.name}}}", real=True), e) for P, e in zip(h["P"], h["pdot"])]
    H = h["H"]
    return Equations(qd_eqs + pd_eqs, form, {"H": H})


# --------------------------------------------------------------------------- drawing


def draw_model(m, t=None, q=None, **kw):
    from ..animate import draw

    if q is None and t:
        r = m.simulate(float(t), points=2)
        q, t = r.q[-1], float(r.t[-1])
    return draw(m, q, float(t or 0.0), **kw)


def animate_result(r, model=None, **kw):
    from ..animate import animate

    return animate(r, _result_model(r, model, "animate"), **kw)


def view_result(r, model=None, **kw):
    from ..view import view

    return view(r, _result_model(r, model, "view"), **kw)


def view_model(m, t_end=None, q=None, **kw):
    from ..view import still, view

    if t_end is None:
        return still(m, q, **kw)
    if q is not None:
        from ..diagnostics import UsageError

        raise UsageError("view: give t_end (simulate from the start values) or q (a still), not both")
    from ..animate import frame_times, pick_speed

    t0 = float(m.scene_settings.get("start_time", 0.0))
    fps = kw.setdefault("fps", 30.0)
    speed = kw.get("speed")
    kw["speed"] = speed = pick_speed(float(t_end) - t0) if speed is None else speed
    times = frame_times(t0, float(t_end), fps, speed)          # simulated exactly on the frame times
    return view(m.simulate(float(times[-1]), points=max(2, len(times))), m, **kw)


def _result_model(r, model, verb):
    from ..diagnostics import UsageError

    model = model if model is not None else getattr(r, "source_model", None)
    if model is None:
        raise UsageError(f"this result does not know its model: pass it, r.{verb}(model)")
    return model


# --------------------------------------------------------------------------- tables


def _columns(r):
    from .units import signal_units

    units = signal_units(r)
    names = [c for c in r.columns if c != "time"]
    return names, units


def to_pandas(r):
    """A DataFrame indexed by time [s]; ``df.attrs["units"]`` maps every column to its unit."""
    try:
        import pandas as pd
    except ImportError:
        from ..diagnostics import UsageError

        raise UsageError("to_pandas needs pandas: pip install 'mechdsl[table]'") from None
    names, units = _columns(r)
    data = {n: np.asarray(r[n], float) for n in names}
    df = pd.DataFrame(data, index=pd.Index(np.asarray(r.t, float), name="time"))
    df.attrs["units"] = {n: units.get(n, "") for n in ["time"] + names}
    df.attrs["model"] = r.metadata.get("model", "")
    return df


def to_xarray(r):
    """A Dataset over the coordinate ``time``; every variable has ``attrs["units"]``."""
    try:
        import xarray as xr
    except ImportError:
        from ..diagnostics import UsageError

        raise UsageError("to_xarray needs xarray: pip install 'mechdsl[table]'") from None
    names, units = _columns(r)
    ds = xr.Dataset({n: ("time", np.asarray(r[n], float), {"units": units.get(n, "")}) for n in names},
                    coords={"time": ("time", np.asarray(r.t, float), {"units": "s"})},
                    attrs={"model": r.metadata.get("model", ""), "generator": "mechdsl"})
    return ds
