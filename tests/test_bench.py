"""mech bench: method specifications, error norms, references, the sweep, the CLI.

The physics check uses the closed-form motion of the pendulum released from the horizontal
(tests/references/README.md, "Closed forms", a copy of ../shared/references): sin(theta/2) = k cd(w t | k^2),
k = sin(a/2), w = sqrt(g/L).
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.special import ellipj

import mechdsl
from mechdsl.bench import (
    Setup,
    parse_tolerances,
    parse_variants,
    read_csv,
    run_bench,
    to_csv_text,
    write_chart,
    write_tables,
)
from mechdsl.bench import measure
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError

from conftest import CHECKOUT, MODELS, REFERENCES

PENDULUM = MODELS / "pendulum.mech"
STIFF = CHECKOUT / "benchmarks" / "stability" / "stiff_spring_pendulum.mech"
T_END = 3.0
POINTS = 31


def exact_theta(t, a=np.pi / 2, g=9.81, L=1.0):
    k = np.sin(a / 2)
    sn, cn, dn, _ = ellipj(np.sqrt(g / L) * np.asarray(t), k * k)
    return 2 * np.arcsin(k * cn / dn)


def exact_csv(path, n=POINTS, t_end=T_END):
    t = np.linspace(0, t_end, n)
    lines = ["time,theta"] + [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, exact_theta(t))]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def setup():
    m = mechdsl.load(str(PENDULUM), scene="Swing")
    return Setup.from_model(m, t_end=T_END, points=POINTS, source=str(PENDULUM))


# --------------------------------------------------------------------------- specifications


def test_variants_and_formulations():
    v = parse_variants("erk, projection+cvodes-bdf, rk[dt=0.01], baumgarte[baumgarte=(0 0)]+idas")
    assert [x.label for x in v] == ["erk", "projection+cvodes-bdf", "rk[dt=0.01]", "baumgarte[baumgarte=(0 0)]+idas"]
    assert v[1].formulation == "projection" and v[1].method == "cvodes-bdf"
    assert v[2].fixed_dt == 0.01 and v[2].kwargs == {"dt": 0.01}
    assert v[3].kwargs == {"baumgarte": (0, 0), "formulation": "baumgarte"}
    crossed = parse_variants(["cvodes-bdf,ggl+idas"], ["projection,baumgarte"])
    assert [x.label for x in crossed] == ["projection+cvodes-bdf", "baumgarte+cvodes-bdf", "ggl+idas"]


@pytest.mark.parametrize("bad", ["", "erk,erk", "a+b+c", "rk[dt]", "rk[dt=1", "+erk"])
def test_bad_variants(bad):
    with pytest.raises(UsageError):
        parse_variants(bad)


def test_tolerances():
    default = parse_tolerances(None)
    assert len(default) == 21 and default[0] == pytest.approx(1e-2) and default[-1] == pytest.approx(1e-12)
    assert np.allclose(np.diff(np.log10(default)), -0.5)
    assert parse_tolerances("1e-4,1e-2,1e-4") == [1e-2, 1e-4]
    assert parse_tolerances("1e-3..1e-5/1") == [1e-3, 1e-4, 1e-5]
    assert len(parse_tolerances("1e-2..1e-6/4")) == 17
    for bad in ("2", "1e-16", "x", "1e-2..y", "1e-2..1e-4/0"):
        with pytest.raises(UsageError):
            parse_tolerances(bad)


# --------------------------------------------------------------------------- norms


def test_error_norms_by_hand():
    R = np.array([[1.0, -2.0], [2.0, 0.0], [4.0, 1.0]])
    Y = R + np.array([[0.0, 0.0], [0.4, 0.2], [-0.4, 0.1]])
    s = measure.component_scales({"a": R[:, 0], "b": R[:, 1]}, ["a", "b"])
    assert s.tolist() == [4.0, 2.0]
    e = measure.errors(Y, R, s)
    assert e["final"] == pytest.approx(0.1)                   # max(0.4/4, 0.1/2)
    assert e["l2"] == pytest.approx(np.sqrt((0.1 ** 2 + 0.1 ** 2 + 0.1 ** 2 + 0.05 ** 2) / 6))
    assert measure.component_scales({"z": np.zeros(3)}, ["z"]).tolist() == [1.0]


# --------------------------------------------------------------------------- references


def test_reference_csv_and_grid(tmp_path):
    ref = read_csv(exact_csv(tmp_path / "exact.csv"))
    n, idx = ref.grid_points(0.0)
    assert n == POINTS and idx.tolist() == list(range(POINTS))
    # a reference with only its last row: compare the final time on a 2-point grid
    (tmp_path / "last.csv").write_text(f"time,theta\n{T_END!r},{float(exact_theta(T_END))!r}\n")
    n, idx = read_csv(tmp_path / "last.csv").grid_points(0.0)
    assert n == 2 and idx.tolist() == [1]
    (tmp_path / "uneven.csv").write_text("time,theta\n0,1\n1,1\n3,1\n")
    with pytest.raises(UsageError):
        read_csv(tmp_path / "uneven.csv").grid_points(0.0)
    (tmp_path / "bad.csv").write_text("t,theta\n0,1\n")
    with pytest.raises(UsageError):
        read_csv(tmp_path / "bad.csv")


def test_simulate_csv_is_a_reference(tmp_path, setup):
    from mechdsl.simulate import simulate

    r = simulate(setup.eom, T_END, rtol=1e-10, atol=1e-10, points=POINTS)
    r.to_csv(tmp_path / "run.csv")
    ref = read_csv(tmp_path / "run.csv")
    assert np.array_equal(ref.values["theta"], r["theta"]) and "der(theta)" in ref.values


def test_errors_against_the_closed_form(tmp_path, setup):
    res = run_bench(setup, variants=parse_variants("erk,cvodes-bdf"), tolerances=[1e-4, 1e-8],
                    reference=exact_csv(tmp_path / "exact.csv"), repeats=1)
    assert [r.status for r in res.rows] == ["ok"] * 4
    for label in ("erk", "cvodes-bdf"):
        loose, tight = res.rows_of(label)
        assert tight.err_final < loose.err_final and tight.err_l2 < loose.err_l2
        assert tight.err_final < 1e-5 and tight.cpu > 0 and len(tight.cpu_runs) == 1
    # the error is what it says: recompute erk at 1e-8 by hand
    from mechdsl.simulate import simulate

    r = simulate(setup.eom, T_END, rtol=1e-8, atol=1e-8, method="erk", points=POINTS)
    th = exact_theta(r.t)
    scale = np.abs(th).max()
    assert res.rows_of("erk")[1].err_final == pytest.approx(abs(r["theta"][-1] - th[-1]) / scale, rel=1e-12)
    assert res.rows_of("erk")[1].err_l2 == pytest.approx(np.sqrt(np.mean(((r["theta"] - th) / scale) ** 2)), rel=1e-12)
    assert res.rows_of("erk")[1].invariants["energy"] == pytest.approx(r.stats["energy_drift_relative"])


def test_auto_reference_estimates_its_own_accuracy(setup):
    res = run_bench(setup, variants=parse_variants("erk"), tolerances=[1e-6], repeats=1)
    ref = res.reference
    assert ref.methods == ("scipy-dop853", "erk") and ref.tolerance == pytest.approx(1e-8, rel=1e-12)
    true_err = np.abs(ref.values["theta"] - exact_theta(ref.t)).max() / np.abs(exact_theta(ref.t)).max()
    est = ref.accuracy["final"]
    assert true_err < 1e-7 and 0 < est < 1e-6
    # the estimate is of the right order (within a factor 1000 of the true final error)
    final_true = abs(ref.values["theta"][-1] - exact_theta(T_END)) / np.abs(exact_theta(ref.t)).max()
    assert final_true < 1e3 * est + 1e-14


def test_failures_not_applicable_and_skipped_are_rows(tmp_path, setup):
    variants = parse_variants("projection+erk,erk,stormer-verlet")
    res = run_bench(setup, variants=variants, tolerances=[1e-3, 1e-5], reference=exact_csv(tmp_path / "e.csv"),
                    repeats=1, budget=0.0)
    by = {(r.label, r.tolerance): r for r in res.rows}
    assert by[("projection+erk", 1e-3)].status == "n/a" and "constraints" in by[("projection+erk", 1e-3)].message
    assert by[("erk", 1e-3)].status == "ok" and by[("erk", 1e-5)].status == "skipped"
    sv = by[("stormer-verlet", 1e-3)]
    assert sv.status == "ok" and sv.dt is not None and sv.err_final < 1e-2
    assert len(res.rows) == 5
    text = to_csv_text(res)
    assert text.count("\n") == 6 and ",skipped," in text and ",n/a," in text


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_failed_runs_are_shown(tmp_path):
    """The stiff spring pendulum: fixed-step RK4 with dt = 0.01 blows up (benchmarks/stability)."""
    m = mechdsl.load(str(STIFF), scene="Swing")
    st = Setup.from_model(m, t_end=0.1, points=11)     # RK4 fails at t = 0.03
    res = run_bench(st, variants=parse_variants("rk[dt=0.01],collocation[dt=0.01]"), tolerances=[1e-6], repeats=1)
    assert res.kind == "stiff" and res.reference.methods == ("rosenbrock", "scipy-radau")
    failed, ok = res.rows
    assert failed.status == "failed" and "t = " in failed.message and failed.cpu is not None
    assert failed.err_final is None and ok.status == "ok" and ok.err_final < 1e-6
    files = write_chart(res, tmp_path)
    assert all(p.stat().st_size > 1000 for p in files)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_outputs_written_atomically_and_rerun(tmp_path, setup):
    res = run_bench(setup, variants=parse_variants("erk,rk[dt=0.5]"), tolerances=[1e-4],
                    reference=exact_csv(tmp_path / "e.csv"), repeats=1)
    out = tmp_path / "out"
    files = write_tables(res, out) + write_chart(res, out)
    assert sorted(p.name for p in files) == ["bench.csv", "bench.json", "work_precision.png", "work_precision.svg"]
    meta = json.loads((out / "bench.json").read_text())
    assert meta["timer"] == "time.process_time" and meta["rows"][1]["dt"] == 0.5
    write_tables(res, out)                    # mechdsl's own outputs may be replaced without --force
    write_chart(res, out)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "bench.csv").write_text("my data\n")
    with pytest.raises(UsageError):
        write_tables(res, tmp_path / "mine")
    assert (tmp_path / "mine" / "bench.csv").read_text() == "my data\n"


# --------------------------------------------------------------------------- CLI


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_bench(tmp_path, capsys):
    out = tmp_path / "o"
    args = ["bench", str(PENDULUM), "--scene", "Swing", "--t-end", "2", "--points", "21", "--methods", "erk",
            "--methods", "cvodes-adams", "--tolerances", "1e-3,1e-6", "--repeats", "1", "-o", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "reference: auto: scipy-dop853" in text and "estimated accuracy" in text
    assert text.count("erk ") >= 2 and "cvodes-adams" in text and "wrote" in text
    rows = (out / "bench.csv").read_text().splitlines()
    assert rows[0].startswith("method,") and len(rows) == 5
    assert main(args + ["--no-chart"]) == 0   # re-run over its own outputs (charts: test_outputs_written...)


@pytest.mark.parametrize("extra", [["--tolerances", "3"], ["--methods", "erk+"], ["--repeats", "0"],
                                   ["--reference", "/nonexistent.csv"], ["--compare", "nosuch"]])
def test_cli_usage_errors(extra, capsys):
    args = ["bench", str(PENDULUM), "--scene", "Swing", "--t-end", "1", "--points", "11", "--methods", "erk",
            "--tolerances", "1e-3", "--repeats", "1", *extra]
    assert main(args) == 2
    assert "error" in capsys.readouterr().err


# --------------------------------------------------------------------------- constrained models


def test_constrained_bench_against_cash_reference(tmp_path):
    """J. Cash's index-3 pendulum (scene Cash): the published reference at t = 1
    (tests/references/pendulum_index3.json, accurate to ~1e-11), as a one-row CSV."""
    ref = json.loads((REFERENCES / "pendulum_index3.json").read_text())["reference_t1"]
    csv = tmp_path / "cash.csv"
    csv.write_text(f"time,plane.x,plane.y\n1.0,{float(ref['x'])!r},{float(ref['y'])!r}\n")
    m = mechdsl.load(str(MODELS / "pendulum_cartesian.mech"), scene="Cash")
    st = Setup.from_model(m)
    variants = parse_variants("ggl+idas,baumgarte+cvodes-adams,index1-ode+scipy-dop853,index1-ode+idas,ggl+erk")
    res = run_bench(st, variants=variants, tolerances=[1e-5, 1e-10], reference=csv, repeats=1)
    assert res.kind == "dae" and res.reference.t.tolist() == [1.0]
    by = {(r.label, r.tolerance): r for r in res.rows}
    for lab in ("ggl+idas", "baumgarte+cvodes-adams", "index1-ode+scipy-dop853", "index1-ode+idas"):
        loose, tight = by[(lab, 1e-5)], by[(lab, 1e-10)]
        assert loose.ok and tight.ok, (loose.message, tight.message)
        assert tight.err_final < 1e-7 and tight.err_final < loose.err_final
        assert "residual" in tight.invariants
    assert by[("ggl+erk", 1e-5)].status == "n/a"          # GGL is integrated by IDAS only
    # the unstabilized index-1 ODE lets the constraint drift more than the stabilized GGL form
    assert by[("index1-ode+scipy-dop853", 1e-5)].invariants["residual"] > by[("ggl+idas", 1e-5)].invariants["residual"]


# --------------------------------------------------------------------------- the default plan (issue 11)


def _pilot_result(success=True, t_fail=None):
    from types import SimpleNamespace

    failure = None if success else SimpleNamespace(time=t_fail, cause="integrator failure", detail="")
    return SimpleNamespace(success=success, failure=failure, t=np.array([0.0, t_fail or 0.0]))


def test_nice_below():
    from mechdsl.bench.plan import nice_below

    for x, want in [(0.318, 0.2), (7.0, 5.0), (1.0, 1.0), (0.0999, 0.05), (20.0, 20.0), (1999.0, 1000.0)]:
        assert nice_below(x) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("cost, level, t_end, repeats", [(0.01, "cheap", T_END, None), (0.5, "moderate", T_END, 1),
                                                         (30.0, "costly", 0.1, 1)])
def test_default_plan_is_proportionate_to_the_pilot(setup, monkeypatch, cost, level, t_end, repeats):
    from mechdsl.bench import plan as P

    monkeypatch.setattr(P, "pilot", lambda s, cap=P.PILOT_CAP: (cost, s.t_end, _pilot_result()))
    plan = P.default_plan(setup, t_end_given=False, tolerances_given=False, repeats_given=False, budget_given=False)
    assert plan.t_end == pytest.approx(t_end, rel=1e-12)          # 3 s x 1 s / 30 s = 0.1 s for the costly one
    assert plan.tolerances == P.TOLERANCES[level] and plan.repeats == repeats
    assert plan.budget == P.RUN_BUDGET and plan.sweep_budget == P.SWEEP_BUDGET
    text = "\n".join(plan.notes)
    assert level in text and ("horizon shortened to t = 0.1 (from 3)" in text) == (level == "costly")


def test_default_plan_ends_before_the_pilots_failure_and_keeps_what_is_given(setup, monkeypatch):
    from mechdsl.bench import plan as P

    monkeypatch.setattr(P, "pilot", lambda s, cap=P.PILOT_CAP: (0.01, 1.0, _pilot_result(False, 1.0)))
    plan = P.default_plan(setup, t_end_given=False, tolerances_given=True, repeats_given=True, budget_given=True)
    assert plan.t_end == pytest.approx(0.5, rel=1e-12)
    assert plan.tolerances is None and plan.repeats is None and plan.budget is None and plan.sweep_budget is None
    assert any("failed at t = 1" in n for n in plan.notes) and any("before the pilot's failure" in n for n in plan.notes)

    def no_pilot(*a, **k):
        raise AssertionError("no pilot when the end time and the tolerances are given")

    monkeypatch.setattr(P, "pilot", no_pilot)
    plan = P.default_plan(setup, t_end_given=True, tolerances_given=True, repeats_given=False, budget_given=False)
    assert plan.t_end == setup.t_end and plan.notes == []


def test_pilot_stops_at_its_cap():
    from mechdsl.bench.plan import pilot

    st = Setup.from_model(mechdsl.load(str(MODELS / "bouncing_ball.mech"), scene="Bounce"))
    cost, reached, result = pilot(st, cap=0.0)              # stopped at the first progress report
    assert result is None and 0 < reached < st.t_end and 0 < cost < 1e3


def test_sweep_budget_skips_the_remaining_runs(setup, tmp_path):
    res = run_bench(setup, variants=parse_variants("erk,cvodes-adams"), tolerances=[1e-3, 1e-6],
                    reference=exact_csv(tmp_path / "e.csv"), repeats=1, sweep_budget=0.0)
    # tolerance by tolerance: only the first run fits a budget of 0 s
    assert [(r.label, r.tolerance, r.status) for r in res.rows] == [
        ("erk", 1e-3, "ok"), ("erk", 1e-6, "skipped"), ("cvodes-adams", 1e-3, "skipped"),
        ("cvodes-adams", 1e-6, "skipped")]
    assert "budget of 0 s" in res.rows[-1].message


def test_no_stop_time_means_ten_seconds_as_for_simulate():
    """Before: a usage error demanding --t-end on the three models without a scene."""
    st = Setup.from_model(mechdsl.load(str(MODELS / "two_masses_spring.mech")))
    assert st.t_end == pytest.approx(10.0, rel=1e-15) and "t_end = 10 s" in st.notes[0]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_andrews_reference_falls_back_to_a_method_that_works(capsys):
    """Before: the automatic reference (ggl+idas at 1e-13) hit IDA_CONV_FAIL at t = 0.0115 and
    the bench ended with a usage error (exit 2).  Now the next candidate replaces it."""
    args = ["bench", str(MODELS / "andrews.mech"), "--methods", "projection+auto", "--tolerances", "1e-3,1e-11",
            "--repeats", "1"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "reference: auto: projection+cvodes-adams at rtol = atol = 1e-1" in out
    acc = re.search(r"estimated accuracy .*: final ([0-9.e+-]+)", out)
    assert acc and float(acc.group(1)) < 1e-6


def test_reference_candidates_replace_a_failing_method(setup, monkeypatch):
    """A candidate that cannot run is replaced by the next one, and the note says why."""
    from mechdsl.bench import reference as R

    monkeypatch.setattr(R, "auto_candidates", lambda kind, formulation=None: ("nosuch-method", "scipy-dop853", "erk"))
    res = run_bench(setup, variants=parse_variants("erk"), tolerances=[1e-4], repeats=1)
    ref = res.reference
    assert ref.methods == ("scipy-dop853", "erk") and ref.tolerance == pytest.approx(1e-8, rel=1e-12)
    assert len(ref.notes) == 1 and ref.notes[0].startswith("not used: nosuch-method at tolerance 1e-08: ")
    # against the closed form: the reference is accurate to its estimate
    t = np.linspace(0, T_END, POINTS)
    assert np.max(np.abs(ref.values["theta"] - exact_theta(t))) < 1e-4


def test_reference_tolerance_is_loosened_when_no_pair_succeeds(setup, monkeypatch):
    from mechdsl.bench import reference as R
    from mechdsl.bench import runner

    assert R.reference_ladder(1e-12) == [1e-12, 1e-11, 1e-10] and R.reference_ladder(1e-8) == [1e-8]
    real = runner.simulate_variant

    def fails_below_1e11(st, v, tol, *a, **k):
        if tol < 1e-11 and v.method in ("erk", "cvodes-adams"):
            raise UsageError(f"{v.method} refuses tolerances below 1e-11 here")
        return real(st, v, tol, *a, **k)

    monkeypatch.setattr(runner, "simulate_variant", fails_below_1e11)
    res = run_bench(setup, variants=parse_variants("scipy-dop853"), tolerances=[1e-10], repeats=1)
    assert res.reference.tolerance == pytest.approx(1e-11, rel=1e-12)          # one decade looser than 1e-12
    assert res.reference.methods == ("scipy-dop853", "erk")
    assert [n.split(":")[1].strip() for n in res.reference.notes] == ["erk at tolerance 1e-12",
                                                                         "cvodes-adams at tolerance 1e-12"]


BLOWUP = """model Blowup "pulled into a singular potential: x reaches 1 at t = pi/2 - 1"
  coordinate Real x(start = 0, speed = 1);
