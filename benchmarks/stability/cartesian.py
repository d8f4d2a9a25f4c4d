"""The point-mass pendulum in Cartesian form (IFToMM A01): the unstabilized index-1
formulation drifts off the circle, stabilized and projected formulations stay on it.

models/pendulum_cartesian.mech, scene A01: a point mass on a massless 1 m rod written as
x^2 + y^2 = L^2, released from the horizontal, 2000 s (about 845 periods).  The index-1
form (accelerations from the differentiated constraint, ``baumgarte = (0, 0)``) only keeps
g'' = 0, so integration errors in g and g' grow without bound; Baumgarte stabilization
(automatic rates) keeps the drift bounded, projection and the GGL formulation hold it at
the drift bound max(10 atol, 1e-10).  The positions are compared with the closed form of the
pendulum (elliptic functions: sin(theta/2) = k cd(w t | k^2)); at this tolerance the phase
error after 845 periods is a matter of accuracy, not of stability.
"""
from __future__ import annotations

import warnings

import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "models/pendulum_cartesian.mech"
TOL = 1e-8
VARIANTS = {                                 # label -> (formulation, method, options)
    "index-1, unstabilized": ("baumgarte", "cvodes-bdf", {"baumgarte": (0, 0)}),
    "Baumgarte (automatic)": ("baumgarte", "cvodes-bdf", {}),
    "projection": ("projection", "cvodes-bdf", {}),
    "GGL (IDAS)": ("ggl", "idas", {}),
}


def exact_xy(t, a=np.pi / 2, g=9.81, L=1.0):
    from scipy.special import ellipj

    k = np.sin(a / 2)
    _, cn, dn, _ = ellipj(np.sqrt(g / L) * np.asarray(t), k * k)
    th = 2 * np.arcsin(k * cn / dn)
    return L * np.sin(th), -L * np.cos(th)


def run(size: str = "small") -> Case:
    from mechdsl.simulate import simulate

    check_size(size)
    T = 200.0 if size == "small" else 2000.0
    e = load(MODEL, scene="A01").eom
    case = Case(name="cartesian", title="Cartesian pendulum (index-3 DAE), drift off the circle", size=size)
    runs = {}
    for lab, (form, meth, kw) in VARIANTS.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs[lab] = simulate(e, T, rtol=TOL, atol=TOL, method=meth, formulation=form, points=int(T) + 1, **kw, error_estimate="off")
    bound = max(10 * TOL, 1e-10)
    stats = {}
    for lab, r in runs.items():
        g = np.abs(r["residual(c1)"])
        xe, ye = exact_xy(r.t)
        tenth = r.t <= r.t[-1] / 10
        stats[lab] = {"max": float(g.max()), "tenth": float(g[tenth].max()), "end": float(g[-1]),
                      "pos": float(np.hypot(r["x"] - xe, r["y"] - ye)[-1]), "g": g}
    case.data.update(runs=runs, stats=stats, T=T, bound=bound)
    case.table.append(f"  rtol = atol = {TOL:g}, {T:g} s; drift bound max(10 atol, 1e-10) = {bound:.0e}")
    case.table.append(f"  {'formulation':24s} {'max |g|':>9s} {'first 10%':>10s} {'at T':>9s} {'|r - r_exact|(T)':>17s}  status")
    for lab, s in stats.items():
        case.table.append(f"  {lab:24s} {s['max']:9.1e} {s['tenth']:10.1e} {s['end']:9.1e} {s['pos']:17.1e}  "
                          f"{fmt_fail(runs[lab])}")
    u = stats["index-1, unstabilized"]
    case.check("unstabilized index-1: the constraint drifts far beyond the bound and keeps growing",
               runs["index-1, unstabilized"].success and u["max"] >= 1e3 * bound and u["max"] >= 10 * u["tenth"],
               f"max |g| {u['max']:.1e} = {u['max'] / bound:.0f} x the bound; {u['max'] / u['tenth']:.0f} x its value "
               f"over the first tenth")
    for lab in ("projection", "GGL (IDAS)"):
        s = stats[lab]
        case.check(f"{lab}: stays on the circle (max |g| <= the drift bound)", runs[lab].success and s["max"] <= bound,
                   f"max |g| {s['max']:.1e}")
    b = stats["Baumgarte (automatic)"]
    case.check("Baumgarte stabilization: the drift stays bounded (max over the run <= 2 x max over the first tenth) "
               "and >= 100 x below the unstabilized one",
               runs["Baumgarte (automatic)"].success and b["max"] <= 2 * b["tenth"] and 100 * b["max"] <= u["max"],
               f"max |g| {b['max']:.1e}, first tenth {b['tenth']:.1e}")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.3))
    for lab, s in d["stats"].items():
        r = d["runs"][lab]
        a1.semilogy(r.t[1:], np.maximum(s["g"][1:], 1e-17), lw=0.9, label=lab)
        xe, ye = exact_xy(r.t)
        a2.semilogy(r.t[1:], np.maximum(np.hypot(r["x"] - xe, r["y"] - ye)[1:], 1e-17), lw=0.9, label=lab)
    a1.axhline(d["bound"], color="k", ls=":", lw=0.8)
    a1.annotate("drift bound", xy=(0.02, d["bound"]), xycoords=("axes fraction", "data"), xytext=(0, 3),
                textcoords="offset points", fontsize="x-small")
    a1.set_ylabel("|x^2 + y^2 - L^2|")
    a2.set_ylabel("distance from the exact position [m]")
    for a in (a1, a2):
        a.set_xlabel("t [s]")
        a.grid(True, alpha=0.3)
        a.legend(fontsize="x-small")
    fig.suptitle(f"Cartesian pendulum, {d['T']:g} s at rtol = atol = {TOL:g}: constraint drift and position error",
                 fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_cartesian")
