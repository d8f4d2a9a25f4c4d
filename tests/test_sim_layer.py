"""The one simulation layer (mechdsl.simulation): settings, problem, what ran, statistics,
accuracy report, non-finite results, no global side effects.  Each test failed before the
layer existed (project issue 12, failures 2-5 and 7; issue 18)."""
from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import mechdsl
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError
from mechdsl.simulate import simulate
from conftest import needs_cc
from sim_models import pendulum
import mechdsl.examples

MODELS = mechdsl.examples.folder()
SCHEMA = ("steps", "rhs_evals", "jac_evals", "rejected_steps", "events", "points", "cpu_time", "wall_time",
          "energy_drift", "energy_drift_relative", "invariant_drift", "constraint_drift")


def _four_bar_with_scene(tmp_path, settings: str) -> Path:
    text = (MODELS / "four_bar.mech").read_text()
    path = tmp_path / "fb.mech"
    path.write_text(text + f"\nscene Custom\n  model FourBar;\n  stop_time = 0.5;\n{settings}\nend Custom;\n")
    return path


# ------------------------------------------------------------------ failure 2: metadata names what ran


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_partitioning_runs_the_method_it_names():
    """Partitioning used to integrate with CVODES BDF whatever the method, labelled 'CasADi erk'."""
    m = mechdsl.load(MODELS / "four_bar.mech")
    erk = m.simulate(0.3, formulation="partitioning", method="erk", points=31, error_estimate="off")
    bdf = m.simulate(0.3, formulation="partitioning", method="cvodes-bdf", points=31, error_estimate="off")
    assert erk.success and bdf.success
    assert erk.metadata["run"]["integrator"] == "casadi:erk" and erk.metadata["run"]["method"] == "erk"
    assert bdf.metadata["run"]["integrator"] == "casadi:cvodes" and bdf.metadata["run"]["method"] == "bdf"
    # two different integrators at the same tolerance: close, but not the same numbers
    assert not np.array_equal(erk.q, bdf.q)
    np.testing.assert_allclose(erk.q, bdf.q, atol=1e-5)
    auto = m.simulate(0.3, formulation="partitioning", points=31)
    assert auto.metadata["run"]["integrator"] == "casadi:cvodes" and "CVODES" in auto.metadata["method"]


@pytest.mark.parametrize("file, kw, problem, integrator", [
    ("double_pendulum.mech", {"method": "scipy-dop853"}, "ode", "scipy:DOP853"),
    ("double_pendulum.mech", {"method": "rk4", "dt": 0.01}, "canonical", "mechdsl:rk4"),
    ("pendulum_cartesian.mech", {"formulation": "ggl"}, "dae", "casadi:idas"),
    ("bouncing_ball.mech", {"compiled": False}, "hybrid", "scipy:DOP853"),
])
def test_every_run_says_what_ran(file, kw, problem, integrator):
    r = mechdsl.load(MODELS / file).simulate(0.5, points=11, **kw)
    run = r.metadata["run"]
    assert run["problem"] == problem and run["integrator"] == integrator
    for key in ("formulation", "method", "rtol", "atol", "compiled", "settings"):
        assert key in run
    assert run["rtol"] == r.metadata["run"]["settings"]["rtol"]


# ------------------------------------------------------------------ failure 3: CLI = API for a scene


def test_cli_honours_scene_formulation_reactions_and_matches_the_api(tmp_path, capsys):
    path = _four_bar_with_scene(tmp_path, '  formulation = "ggl";\n  reactions = true;\n  points = 26;')
    out = tmp_path / "r.csv"
    assert main(["simulate", str(path), "--scene", "Custom", "-o", str(out), "--no-progress"]) == 0
    meta = json.loads((tmp_path / "r.json").read_text())["metadata"]
    assert meta["formulation"] == "ggl" and meta["run"]["integrator"] == "casadi:idas"
    api = mechdsl.load(path, scene="Custom").simulate()
    assert api.metadata["run"] == meta["run"]
    api_meta = json.loads(api.to_json_text())["metadata"]
    for key in ("source", "target", "scene"):           # said by the command only
        meta.pop(key, None)
    assert api_meta == meta
    header = out.read_text().splitlines()[0].split(",")
    assert header == api.columns                       # reactions recorded by both
    assert any(c.startswith("lambda") or "F_close" in c for c in header)
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 1:1 + len(api.coordinates)], api.q, rtol=0, atol=1e-12)


