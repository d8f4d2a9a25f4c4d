"""Regenerate docs/performance.md and its figures (docs/figures/) in one run.

    PYTHONPATH=src python benchmarks/make_performance.py [--quick] [--docs DIR] [--no-nlink]

Everything the page states is measured by this run: the work-precision charts and tables
(mechdsl.bench), the stability suite (benchmarks/stability, full sizes), the N-link
scaling table (benchmarks/nlink.py, run as a subprocess) and the cost of simulating the
chain against N.  Ratios compare runs of the same invocation.  --quick uses short sweeps
and small sizes and writes into a temporary folder unless --docs is given (a smoke test of
the script, not numbers to publish).
"""
from __future__ import annotations

import argparse
import importlib
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import mechdsl  # noqa: E402
from mechdsl.bench import Setup, parse_tolerances, parse_variants, run_bench, write_chart, write_tables  # noqa: E402
from mechdsl.bench.report import fastest, fastest_lines, format_table, markdown_table  # noqa: E402

from stability.run import available_cases, run_cases  # noqa: E402

ANDREWS_JSON = ROOT / "tests" / "references" / "andrews_squeezer.json"     # a copy of ../shared/references


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- work-precision


def bench(path, *, scene=None, model=None, t_end=None, points=None, methods, tolerances, repeats=3, budget=5.0,
          reference="auto", compare="positions", params=None, setup_kw=None):
    m = mechdsl.load(str(ROOT / path), scene=scene, model=model)
    if params:
        m = m.with_params(**params)
    st = Setup.from_model(m, t_end=t_end, points=points, source=path, **(setup_kw or {}))
    log(f"== bench {path} {scene or model or ''}")
    return run_bench(st, variants=parse_variants(methods), tolerances=parse_tolerances(tolerances),
                     reference=reference, compare=compare, repeats=repeats, budget=budget,
                     log=lambda s: log("   " + s))


def wp_section(title, res, stem, figs, intro, targets=(1e-3, 1e-6, 1e-9), data_dir=None):
    write_chart(res, figs, stem=stem)
    if data_dir is not None:
        write_tables(res, Path(data_dir) / stem)
    lines = [f"### {title}", "", intro, "", f"![{title}](figures/{stem}.png)", "", "```",
             *fastest_lines(res, targets), "```", "",
             "<details><summary>every run (the table <code>mech bench</code> prints)</summary>", "", "```",
             format_table(res), "```", "", "</details>", ""]
    return "\n".join(lines)


def work_precision(quick, figs):
    tol = "1e-3..1e-9/1" if quick else "1e-2..1e-12"
    rep = 1 if quick else 3
    out = {}
    out["dp"] = bench("models/double_pendulum.mech", scene="Chaos", t_end=10, points=101,
                      methods="erk,cvodes-adams,cvodes-bdf,rosenbrock,scipy-dop853,scipy-rk45,scipy-lsoda,rk,"
                              "stormer-verlet,gauss-legendre",
                      tolerances=tol, repeats=rep)
    out["stiff"] = bench("benchmarks/stability/stiff_spring_pendulum.mech", scene="Swing", t_end=10, points=101,
                         methods="cvodes-bdf,rosenbrock,scipy-radau,scipy-bdf,scipy-lsoda,erk,scipy-rk45,"
                                 "collocation[dt=0.01],rk[dt=0.01]",
                         tolerances="1e-3..1e-8/1" if quick else "1e-2..1e-10", repeats=rep)
    out["nlink"] = bench("models/nlink_pendulum.mech", t_end=5, points=51, params={"N": 10},
                         methods="erk,cvodes-adams,cvodes-bdf,scipy-dop853,scipy-lsoda,rk",
                         tolerances="1e-3..1e-9/1" if quick else "1e-2..1e-11", repeats=rep)
    return out


# --------------------------------------------------------------------------- Andrews (constrained)


def andrews_reference_csv(coords, path):
    """The Test Set's reference (PSIDE at 1e-14) as a reference CSV of one row, t = 0.03, so
    that errors are relative to |q_i(0.03)| component by component (7 digits = 1e-7)."""
    import json

    d = json.loads(ANDREWS_JSON.read_text())
    y1 = [float(v) for v in d["reference_t0.03"]]
    head = ["time", *coords, *(f"der({c})" for c in coords)]
    rows = [[0.03, *y1[:14]]]
    text = ",".join(head) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n"
    Path(path).write_text(text)
    return path


