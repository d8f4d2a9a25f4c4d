"""Andrews' squeezing mechanism given to IDAS at index 3 (fails) and in reduced
formulations (work).

models/andrews.mech: seven bodies, six loop constraints, the index-3 DAE of the IVP Test
Set.  Written as it stands (x = (q, q'), z = lambda, 0 = g(q)) its differentiation index is
3: mechdsl's index guard refuses to hand it to IDAS, and forced past the guard IDAS fails
at the start, whatever its options.  The reduced formulations of mechdsl.dae (GGL at
index 2, Baumgarte, projection and partitioning as index-1 ODEs) reach 7 correct digits in
the positions against the Test Set's reference (PSIDE at 1e-14;
tests/references/andrews_squeezer.json, a copy of ../shared/references).
"""
from __future__ import annotations

import contextlib
import io
import json
import warnings
from pathlib import Path

import numpy as np

from .suite import Case, check_size, load, pyplot, save

MODEL = "models/andrews.mech"
REFERENCE = Path(__file__).resolve().parents[2] / "tests" / "references" / "andrews_squeezer.json"   # ../shared copy
T = 0.03
REDUCED = {"ggl+idas": ("ggl", "idas"), "baumgarte+cvodes-bdf": ("baumgarte", "cvodes-bdf"),
           "projection+cvodes-bdf": ("projection", "cvodes-bdf"),
           "partitioning+cvodes-adams": ("partitioning", "cvodes-adams")}
IDAS_OPTIONS = {"default": {}, "calc_ic off": {"calc_ic": False},
                "calc_ic off, algebraic out of the error test": {"calc_ic": False, "suppress_algebraic": True}}


def reference():
    d = json.loads(REFERENCE.read_text())
    return np.array([float(v) for v in d["y0"]]), np.array([float(v) for v in d["reference_t0.03"][:7]])


def index3_dae(eom):
    """x = (q, q'), z = lambda:  q'' = M^-1 (bias - G^T lambda),  0 = g(q)."""
    import casadi as ca

    lam = ca.SX.sym("lam", eom.m)
    G = ca.jacobian(eom.g, eom.q)
    acc = ca.solve(eom.M, eom.bias - ca.mtimes(G.T, lam))
    return {"x": ca.vertcat(eom.q, eom.qd), "z": lam, "p": eom.p, "t": eom.t, "ode": ca.vertcat(eom.qd, acc),
            "alg": eom.g}


def run(size: str = "small") -> Case:
    from mechdsl.diagnostics import MechError
    from mechdsl.dae.index import dae_index, guarded_idas
    from mechdsl.simulate import simulate

    check_size(size)
    tols = (1e-10,) if size == "small" else (1e-6, 1e-8, 1e-10)
    e = load(MODEL).eom
    y0, ref = reference()
    pv = np.array(e.param_values, float)
    case = Case(name="andrews", title="Andrews' squeezing mechanism: IDAS at index 3 vs reduced formulations",
                size=size)
    dae = index3_dae(e)
    x0, z0 = y0[:14], y0[21:27]
    index = dae_index(dae, x0, z0, pv, 0.0)
    try:
        guarded_idas("index3", dae, x0, z0, pv, 0.0, [T], {})
        refused = None
    except MechError as ex:
        refused = str(ex)
    forced = {}
    for tol in tols:
        for lab, opts in IDAS_OPTIONS.items():
            o = dict(opts, reltol=tol, abstol=tol, max_num_steps=100_000)
            integ, _ = guarded_idas("index3", dae, x0, z0, pv, 0.0, list(np.linspace(0, T, 31)[1:]), o, force=True)
            with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):   # IDAS's own messages
                warnings.simplefilter("ignore")
                try:
                    res = integ(x0=x0, z0=z0, p=pv)
                    q = np.array(res["xf"], float)[:7, -1]
                    forced[(tol, lab)] = ("finished", float(np.max(np.abs(q - ref) / np.abs(ref))))
                except RuntimeError as ex:
                    msg = [ln for ln in str(ex).strip().splitlines() if ln.strip()][-1]
                    forced[(tol, lab)] = ("failed", msg.split("returned", 1)[-1].strip()[:60])
    reduced = {}
    for tol in tols:
        for lab, (form, meth) in REDUCED.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = simulate(e, T, rtol=tol, atol=tol, method=meth, formulation=form, points=2, error_estimate="off")
            err = float(np.max(np.abs(r.q[-1] - ref) / np.abs(ref))) if r.success else float("inf")
            reduced[(tol, lab)] = (r, err)
    case.data.update(index=index, refused=refused, forced=forced, reduced=reduced, tols=tols)
    case.table.append(f"  differentiation index of the DAE as written: {index}")
    case.table.append(f"  index guard: {refused or 'accepted it'}")
    for (tol, lab), (status, what) in forced.items():
        case.table.append(f"  IDAS at index 3, tol {tol:g}, {lab}: {status}"
                          + (f" (position error {what:.1e})" if status == "finished" else f": {what}"))
    for (tol, lab), (r, err) in reduced.items():
        case.table.append(f"  {lab:28s} tol {tol:g}: max relative position error {err:.1e}"
                          + ("" if r.success else f" ({r.failure.cause})"))
    case.check("the index of the DAE as written is 3 and the guard refuses to give it to IDAS",
               index == 3 and refused is not None and "index is 3" in refused, (refused or "not refused")[:120])
    case.check("forced past the guard, IDAS fails on the index-3 form (every option, every tolerance)",
               all(s == "failed" for s, _ in forced.values()),
               "; ".join(f"{lab} @ {tol:g}: {s}" for (tol, lab), (s, _) in list(forced.items())[:3]))
    tight = min(tols)
    case.check(f"every reduced formulation reaches 7 correct digits in the positions at tolerance {tight:g}",
               all(reduced[(tight, lab)][1] <= 1e-7 for lab in REDUCED),
               ", ".join(f"{lab} {reduced[(tight, lab)][1]:.1e}" for lab in REDUCED))
    return case


def chart(case: Case, out_dir) -> list:
    plt = pyplot()
    d = case.data
    fig, ax = plt.subplots(figsize=(8.5, 4.3))
    labs = list(REDUCED)
    width = 0.8 / (len(d["tols"]) + 1)
    for i, tol in enumerate(d["tols"]):
        errs = [max(d["reduced"][(tol, lab)][1], 1e-17) for lab in labs]
        ax.bar(np.arange(len(labs)) + i * width, errs, width, label=f"tolerance {tol:g}")
    nf = sum(1 for s, _ in d["forced"].values() if s == "failed")
    ax.bar([len(labs) + 0.3], [1.0], 0.5, color="tab:red", hatch="//", alpha=0.6,
           label=f"IDAS at index 3: failed at t = 0 ({nf}/{len(d['forced'])} runs)")
    ax.axhline(1e-7, color="k", ls=":", lw=0.8)
    ax.annotate("7 digits", xy=(0.01, 1e-7), xycoords=("axes fraction", "data"), xytext=(0, 3),
                textcoords="offset points", fontsize="x-small")
    ax.set_xticks(list(np.arange(len(labs)) + width * (len(d["tols"]) - 1) / 2) + [len(labs) + 0.3])
    ax.set_xticklabels(labs + ["index 3\n(no result)"], fontsize="x-small", rotation=15)
    ax.set_yscale("log")
    ax.set_ylabel("max relative position error at t = 0.03")
    ax.legend(fontsize="x-small")
    ax.set_title("Andrews' squeezer against the Test Set reference", fontsize="medium")
    fig.tight_layout()
    return save(fig, out_dir, "stability_andrews")