def test_cli_formulation_option_overrides_the_scene(tmp_path, capsys):
    path = _four_bar_with_scene(tmp_path, '  formulation = "ggl";\n  points = 11;')
    assert main(["simulate", str(path), "--scene", "Custom", "--formulation", "baumgarte", "--no-progress"]) == 0
    assert "formulation baumgarte" in capsys.readouterr().out


# ------------------------------------------------------------------ failure 4 and 7: one statistics schema


@pytest.mark.slow_cases('pendulum_cartesian.mech-kw2')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("file, kw", [
    ("double_pendulum.mech", {}),
    ("pendulum_cartesian.mech", {}),
    ("pendulum_cartesian.mech", {"formulation": "partitioning"}),
    ("bouncing_ball.mech", {}),
    ("double_pendulum.mech", {"method": "stormer-verlet", "dt": 0.01}),
])
def test_every_run_has_the_same_statistics_and_invariant_drift(file, kw):
    r = mechdsl.load(MODELS / file).simulate(0.5, points=11, **kw)
    for key in SCHEMA:
        assert key in r.stats
    assert isinstance(r.stats["steps"], int) and r.stats["steps"] > 0
    assert r.stats["energy_drift"] is not None and r.stats["energy_drift"] >= 0
    E = r["energy"]
    change = float(np.abs(E - E[0]).max())
    if r.metadata["run"]["problem"] == "hybrid":     # contacts: the drift between events (impacts dissipate)
        assert r.stats["energy_drift"] <= change
    else:
        assert r.stats["energy_drift"] == pytest.approx(change, rel=1e-12, abs=1e-300)