def andrews(quick, figs, tmp):
    path = ROOT / "models" / "andrews.mech"
    if not path.exists():
        return None
    m = mechdsl.load(str(path))
    coords = list(m.eom.coords)
    from mechdsl.bench import read_csv

    ref = read_csv(andrews_reference_csv(coords, Path(tmp) / "andrews_reference.csv"))
    ref.source = "the IVP Test Set's q(0.03) (PSIDE at 1e-14; tests/references/andrews_squeezer.json)"
    methods = os.environ.get("MECHDSL_ANDREWS_METHODS") or ANDREWS_METHODS
    res = bench("models/andrews.mech", t_end=0.03, methods=methods,
                tolerances="1e-4..1e-10/1" if quick else "1e-3..1e-11", reference=ref,
                repeats=1 if quick else 3, budget=20.0)
    return res


ANDREWS_METHODS = ("ggl+idas,projection+erk,baumgarte+erk,baumgarte+cvodes-bdf,baumgarte+cvodes-adams,"
                   "projection+cvodes-bdf,projection+cvodes-adams,partitioning+cvodes-adams,index1-ode+scipy-dop853")


def andrews_check(res, digits=7):
    """The issue's check: a formulation reaches `digits` correct digits in the positions
    (final-time relative error <= 10^-digits against the Test Set) faster than DOP853."""
    target = 10.0 ** -digits
    dop = [lab for lab in res.variants() if "scipy-dop853" in lab]
    others = [lab for lab in res.variants() if lab not in dop]
    best_dop = min((r for r in (fastest(res, lab, target) for lab in dop) if r is not None), key=lambda r: r.cpu,
                   default=None)
    best = min((r for r in (fastest(res, lab, target) for lab in others) if r is not None), key=lambda r: r.cpu,
               default=None)
    ran = [r for lab in dop for r in res.rows_of(lab) if r.status in ("ok", "failed")]
    if not dop or not ran:      # no DOP853 run that integrated: nothing to compare with
        return False, ("no scipy DOP853 run in the chart integrated the model ("
                       + "; ".join(sorted({f"{r.status}: {r.message[:80]}" for lab in dop for r in res.rows_of(lab)}))
                       + ")")
    holds = best is not None and (best_dop is None or best.cpu < best_dop.cpu)
    detail = (f"fastest formulation reaching {target:.0e}: "
              + (f"{best.label} at tolerance {best.tolerance:.0e}, {best.cpu * 1e3:.3g} ms" if best else "none")
              + "; scipy DOP853: "
              + (f"{best_dop.label} at {best_dop.tolerance:.0e}, {best_dop.cpu * 1e3:.3g} ms" if best_dop
                 else "never reached it")
              + (f" (ratio {best_dop.cpu / best.cpu:.2f})" if best and best_dop else ""))
    return holds, detail


# --------------------------------------------------------------------------- scaling


def script_table(script: str, sizes: str, extra=()) -> str:
    """Run a benchmark script of this folder with --sizes; its stdout (or its failure) as text."""
    cmd = [sys.executable, str(ROOT / "benchmarks" / script), "--sizes", sizes, *extra]
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    log(f"== {script} {sizes}")
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if r.returncode != 0:
        return f"benchmarks/{script} failed:\n\n```\n{r.stderr[-2000:]}\n```\n"
    return r.stdout.strip()


def nlink_table(quick):
    return script_table("nlink.py", "1,2,5,10" if quick else "1,2,5,10,20,50,100", ["--no-sympy"] if quick else [])


def nlink_run_table(quick):
    """benchmarks/nlink_run.py: 5 s of the chain with default options against scipy DOP853 + pin.aba."""
    return script_table("nlink_run.py", "2,5,10" if quick else "2,5,10,20,30,50,100,200")


NLINK_RUN_TEXT = ("The same 5 s with every option at its default (rtol 1e-8 given): `method = auto` compiles "
                  "the dop853 stepping loop when its estimate says it pays (docs/simulate.md), against scipy's "
                  "DOP853 on Pinocchio's ABA (`benchmarks/nlink_run.py`; warm: the first run, which derives "
                  "and compiles, is the *first run* column). Goals (issue 16): ratio at most 0.5 at every N, "
                  "N = 30 under 30 ms of CPU.")