equation
  kinetic = 1/2*der(x)^2;
  potential = -1/(1 - x);
end Blowup;

scene Run "ten seconds"
  model Blowup;
  stop_time = 10;
end Run;
"""


def test_reference_that_no_method_computes_is_a_located_simulation_error(tmp_path, capsys):
    """Before: a usage error (exit 2).  A failed simulation is exit 1 with a coded diagnostic."""
    f = tmp_path / "blowup.mech"
    f.write_text(BLOWUP)
    assert main(["bench", str(f), "--t-end", "10", "--tolerances", "1e-3", "--methods", "erk"]) == 1
    err = capsys.readouterr().err
    assert f"{f}:8:1: error[E880]: cannot compute the automatic reference" in err
    assert "scipy-dop853 at tolerance 1e-08: failed at t = 0.5707" in err and "help:" in err


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_cli_bench_defaults_on_a_small_model(capsys):
    """mech bench with defaults: the plan is chosen and said (cart_pole: about a second of CPU)."""
    assert main(["bench", str(MODELS / "cart_pole.mech")]) == 0
    out = capsys.readouterr().out
    assert "plan: default plan for a model that is cheap" in out and "plan: methods: the default set" in out
    assert "reference: auto: scipy-dop853" in out and "t = 0 .. 3" in out


def test_a_run_is_stopped_after_its_cpu_seconds():
    """The default plan stops a run after STOP_AFTER s of CPU where the simulator reports
    progress (here: the bouncing ball's first output point)."""
    from mechdsl.bench.runner import measure_run

    st = Setup.from_model(mechdsl.load(str(MODELS / "bouncing_ball.mech"), scene="Bounce"))
    row = measure_run(st, parse_variants("erk")[0], 1e-6, st.points, None, None, ("drop.s",), 1, False,
                      stop_after=0.0)
    assert row.status == "skipped" and "stopped at t = " in row.message and "after 0 s" in row.message
    assert 0 < row.t_reached < st.t_end and row.cpu > 0


def test_reference_of_a_scene_formulation_comes_first():
    """A02's scene chooses `augmented` (the only formulation that crosses its singular
    configurations): the automatic reference tries that formulation before the default ones."""
    from mechdsl.bench import reference as R

    c = R.auto_candidates("dae", "augmented")
    assert c[:3] == ("augmented+cvodes-adams", "augmented+erk", "augmented+cvodes-bdf")
    assert "ggl+idas" in c and R.auto_candidates("ode", "augmented") == R.auto_candidates("ode")


def test_repeats_are_interleaved_across_the_variants(tmp_path, setup, monkeypatch):
    """run_bench times each variant once after its warm-up, then the other repeats round-robin
    across the variants of the tolerance (order reversed every other round): runs compared
    are measured side by side.  Each row keeps every timed run and their minimum; Row.ran is
    the method that ran (what auto chose)."""
    from mechdsl.bench import runner

    order = []
    plain = runner.simulate_variant

    def traced(st, variant, tol, *a, **k):
        order.append((variant.label, tol))
        return plain(st, variant, tol, *a, **k)

    monkeypatch.setattr(runner, "simulate_variant", traced)
    res = run_bench(setup, variants=parse_variants("auto,erk"), tolerances=[1e-4, 1e-6],
                    reference=exact_csv(tmp_path / "exact.csv"), repeats=3)
    assert [r.status for r in res.rows] == ["ok"] * 4
    for r in res.rows:
        assert len(r.cpu_runs) == 3 and r.cpu == min(r.cpu_runs)
    assert res.rows_of("erk")[0].ran == "erk" and res.rows_of("auto")[0].ran in ("dopri5", "dop853", "erk")
    # per tolerance: warm-up + one run each, then the two more rounds (reversed, then in order)
    a, e = ("auto", 1e-4), ("erk", 1e-4)
    assert order[:8] == [a, a, e, e, e, a, a, e]


def test_fast_rows_are_repeated_until_their_runs_add_up(tmp_path, setup):
    """min_total: a row whose timed runs add up to less gets more interleaved rounds than
    ``repeats`` (at most runner.MAX_ROUNDS)."""
    from mechdsl.bench.runner import MAX_ROUNDS

    res = run_bench(setup, variants=parse_variants("erk,rk[dt=0.01]"), tolerances=[1e-4],
                    reference=exact_csv(tmp_path / "exact.csv"), repeats=2, min_total=0.02)
    for r in res.rows:
        assert r.ok and len(r.cpu_runs) >= 2 and r.cpu == min(r.cpu_runs)
        assert sum(r.cpu_runs) >= 0.02 or len(r.cpu_runs) == MAX_ROUNDS + 1