def test_dae_summary_prints_steps_and_energy_drift(capsys):
    assert main(["simulate", str(MODELS / "pendulum_cartesian.mech"), "--t-end", "0.5", "--points", "11",
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "steps" in out and "energy drift" in out and "constraint drift" in out


@pytest.mark.parametrize("file", ["double_pendulum.mech", "pendulum_cartesian.mech", "bouncing_ball.mech"])
def test_one_tolerance_rule_for_every_model(file):
    with pytest.raises(UsageError, match="double precision"):
        mechdsl.load(MODELS / file).simulate(0.5, rtol=1e-15)


def test_rk4_is_reachable_from_the_api_and_the_cli(capsys):
    """docs/analysis.md documents rk4; it was refused with 'unknown method'."""
    r = mechdsl.load(MODELS / "double_pendulum.mech").simulate(1.0, method="rk4", dt=0.001, points=11)
    ref = mechdsl.load(MODELS / "double_pendulum.mech").simulate(1.0, rtol=1e-12, atol=1e-12, points=11)
    assert r.success and r.metadata["run"]["method"] == "rk4"
    np.testing.assert_allclose(r.q, ref.q, atol=1e-8)      # order 4 at h = 1e-3
    assert main(["simulate", str(MODELS / "double_pendulum.mech"), "--t-end", "0.2", "--method", "rk4",
                 "--dt", "0.01", "--no-progress"]) == 0


# ------------------------------------------------------------------ failure 5: no global stderr swap


def _slow_pendulum_run(**kw):
    """A run that lasts at least 0.2 s whatever the machine: the pendulum's right-hand side
    sleeps 1 ms per call (rk, 50 steps of 4 calls)."""
    import time

    import casadi as ca

    from mechdsl.eom.codegen import casadi_functions

    class Slow(ca.Callback):
        def __init__(self, f):
            ca.Callback.__init__(self)
            self.f = f
            self.construct("slow_ode", {})

        def get_n_in(self):
            return 4

        def get_n_out(self):
            return 1

        def get_sparsity_in(self, i):
            return self.f.sparsity_in(i)

        def get_sparsity_out(self, i):
            return self.f.sparsity_out(i)

        def eval(self, args):
            time.sleep(0.001)
            return [self.f(*args)]

    e = pendulum()
    slow = Slow(casadi_functions(e, names=("ode",))["ode"])
    r = simulate(e, 1.0, method="rk", dt=0.02, points=11, functions={"ode": slow}, **kw)
    del slow
    return r


def test_output_of_other_code_during_a_run_is_not_swallowed(capsys):
    """run_casadi replaced sys.stderr for the whole process while a run went on: a progress
    callback's (or any other thread's) messages vanished into the integrator's buffer."""
    said = []

    def progress(t, t1):
        if t < t1 and not said:          # during the run, not after it
            print("progress message", file=sys.stderr)
            said.append(t)

    assert _slow_pendulum_run(progress=progress).success
    assert said and "progress message" in capsys.readouterr().err


def test_concurrent_runs_leave_stderr_as_it_was():
    original = sys.stderr
    barrier = threading.Barrier(2)
    results = []

    def work():
        barrier.wait()
        results.append(_slow_pendulum_run())

    threads = [threading.Thread(target=work) for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert sys.stderr is original
    assert len(results) == 2 and all(r.success for r in results)
    np.testing.assert_array_equal(results[0].q, results[1].q)     # deterministic under threads


# ------------------------------------------------------------------ issue 18: times and counts


@pytest.mark.parametrize("args, text", [
    (["--t-start=-1e308"], "times must lie within"),
    (["--points", "1e308"], "points"),
    (["--points", "10000000"], "budget"),
    (["--method", "rk4", "--dt", "1e-12"], "budget"),
])
def test_absurd_times_and_counts_are_usage_errors(args, text, capsys):
    code = main(["simulate", str(MODELS / "heavy_top.mech"), "--t-end", "1", "--no-progress", *args])
    err = capsys.readouterr().err
    assert code == 2 and text in err and "Traceback" not in err


@pytest.mark.parametrize("setting, text", [
    ("start_time = -1e308;", "times must lie within"),
    ("points = 1e308;", "too large to be a count"),
    ("points = 100000000;", "budget"),
    ("dt = 1e-12;", "budget"),
])
def test_absurd_scene_settings_are_located_model_errors(tmp_path, capsys, setting, text):
    """Values written in the scene: E604 at the scene (exit 1); the same values given as
    options are usage errors (exit 2, test_a_scene_value_over_a_budget_is_a_located_model_error)."""
    src = (MODELS / "heavy_top.mech").read_text()
    key = setting.split(" ")[0]
    lines = [ln for ln in src.splitlines() if not ln.strip().startswith(f"{key} =")]
    path = tmp_path / "top.mech"
    path.write_text("\n".join(lines).replace("stop_time = 2;", f"stop_time = 2;\n  {setting}") + "\n")
    code = main(["simulate", str(path), "--scene", "Spin", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1 and "error[E604]: scene setting" in err and text in err and "Traceback" not in err


def test_budget_can_be_raised():
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    with pytest.raises(UsageError, match="budget"):
        m.simulate(0.01, points=200, budget=100)
    assert len(m.simulate(0.01, points=200, budget=1000).t) == 200


def test_non_finite_results_fail_with_time_and_coordinate(monkeypatch):
    """A back end that returns inf/nan without noticing: the run fails at the first such
    time, names the coordinate and keeps the results before it."""
    import mechdsl.simulation.backends.fixed_step as symp
    from mechdsl.output.result import Result

    def broken(eom, s, progress=None, step_eom=None):
        t = np.linspace(0.0, s.t_end, 6)
        q = np.zeros((6, eom.n))
        q[3:, 0] = np.nan
        return Result(t=t, q=q, qd=np.zeros((6, eom.n)), coordinates=tuple(eom.coords),
                      signals={"energy": np.zeros(6)}, metadata={"method": "rk4"})

    monkeypatch.setattr(symp, "fixed_step_run", broken)
    r = simulate(pendulum(), 1.0, method="rk4", dt=0.1)
    assert not r.success and r.failure.time == pytest.approx(0.6)
    assert "theta" in r.failure.detail
    assert len(r.t) == 3 and np.isfinite(r.q).all() and len(r["energy"]) == 3


# ------------------------------------------------------------------ accuracy report and error estimate


def test_drift_warning_when_the_result_is_worse_than_the_tolerance():
    """The fixed-step rk (CasADi) with a coarse dt: energy drifts far beyond rtol."""
    r = mechdsl.load(MODELS / "double_pendulum.mech").simulate(5.0, method="rk", dt=0.05, rtol=1e-10,
                                                               atol=1e-10, points=51)
    assert any("energy should stay constant" in w for w in r.metadata["warnings"])
    good = mechdsl.load(MODELS / "double_pendulum.mech").simulate(1.0, rtol=1e-10, atol=1e-10, points=51)
    assert not any("should stay constant" in w for w in good.metadata["warnings"])


def test_error_estimate_against_the_actual_error():
    """estimate_error: the difference to a run at a 100x tighter tolerance is close to the
    actual error (against a run at rtol 1e-13)."""
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    r = m.simulate(3.0, rtol=1e-6, atol=1e-8, points=31, estimate_error=True, method="cvodes-adams")
    ref = m.simulate(3.0, rtol=1e-13, atol=1e-13, points=31, method="cvodes-adams")
    est = r.metadata["error_estimate"]["max_abs_difference"]
    for j, c in enumerate(r.coordinates):
        actual = float(np.abs(r.q[:, j] - ref.q[:, j]).max())
        assert actual > 0
        assert 0.5 * actual <= est[c] <= 2.0 * actual
    assert "x2" in est


# ------------------------------------------------------------------ the problem


def test_problem_dump_is_deterministic_and_names_the_formulation(tmp_path, capsys):
    path = _four_bar_with_scene(tmp_path, '  formulation = "ggl";')
    args = ["compile", str(path), "--scene", "Custom", "--emit", "problem"]
    assert main(args) == 0
    first = capsys.readouterr().out
    assert main(args) == 0
    assert capsys.readouterr().out == first
    assert "kind: dae" in first and "formulation: ggl" in first and "constraints: " in first
    assert "invariants: energy" in first and "inputs: none" in first


def test_first_integral_search_is_cached_on_disk(tmp_path, monkeypatch):
    """The search runs once per model and parameter values; a later process reads it back."""
    import mechdsl.analysis.integrals as integrals

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    first = mechdsl.load(MODELS / "heavy_top.mech").simulate(0.2, points=11, method="erk")
    assert "p_tip.phi" in first.signals and list((tmp_path / "integrals").iterdir())

    searches = []
    monkeypatch.setattr(integrals, "integral_signals", lambda *a, **k: searches.append(1) or {})
    again = mechdsl.load(MODELS / "heavy_top.mech").with_params(m=1.0).simulate(0.2, points=11, method="erk")
    assert not searches
    np.testing.assert_array_equal(again["p_tip.phi"], first["p_tip.phi"])
    other = mechdsl.load(MODELS / "heavy_top.mech").with_params(m=2.0)
    other.simulate(0.2, points=11, method="erk")       # other parameter values: a new search
    assert searches == [1]


def test_estimate_error_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "e.csv"
    assert main(["simulate", str(MODELS / "double_pendulum.mech"), "--t-end", "1", "--points", "11", "--rtol", "1e-6",
                 "--estimate-error", "-o", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "error estimate (max difference to a run at rtol = 1e-08" in text and "j1.phi:" in text
    est = json.loads((tmp_path / "e.json").read_text())["metadata"]["error_estimate"]["max_abs_difference"]
    assert 0 < est["j1.phi"] < 1e-3


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_simulate_imports_only_what_it_needs(tmp_path):
    """Cold start: an ODE run loads neither the benchmark, contact, DAE nor analysis packages
    (bench alone cost ~0.6 s of a 1.35 s run)."""
    import subprocess

    code = ("import sys\nfrom mechdsl.cli import main\n"
            f"main(['simulate', {str(MODELS / 'double_pendulum.mech')!r}, '--t-end', '0.1', '--no-progress'])\n"
            "print(sorted(m for m in ('mechdsl.bench', 'mechdsl.impacts', 'mechdsl.dae', 'mechdsl.output.plot', "
            "'matplotlib', 'scipy.optimize') if m in sys.modules))\n")
    env = {**__import__("os").environ, "MECHDSL_CACHE": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_settings_refuse_bad_values_for_every_model():
    from mechdsl.dae.dae_run import FORMULATIONS
    from mechdsl.simulation.registry import FORMULATIONS as KNOWN

    assert tuple(FORMULATIONS) == KNOWN
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    for kw, text in ((dict(formulation="nonsense"), "unknown formulation"), (dict(outputs=5), "list of names"),
                     (dict(points="abc"), "points"), (dict(estimate_error="yes"), "true or false")):
        with pytest.raises(UsageError, match=text):
            m.simulate(0.1, **kw)


@needs_cc
def test_cli_honours_scene_compiled(tmp_path, capsys):
    text = (MODELS / "double_pendulum.mech").read_text()
    path = tmp_path / "dp.mech"
    path.write_text(text + "\nscene Fast\n  model DoublePendulum;\n  stop_time = 0.2;\n  points = 11;\n"
                           "  compiled = true;\nend Fast;\n")
    out = tmp_path / "dp.csv"
    assert main(["simulate", str(path), "--scene", "Fast", "-o", str(out), "--no-progress"]) == 0
    meta = json.loads((tmp_path / "dp.json").read_text())["metadata"]
    assert meta["run"]["compiled"] is True and meta["options"]["compiled"] is True


@pytest.mark.slow_cases('heavy_top.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("file", ["pendulum.mech", "bouncing_ball.mech", "heavy_top.mech"])
def test_cli_and_api_give_the_same_run_for_the_first_scene(file, tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert main(["simulate", str(MODELS / file), "-o", str(out), "--no-progress"]) == 0
    cli = json.loads((tmp_path / "r.json").read_text())["metadata"]
    api = mechdsl.load(MODELS / file).simulate()
    api_meta = json.loads(api.to_json_text())["metadata"]
    for key in ("source", "target", "scene"):
        cli.pop(key, None)
    assert api_meta == cli
    assert out.read_text() == api.to_csv_text()


def test_kinds_of_the_shipped_models():
    """The golden problem dumps (tests/golden/*.problem.txt, checked by test_golden.py) name
    the kind each shipped model's default run solves."""
    golden = Path(__file__).resolve().parent / "golden"
    kinds = {name: (golden / f"{name}.problem.txt").read_text().splitlines()[1].split()[1]
             for name in ("double_pendulum", "pendulum_cartesian", "bouncing_ball", "heavy_top")}
    assert kinds == {"double_pendulum": "ode", "pendulum_cartesian": "dae", "bouncing_ball": "hybrid",
                     "heavy_top": "canonical"}


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_problem_and_metadata_do_not_depend_on_what_ran_before(monkeypatch):
    """is_conservative answered None for large models until someone had built Q: the problem
    dump (and a run's metadata) changed with the order of calls in the process."""
    import mechdsl.api as api
    from mechdsl.simulation import dump

    monkeypatch.setattr(api, "_EOM_CACHE", {})          # a fresh derivation: Q not built yet
    m = mechdsl.load(MODELS / "nfourbar.mech")
    first = dump(m.problem(t_end=1.0))
    m.eom.Q                                              # noqa: B018 - what another caller may do
    assert dump(m.problem(t_end=1.0)) == first
    assert "invariants: energy" in first


def test_message_capture_is_per_thread_and_nests():
    from mechdsl.integrators import captured_messages

    original = sys.stderr
    seen = {}

    def worker():
        with captured_messages() as buf:
            print("from the worker", file=sys.stderr)
            with captured_messages() as inner:
                print("inner", file=sys.stderr)
            print("worker again", file=sys.stderr)
        seen["outer"], seen["inner"] = buf.getvalue(), inner.getvalue()

    th = threading.Thread(target=worker)
    th.start()
    th.join()
    assert seen == {"outer": "from the worker\nworker again\n", "inner": "inner\n"}
    assert sys.stderr is original


def test_bench_runs_rk4(capsys):
    assert main(["bench", str(MODELS / "double_pendulum.mech"), "--t-end", "0.5", "--methods", "rk4",
                 "--tolerances", "1e-4", "--repeats", "1"]) == 0
    rows = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("rk4 ")]
    assert rows and rows[0].rstrip().endswith("ok")


def test_threaded_runs_of_distinct_models_match_sequential_runs():
    files = ("double_pendulum.mech", "pendulum_cartesian.mech", "bouncing_ball.mech", "heavy_top.mech")
    models = [mechdsl.load(MODELS / f) for f in files]
    results: dict = {}

    def work(i):
        results[i] = models[i].simulate(0.3, points=7)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(files))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for i, m in enumerate(models):
        alone = m.simulate(0.3, points=7)
        np.testing.assert_array_equal(results[i].q, alone.q)
        np.testing.assert_array_equal(results[i]["energy"], alone["energy"])


def test_an_output_not_finite_at_the_start_is_refused_at_the_output(tmp_path):
    """E757 from check and simulate alike, located at the output's declaration."""
    text = (MODELS / "pendulum.mech").read_text()
    src = text.replace("end Pendulum;", "  output Real w = sqrt(-1 - cos(theta)*cos(theta));\nend Pendulum;", 1)
    path = tmp_path / "p.mech"
    path.write_text(src)
    with pytest.raises(mechdsl.MechError) as e:
        mechdsl.load(path, model="Pendulum").simulate(0.2, points=5)
    assert e.value.first.code == "E757" and "output 'w'" in e.value.first.message
    line = src.splitlines().index("  output Real w = sqrt(-1 - cos(theta)*cos(theta));") + 1
    assert e.value.first.span.line == line


def test_an_output_that_becomes_nan_fails_the_run_at_that_time(tmp_path):
    """w = sqrt(sin(theta)) for the pendulum released at rest from theta = pi/2: theta reaches 0
    after a quarter period, sqrt(L/g) K(1/sqrt(2)) = 0.5920 s (closed form), and w is nan from
    there on.  The run fails at the first output time after that, names w, keeps what came before,
    and its CSV has no nan."""
    from scipy.special import ellipk

    text = (MODELS / "pendulum.mech").read_text()
    src = text.replace("end Pendulum;", "  output Real w = sqrt(sin(theta));\nend Pendulum;", 1)
    path = tmp_path / "p.mech"
    path.write_text(src)
    m = mechdsl.load(path, model="Pendulum")
    L, g = m.parameters["L"], abs(m.parameters.get("g", 9.81))
    quarter = np.sqrt(L / g) * ellipk(0.5)
    r = m.simulate(1.0, points=101)
    assert not r.success and r.failure.cause == "non-finite output" and "w became nan" in r.failure.detail
    assert quarter < r.failure.time <= quarter + 0.01 + 1e-12
    assert len(r.t) >= 59 and r.t[-1] < quarter and np.isfinite(r["w"]).all()
    r.to_csv(tmp_path / "p.csv")
    assert "nan" not in (tmp_path / "p.csv").read_text()


@pytest.mark.parametrize("file, kw, text", [
    ("bouncing_ball.mech", {"dt": 0.01, "reactions": True}, "a contact problem: dt = 0.01, reactions = True"),
    ("heavy_top.mech", {"max_steps": 10}, "a fixed-step problem: max_steps = 10"),
    ("double_pendulum.mech", {"rest_speed": 1.0}, "an ODE problem: rest_speed = 1.0"),
])
def test_settings_without_effect_are_noted(file, kw, text):
    """They used to be dropped silently by the contact and fixed-step drivers."""
    r = mechdsl.load(MODELS / file).simulate(0.2, points=5, **kw)
    assert any(text in n for n in r.metadata["notes"])


def test_no_error_estimate_below_the_precision_floor(capsys):
    """At rtol = 1e-13 the 'tighter' run would be clamped to the same 1e-14 floor... or below
    it: an estimate of 0 would be a silent wrong answer; it says why there is none instead."""
    r = mechdsl.load(MODELS / "double_pendulum.mech").simulate(0.2, rtol=1e-13, atol=1e-13, points=5,
                                                               estimate_error=True)
    assert r.metadata["error_estimate"]["unavailable"] and not r.metadata["error_estimate"]["max_abs_difference"]


def test_a_scene_value_over_a_budget_is_a_located_model_error(tmp_path, capsys):
    """A scene's dt = 1e-320 (found by the pipeline fuzzer) was a usage error (exit 2) from
    simulate and passed check: it is the model's value, so it is E604 at the scene, from check
    and simulate alike; the same value given with --dt stays a usage error, and --dt given on
    the command line overrides the scene's bad value."""
    from mechdsl.cli import main

    src = (MODELS / "heavy_top.mech").read_text()
    assert "  dt = 0.002;" in src
    path = tmp_path / "top.mech"
    path.write_text(src.replace("  dt = 0.002;", "  dt = 1e-320;"))
    for cmd in (["check", str(path)], ["simulate", str(path)]):
        assert main(cmd) == 1
        err = capsys.readouterr().err
        assert "error[E604]: scene setting dt" in err and f"{path}:" in err
    assert main(["simulate", str(path), "--dt", "0.01", "--t-end", "0.05"]) == 0
    capsys.readouterr()
    assert main(["simulate", str(MODELS / "heavy_top.mech"), "--dt", "1e-320"]) == 2