def chain_table(quick):
    """benchmarks/chain_kernel.py: the ode unrolled against looped per N."""
    return script_table("chain_kernel.py", "2,12,50" if quick else "2,12,50,100,200")


CHAIN_TEXT = ("`benchmarks/chain_kernel.py` (issue 16): the N-rod chain's `ode` unrolled (one SX expression) "
              "and looped (per-link kernels chained by `mapaccum`, mechanics/chain.py; none below a run of 4 "
              "identical links); C bytes of the ode alone (in parentheses without the static index tables), "
              "wall time of `codegen.compile_functions` (gcc at mechdsl's flags by size), one evaluation "
              "through `FastFunction` compiled and in the virtual machine, and the ratios looped / unrolled. "
              "The simulator compiles the looped form for chains over 8000 SX operations (`codegen.LOOP_OPS`) "
              "and always evaluates the unrolled form in the virtual machine.")


def contacts_table(quick):
    """benchmarks/impacts_compiled.py: contact stepping compiled against Python and free flight."""
    return script_table("impacts_compiled.py", "20", ["--repeats", "3" if quick else "5"])


CONTACTS_TEXT = ("`benchmarks/impacts_compiled.py` (issue 16): models with contacts step their free flights "
                 "(all contacts open) in the compiled dop853 loop, which also locates the events; the impact "
                 "law, persistent contacts and fixations stay in Python (docs/internals/impacts.md). Wall "
                 "times of whole `simulate_with_contacts` calls, warm. Goal: the ball's 20 bounces within 2x "
                 "of its free flight at equal step counts.")


def export_table(quick):
    """benchmarks/export_fmu.py: export time, the FMU's co-simulation against mech simulate, FMU size."""
    return script_table("export_fmu.py", "2,4,8" if quick else "2,4,8,16,32", ["--repeat", "1" if quick else "3"])


EXPORT_TEXT = ("`benchmarks/export_fmu.py` (issue 29): `mech export` of the double pendulum in a fresh process "
               "(import, load, derive, generate, compile, zip) with an empty cache and with the runtime's "
               "compiled objects cached; the FMU's co-simulation of the Chaos scene against `mech simulate`'s "
               "compiled loop, side by side in one run (CPU time, minimum of repeats), the FMU driven from "
               "Python (fmpy) and from a C driver; the size of the N-link chain's FMU against N. Goals: export "
               "under 5 s, the FMU's co-simulation at least as fast as mech simulate's compiled loop, the "
               "size linear in the model.")


def simulation_scaling(quick):
    """CPU time of simulating the N-link chain for 5 s at rtol = atol = 1e-8 (erk and
    cvodes-adams, virtual machine), min of 3 after a warm-up."""
    from mechdsl.bench.timing import timed
    from mechdsl.simulate import simulate

    sizes = (2, 5, 10) if quick else (2, 5, 10, 20, 50)
    base = mechdsl.load(str(ROOT / "models" / "nlink_pendulum.mech"))
    body = []
    for N in sizes:
        e = base.with_params(N=N).eom
        cells = [str(N)]
        for meth in ("erk", "cvodes-adams"):
            tm = timed(lambda: simulate(e, 5.0, rtol=1e-8, atol=1e-8, method=meth, points=51), 1 if quick else 3,
                       ok=lambda r: r.success)
            r = tm.result
            cells += [f"{tm.best * 1e3:.4g}" if r.success else f"failed ({r.failure.cause})", str(r.stats.get("steps"))]
        body.append(cells)
        log(f"   N={N}: " + " ".join(cells))
    return markdown_table(["N", "erk CPU [ms]", "erk steps", "cvodes-adams CPU [ms]", "cvodes-adams steps"], body)


# --------------------------------------------------------------------------- the page


USAGE = """\
## `mech bench`: work-precision of a model

```
mech bench FILE [--scene S | --model M] [--methods LIST] [--formulations LIST] [--tolerances SPEC]
                [--reference auto|FILE.csv] [--reference-methods A,B] [--compare WHAT]
                [--repeats K] [--budget S] [--t-end T] [--points N] [--set NAME=VALUE ...]
                [--compiled] [-o DIR] [--no-chart] [--force] [-q] [-v] [--json]
```

- **Methods** (`--methods`, comma separated, repeatable): any method of `mech simulate`
  (`erk`, `cvodes-bdf`, `cvodes-adams`, `idas`, `rosenbrock`, `rk`, `collocation`,
  `scipy-rk45`, `scipy-dop853`, `scipy-radau`, `scipy-bdf`, `scipy-lsoda`,
  `stormer-verlet`, `implicit-midpoint`, `gauss-legendre`, `auto`). For constrained models
  a method is `FORMULATION+METHOD` (`projection+cvodes-bdf`, `ggl+idas`,
  `baumgarte+cvodes-bdf`, `partitioning+cvodes-adams`); `--formulations projection,ggl`
  combines every method that names no formulation with each formulation. `index1-ode+METHOD`
  is the benchmark's own formulation: the constrained model's index-1 ODE (accelerations and
  multipliers from the augmented system, redundant constraints dropped, no stabilization;
  `index1-ode[baumgarte=(a b)]` adds it), given to any ODE method, e.g. scipy's DOP853, which
  `mechdsl.dae` does not offer; like `mechdsl.dae` it builds its system on every run. Options in
  brackets are passed to the simulator by name: `rk[dt=0.01]` (a fixed step: run once,
  not over the sweep), `baumgarte[baumgarte=(0 0)]+cvodes-bdf` (a tuple is written with
  spaces). Defaults: non-stiff models `erk,cvodes-adams,cvodes-bdf,scipy-dop853`; stiff ones
  (what `method = auto` calls stiff) `cvodes-bdf,rosenbrock,scipy-radau,erk`; constrained
  ones every formulation with its automatic integrator.
- **Default plan**: what is not given is chosen in proportion to the model and printed
  (`plan:` lines). The end time is the scene's stop time, else 10 s (as for `mech simulate`).
  A pilot run (the simulator's own method at 1e-6, stopped after 2 s of CPU) measures the
  cost of one run: up to 0.1 s, tolerances `1e-2..1e-10` one a decade and `--repeats`
  (default 3) timed runs; up to 1 s, `1e-3..1e-9` and one timed run; costlier models
  `1e-3..1e-8`, one timed run, and a horizon shortened (to 1, 2 or 5 x 10^k s) so that a
  run at 1e-6 costs about 1 s, or to half the time the pilot reached when it failed. Each
  run has a budget of 5 s of CPU and the whole sweep 25 s; the sweep goes tolerance by
  tolerance across the methods, so a spent budget cuts the tightest tolerances of every
  method (`skipped` rows say so). With defaults every shipped model finishes in about a
  minute; give `--t-end`, `--tolerances`, `--repeats` or `--budget` to choose yourself
  (with both `--t-end` and `--tolerances` there is no pilot and no sweep budget).
- **Tolerances** (`--tolerances`): a list `1e-3,1e-6`, a range in half decades
  `1e-2..1e-12` (21 values) or with k values a decade `1e-2..1e-12/4`. Each run
  uses rtol = atol = tolerance. Fixed-step methods take their step from the tolerance by
  the simulator's rule h omega = 0.5 tol^(1/order) (order 4 for `rk`, 5 for `collocation`,
  2 for Stormer-Verlet and the midpoint rule, 4 for Gauss-Legendre), shortened so that a
  whole number of steps falls into each output interval.
- **Reference** (`--reference`): a CSV in the format of `mech simulate -o` whose times lie
  on the output grid (equally spaced, ending at the stop time; a single row at the stop time
  is allowed), or `auto`: two runs at a tolerance two decades below the tightest of the
  sweep (within [1e-13, 1e-8]) with different methods (non-stiff: `scipy-dop853` and
  `erk`; stiff: `rosenbrock` and `scipy-radau`; constrained: `projection+cvodes-adams` and
  `ggl+idas`; `--reference-methods A,B` to choose). A method that fails is replaced by
  the next candidate (non-stiff `cvodes-adams`; stiff `cvodes-bdf`; constrained
  `projection+cvodes-bdf`, `baumgarte+cvodes-adams`), and when no two succeed the
  tolerance is loosened a decade at a time (at most twice, not above 1e-8); the runs not
  used are printed (`not used: ...`). When no pair succeeds (or a pair given with
  `--reference-methods` fails) it is a simulation error: `error[E880]` at the scene, exit 1.
  The first is the reference; the
  difference between the two is printed and drawn as its estimated accuracy, and errors
  within 3x of it are starred: the reference cannot resolve them. (scipy's Radau steps in
  Python: at 1e-12 on the stiff pendulum below it took over a minute; choose other methods or
  give a file when that matters.)
- **Errors** (`--compare`: `positions` = the coordinates (default), `states` = coordinates
  and speeds, or a list of outputs): relative per component, scaled by the component's
  largest magnitude over the reference; *final* = largest at the stop time, *L2* = root mean
  square over the reference times and components. **Invariants**: the energy (relative
  drift, conservative models), the first integrals the simulator records (cyclic momenta,
  Jacobi integral; absolute drift), quaternion norms, and for constrained models the largest
  constraint residual.
- **CPU time**: `time.process_time` (CPU seconds of the process, all threads: the
  CasADi integrators run in a worker thread), the minimum over `--repeats` runs after one
  warm-up run (one timed run when the warm-up took over 5 s). A run is a whole
  `simulate()` call: set-up after the warm-up, integration, and the recorded signals.
  A run longer than `--budget` CPU seconds (default 30 with given `--t-end` and
  `--tolerances`, else 5) ends its method's sweep; the tighter tolerances appear as `skipped`.
- **Failures** are rows with status `failed` (when and why), `n/a` (a combination the
  simulator refuses, e.g. a formulation on an unconstrained model), `error` or `skipped`:
  nothing is dropped. In the chart a failed run is a cross on the upper edge at its CPU time.
- **Output** (`-o DIR`): `bench.csv` (one row per run), `bench.json` (settings, reference,
  machine, every row), `work_precision.png` and `.svg` (error at the final time, L2 error
  and invariant drift against CPU time, log-log, one line per method). The table is printed,
  followed by the fastest run of each method that meets the error targets 1e-3, 1e-6, 1e-9.

Python: `mechdsl.bench` (`Setup.from_model`, `parse_variants`, `parse_tolerances`,
`run_bench`, `format_table`, `write_tables`, `write_chart`); design in
[internals/bench.md](internals/bench.md).
"""


def stability_section(cases):
    out = ["## The stability suite: where methods fail", "",
           "Each scene below is a `.mech` model (benchmarks/stability/ or models/) and a module of "
           "`benchmarks/stability/` that runs it, states what must fail and what must work, and checks it "
           "against an independent reference. The default test suite runs every case on a small size "
           "(tests/test_stability_*.py); these are the full sizes "
           "(`python benchmarks/stability/run.py`).", ""]
    for c in cases:
        out += [f"### {c.title}", "", (sys.modules[f"stability.{c.name}"].__doc__ or "").split("\n\n", 1)[-1].strip(),
                ""]
        for f in c.data.get("_files", []):
            if str(f).endswith(".png"):
                out += [f"![{c.title}](figures/{Path(f).name})", ""]
        out += ["```", *[ln[2:] if ln.startswith("  ") else ln for ln in c.table], "```", ""]
        out += [f"- **{'holds' if ch.holds else 'FAILS'}**: {ch.claim} ({ch.detail})" for ch in c.checks]
        out += ["", f"({c.data['_cpu']:.1f} s CPU)", ""]
    return "\n".join(out)


def page(ctx) -> str:
    m = ctx["machine"]
    parts = ["# Performance: speed against accuracy", "",
             "<!-- generated by benchmarks/make_performance.py: do not edit by hand -->", "",
             "How fast mechdsl integrates a model for a given accuracy, which methods to use, and where "
             "methods fail. Everything on this page was measured in one run of "
             f"`benchmarks/make_performance.py` ({ctx['total']:.0f} s wall, {ctx['total_cpu']:.0f} s CPU) on "
             f"{m['platform']}, {m['cpus']} cores, load average {m['load']} at the start "
             "(the machine is shared: CPU times are the minimum of repeated runs, and ratios between "
             "runs of the same chart are more reliable than absolute times).",
             f"Versions: {m['versions']}.", "", USAGE,
             "## Work-precision charts", "",
             "Error against CPU time, log-log, one line per method, one point per tolerance (loose to "
             "tight; the first and last are labelled). Left: relative error of the coordinates at the "
             "final time; middle: L2 error over the output grid; right: the drift of the energy. The "
             "dashed line is the estimated accuracy of the computed reference.", ""]
    wp = ctx["wp"]
    parts.append(wp_section("Double pendulum (chaotic), 10 s", wp["dp"], "wp_double_pendulum", ctx["figs"],
                            "models/double_pendulum.mech, scene Chaos, 10 s from the horizontal, 101 output "
                            "points. Non-stiff and chaotic: errors grow with time, so the final-time error is "
                            "the hard one.", data_dir=ctx["data"]))
    parts.append(wp_section("Stiff spring pendulum, 10 s", wp["stiff"], "wp_stiff_spring_pendulum", ctx["figs"],
                            "benchmarks/stability/stiff_spring_pendulum.mech: a spring mode decaying at 1e4/s "
                            "under a 2 s swing. The explicit methods' cost hardly depends on the tolerance: "
                            "their steps are set by stability.", data_dir=ctx["data"]))
    parts.append(wp_section("10-link chain, 5 s", wp["nlink"], "wp_nlink10", ctx["figs"],
                            "models/nlink_pendulum.mech with N = 10 (recursive route, CasADi virtual machine).",
                            data_dir=ctx["data"]))
    if ctx.get("andrews") is not None:
        holds, detail = ctx["andrews_check"]
        parts.append(wp_section("Andrews' squeezing mechanism (index-3 DAE), 0.03 s", ctx["andrews"],
                                "wp_andrews", ctx["figs"],
                                "models/andrews.mech against the Test Set for IVP Solvers' reference at t = 0.03 "
                                "(PSIDE at 1e-14; positions correct to about 1e-10, "
                                "tests/references/andrews_squeezer.json). Errors are relative, positions "
                                f"only. Check (7 correct digits faster than scipy DOP853): "
                                f"**{'holds' if holds else 'FAILS'}**: {detail}.",
                                targets=(1e-4, 1e-7, 1e-9), data_dir=ctx["data"]))
    else:
        parts.append("### Constrained models\n\nmechdsl.dae is not installed in this build: no DAE charts.\n")
    parts.append(stability_section(ctx["cases"]))
    parts += ["## Scaling with the number of links", "",
              "`benchmarks/nlink.py` (the N-rod chain of models/nlink_pendulum.mech): text to CasADi Function, "
              "one right-hand-side evaluation in the virtual machine and compiled, against Pinocchio's ABA "
              "(C++) and sympy.physics.mechanics, with the accuracy against both.", "", ctx["nlink"], "",
              "Simulating the chain for 5 s at rtol = atol = 1e-8 (virtual machine, CPU time, min of 3 "
              "after a warm-up):", "", ctx["simscale"], "", NLINK_RUN_TEXT, "", ctx["nlinkrun"], "",
              "### Chains as loops over per-link kernels", "", CHAIN_TEXT, "", ctx["chain"], ""]
    if ctx.get("contacts"):
        parts += ["## Contacts in the compiled loop", "", CONTACTS_TEXT, "", ctx["contacts"], ""]
    if ctx.get("export"):
        parts += ["## FMI export", "", EXPORT_TEXT, "", ctx["export"], ""]
    if ctx.get("coldstart"):
        parts += ["## Cold start", "", COLDSTART_TEXT, "", ctx["coldstart"], ""]
    if ctx.get("control"):
        parts += ["## Optimal control: cart-pole swing-up", "", CONTROL_TEXT, "", "```", *ctx["control"], "```", ""]
    return "\n".join(parts).rstrip() + "\n"


COLDSTART_TEXT = ("What a fresh `mech` process costs (issues 12 and 16). A run reads its model from the model "
                  "cache (mechdsl.eom.modelcache, docs/simulate.md) after the first: no parsing, analysis or "
                  "derivation, and neither lark nor the front end nor the mechanics are imported. Imports are "
                  "the sum of the top-level cumulative times of `python -X importtime`; numpy's is measured in "
                  "the same process (it then lacks the standard modules mechdsl imported first) and alone, "
                  "in a fresh `python -c \"import numpy\"` after each run; on a shared machine the steady "
                  "figure is each module's least self time over the runs, summed. Goals: imports < 2x numpy's "
                  "own import, `--version` and `check` well under 0.5 s, the 12-link "
                  "chain under 0.4 s warm and 1 s cold on an idle machine.")


CONTROL_TEXT = ("benchmarks/control_swingup.py: the swing-up of docs/control.md solved by IPOPT (exact "
                "Hessian) on a hand-written CasADi cart-pole (parameters as numbers) and on mechdsl's `ode`: "
                "with the parameters as the input p (`mechdsl`), built in (`fixed`: "
                "`m.casadi(fixed_parameters=True)`), compiled, and both; RK4 multiple shooting; the last row "
                "per N shoots on the simulator's own integrator (`m.integrator`, erk at rtol 1e-8, "
                "docs/control.md example 2). Side by side in one run, variants interleaved; CPU s = best "
                "CPU time (time.process_time) of the IPOPT solve, x hand = ratio to the hand-written "
                "model's; replay gap = max |x_replay - x_optimizer| over the grid when the optimal control "
                "is replayed through `m.simulate` (zero-order hold; rtol 1e-10, for the integrator row the "
                "OCP's own method and tolerances), exact gap = the same against a replay at rtol 1e-12. "
                "The RK4 rows' gaps are the optimizer's RK4 discretization error (h^4); the integrator "
                "row's replay gap is round-off. Goals (issue 13): at most 1.5x the hand-written time, the "
                "same iterations, the replay matching to the integrator tolerance.")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="short sweeps and small sizes (smoke test)")
    ap.add_argument("--docs", default=None, help="docs folder to write (default: docs/, or a temporary one "
                                                  "with --quick)")
    ap.add_argument("--no-nlink", action="store_true", help="leave out benchmarks/nlink.py")
    a = ap.parse_args(argv)
    docs = Path(a.docs) if a.docs else (Path(tempfile.mkdtemp(prefix="mechdsl-perf-")) if a.quick
                                        else ROOT / "docs")
    figs = docs / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    data = Path(tempfile.mkdtemp(prefix="mechdsl-perf-data-"))
    w0, c0 = time.perf_counter(), time.process_time()
    from mechdsl.output.result import versions

    v = versions()
    ctx = {"figs": figs, "data": data,
           "machine": {"platform": platform.platform(terse=True), "cpus": os.cpu_count(),
                       "load": ", ".join(f"{x:.2f}" for x in os.getloadavg()),
                       "versions": ", ".join(f"{k} {val}" for k, val in v.items())}}
    ctx["wp"] = work_precision(a.quick, figs)
    try:
        importlib.import_module("mechdsl.dae")
        ctx["andrews"] = andrews(a.quick, figs, data)
    except ImportError:
        ctx["andrews"] = None
    if ctx["andrews"] is not None:
        ctx["andrews_check"] = andrews_check(ctx["andrews"])
        log("andrews check: " + str(ctx["andrews_check"]))
    log("== stability suite")
    ctx["cases"] = run_cases(available_cases(), "small" if a.quick else "full", figs, log=log)
    ctx["nlink"] = "(left out: --no-nlink)" if a.no_nlink else nlink_table(a.quick)
    ctx["chain"] = "(left out: --no-nlink)" if a.no_nlink else chain_table(a.quick)
    log("== simulation cost against N")
    ctx["simscale"] = simulation_scaling(a.quick)
    ctx["nlinkrun"] = nlink_run_table(a.quick)
    ctx["contacts"] = contacts_table(a.quick)
    ctx["export"] = export_table(a.quick)
    log("== cold start")
    from coldstart import section as coldstart_section

    ctx["coldstart"] = coldstart_section(3 if a.quick else 5)
    from control_swingup import rows as control_rows

    ctx["control"] = list(control_rows([30, 60] if a.quick else [30, 60, 120], 1 if a.quick else 3))
    ctx["total"] = time.perf_counter() - w0
    ctx["total_cpu"] = time.process_time() - c0
    out = docs / "performance.md"
    text = page(ctx)
    if out.exists() and "generated by benchmarks/make_performance.py" not in out.read_text():
        print(f"{out} exists and was not generated by this script: not replaced", file=sys.stderr)
        return 2
    tmp = out.with_suffix(".md.tmp")
    tmp.write_text(text)
    os.replace(tmp, out)
    log(f"wrote {out} and figures in {figs} (tables in {data})")
    bad = [c.name for c in ctx["cases"] if not c.holds]
    if ctx.get("andrews_check") and not ctx["andrews_check"][0]:
        bad.append("andrews work-precision check")
    if bad:
        log("checks FAIL: " + ", ".join(bad))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
