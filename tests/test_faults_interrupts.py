"""Issue 25, item 1: every command stops on the first Ctrl-C within a second or two, exits 130
and keeps what finished: animate (the frames drawn so far), bench (the rows measured), and
simulate on every back end (the results up to the interruption).  Sweeps: test_faults_sweep.py.

Each case runs ``mech`` in a child process (its own process group) and sends SIGINT to the
group, as a terminal does, at a point the child reports.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from conftest import MODELS, needs_cc

# the child: ``mech ARGS`` with a hook that sends Ctrl-C to the process group when HOOK fires;
# prints the exit code and the seconds from the signal to the end on its last line
CHILD = textwrap.dedent(r"""
    import json, os, signal, sys, time
    hook, args = sys.argv[1], sys.argv[2:]
    state = {}

    def ctrl_c():
        if "t" not in state:
            state["t"] = time.perf_counter()
            os.killpg(os.getpgrp(), signal.SIGINT)

    if hook == "frames":                       # after the 10th frame drawn
        from mechdsl.animate import writer
        images = writer._images
        def counted(stage):
            for k, im in enumerate(images(stage)):
                if k == 10:
                    ctrl_c()
                yield im
        writer._images = counted
    elif hook == "rows":                       # during the second measured run
        from mechdsl.bench import runner
        measure = runner.measure_run
        calls = []
        def measured(*a, **k):
            calls.append(1)
            if len(calls) == 2:
                import threading
                threading.Timer(0.5, ctrl_c).start()
            return measure(*a, **k)
        runner.measure_run = measured
    elif hook.startswith("cpu:"):              # once the run itself has used this much CPU time
        import threading
        import mechdsl.simulation as S
        simulate = S.simulate
        def watch(start):
            while time.process_time() - start < float(hook[4:]):
                time.sleep(0.05)
            ctrl_c()
        def timed(*a, **k):
            threading.Thread(target=watch, args=(time.process_time(),), daemon=True).start()
            return simulate(*a, **k)
        S.simulate = timed
    from mechdsl.cli import main
    try:
        code = main(args)
    except KeyboardInterrupt:
        code = "KeyboardInterrupt"
    print(json.dumps({"code": code, "latency": time.perf_counter() - state["t"] if "t" in state else None}))
""")


def run_child(tmp_path, hook, *args, timeout=900):
    p = subprocess.Popen([sys.executable, "-c", CHILD, hook, *map(str, args)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True, cwd=tmp_path)
    stdout, stderr = p.communicate(timeout=timeout)
    last = json.loads(stdout.strip().splitlines()[-1])
    return last, stdout, stderr


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".gif", ".html"])
def test_animate_keeps_the_frames_drawn(tmp_path, suffix):
    out = tmp_path / f"a{suffix}"
    r, stdout, stderr = run_child(tmp_path, "frames", "animate", MODELS / "double_pendulum.mech", "--model",
                                  "DoublePendulum", "--t-end", "10", "-o", out)
    assert r["code"] == 130, stdout + stderr
    assert r["latency"] < 5, r
    assert "Traceback" not in stderr and out.exists()
    assert "frames (interrupted)" in stdout
    if suffix == ".gif":
        from PIL import Image

        with Image.open(out) as im:
            assert 10 <= im.n_frames < 300


@pytest.mark.slow
def test_bench_keeps_the_rows_measured(tmp_path):
    out = tmp_path / "b"
    r, stdout, stderr = run_child(tmp_path, "rows", "bench", MODELS / "pendulum.mech", "--t-end", "200",
                                  "--methods", "erk,rk4", "--tolerances", "1e-4,1e-6,1e-8", "--repeats", "1",
                                  "-o", out, "--no-chart", "--quiet")
    assert r["code"] == 130, stdout + stderr
    assert r["latency"] < 10, r
    rows = json.loads((out / "bench.json").read_text())["rows"]
    assert any(row["status"] == "skipped" and "interrupted" in row["message"] for row in rows)
    assert any(row["status"] not in ("skipped",) for row in rows)


# ------------------------------------------------------------------ simulate, every back end

BACK_ENDS = [
    # (name, model file, extra args; a GGL segment spans 8 of 60 monitoring
    # intervals, 1333 s of this run: the columns its interrupted IDAS call wrote are kept)
    ("dae-projection", "four_bar.mech", ["--t-end", "1e4"]),
    ("dae-ggl", "four_bar.mech", ["--t-end", "1e4", "--formulation", "ggl"]),
    ("ode-erk", "double_pendulum.mech", ["--t-end", "1e4", "--method", "erk"]),
    ("ode-cvodes", "double_pendulum.mech", ["--t-end", "1e4", "--method", "cvodes-bdf"]),
    ("ode-scipy", "double_pendulum.mech", ["--t-end", "1e4", "--method", "scipy-dop853"]),
    # (the compiled loop does 1e4 s in under a second: a run long enough to be stopped)
    ("ode-compiled-loop", "double_pendulum.mech", ["--t-end", "1e6", "--method", "dop853"]),
    ("fixed-step", "double_pendulum.mech", ["--t-end", "1e4", "--method", "stormer-verlet", "--dt", "1e-4"]),
    ("rattle", "pendulum_cartesian.mech", ["--t-end", "1e4", "--method", "rattle", "--dt", "1e-4"]),
    ("contacts", "bouncing_ball.mech", ["--t-end", "1e4"]),
]


@pytest.mark.slow
@pytest.mark.parametrize("name, model, extra", BACK_ENDS, ids=[case[0] for case in BACK_ENDS])
def test_simulate_keeps_partial_results_on_every_back_end(tmp_path, name, model, extra):
    """Ctrl-C once the run has used 5 s of CPU: exit 130 within seconds, the results up to
    there written with a failure 'interrupted' in the sidecar."""
    out = tmp_path / "r.csv"
    short = [a if i == 0 or extra[i - 1] != "--t-end" else "0.01" for i, a in enumerate(extra)]
    subprocess.run([sys.executable, "-m", "mechdsl", "simulate", str(MODELS / model), *short, "--no-progress"],
                   capture_output=True, timeout=900)     # the caches warm: the run itself starts at once
    r, stdout, stderr = run_child(tmp_path, "cpu:5", "simulate", MODELS / model, *extra, "--no-progress",
                                  "--points", "100001", "--budget", "100000000", "-o", out)
    assert r["code"] == 130, stdout + stderr
    assert r["latency"] is not None and r["latency"] < 5, r
    assert "Traceback" not in stderr
    lines = out.read_text().splitlines()
    assert len(lines) > 2                                  # the rows up to the interruption
    side = json.loads(out.with_suffix(".json").read_text())
    assert "interrupted" in json.dumps(side.get("failure")), side.get("failure")


# ------------------------------------------------------------------ the same through the Python API (fast)

API_CASES = [
    # (method, extra settings, how long the run would take: long enough to be stopped after 0.3 s)
    ("erk", {}, 1e5),
    ("cvodes-bdf", {}, 1e5),
    ("scipy-dop853", {}, 1e5),
    pytest.param("dop853", {}, 1e8, marks=needs_cc),
    ("stormer-verlet", {"dt": 1e-3}, 1e5),
]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("method, extra, t_end", API_CASES)
def test_ctrl_c_through_the_api_keeps_the_solution_up_to_there(method, extra, t_end):
    """Model.simulate / mechdsl.simulate: Ctrl-C (here interrupt_main, as a terminal's SIGINT)
    raises RunInterrupted carrying the rows reached, failure 'interrupted'; those rows are the
    solution: the same as an uninterrupted run over the same output times, and energy-conserving."""
    import _thread
    import signal
    import threading

    import numpy as np

    from mechdsl.output.result import RunInterrupted
    from mechdsl.simulate import simulate
    from sim_models import pendulum

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:       # (a background test run ignores SIGINT)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    eom = pendulum()
    opts = dict(method=method, rtol=1e-10, atol=1e-10, points=int(min(t_end, 1e6)) + 1, budget=10**9, **extra)
    simulate(eom, 0.1, **{**opts, "points": 11, "error_estimate": "off"})   # build (and compile) first
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt) as info:
            simulate(eom, t_end, **opts)
    finally:
        timer.cancel()
    assert isinstance(info.value, RunInterrupted), type(info.value)
    r = info.value.result
    assert r.failure.cause == "interrupted" and r.metadata["interrupted"]
    k = len(r.t)
    assert 2 < k and r.t[-1] < t_end
    again = simulate(eom, float(r.t[-1]), **{**opts, "points": k, "error_estimate": "off"})   # the reference rows
    assert again.success
    assert np.allclose(again.t, r.t, rtol=1e-12, atol=1e-9)
    assert np.allclose(again.q, r.q, rtol=1e-6, atol=1e-6)
    E = r.signals["energy"]
    assert np.max(np.abs(E - E[0])) < 1e-3 * 9.81            # (m g L: the energy's scale; E(0) = 0)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_ctrl_c_in_a_contact_run_through_the_api():
    """The contact back end (free flight in the compiled loop or stepped in Python): the rows and
    events up to the interruption are kept."""
    import _thread
    import signal
    import threading

    import mechdsl
    from mechdsl.output.result import RunInterrupted

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    m = mechdsl.load(MODELS / "bouncing_ball.mech")
    m.simulate(0.1, points=11)
    timer = threading.Timer(1.0, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt) as info:
            m.simulate(1e4, points=10**6 + 1, budget=10**9)     # about 4 s (its resting phase's rows batched)
    finally:
        timer.cancel()
    assert isinstance(info.value, RunInterrupted), type(info.value)
    r = info.value.result
    assert r.failure.cause == "interrupted" and len(r.t) > 2 and r.t[-1] < 1e4
    gaps = [v for name, v in r.signals.items() if name.endswith(".gap")]
    assert gaps and all((g > -1e-6).all() for g in gaps)          # the ball never went through the floor


def test_ctrl_c_during_the_error_estimate_keeps_the_run_not_the_companion(monkeypatch):
    """A Ctrl-C that lands in the default error estimate's companion run (after the run itself
    ended): RunInterrupted carries the complete run (every output time, no failure), never the
    companion's partial rows on its coarser grid; the estimate is absent and says why."""
    import _thread
    import signal

    import mechdsl
    from mechdsl.output.result import RunInterrupted
    from mechdsl.simulation import estimate as E

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    m = mechdsl.load(MODELS / "double_pendulum.mech")
    real = E._companion_run

    def companion_with_ctrl_c(*args):
        _thread.interrupt_main()                   # the Ctrl-C arrives as the companion starts
        return real(*args)

    monkeypatch.setattr(E, "_companion_run", companion_with_ctrl_c)
    with pytest.raises(KeyboardInterrupt) as info:
        m.simulate(2.0, points=201)
    assert isinstance(info.value, RunInterrupted), type(info.value)
    r = info.value.result
    assert len(r.t) == 201 and r.t[-1] == pytest.approx(2.0, abs=1e-12) and r.failure is None
    assert r.metadata["interrupted"] and "error estimate" in r.metadata["interrupted_during"]
    acc = r.metadata["accuracy"]
    assert acc["error_estimate"] is None and "interrupted" in acc["error_estimate_unavailable"]
    monkeypatch.undo()
    again = m.simulate(2.0, points=201)              # the same run, uninterrupted
    assert again.q == pytest.approx(r.q, abs=1e-12)


def test_ctrl_c_while_mech_simulate_writes_finishes_the_files(monkeypatch, tmp_path, capsys):
    """A Ctrl-C that lands while `mech simulate` writes its CSV is held until the files are
    written: the CSV and its sidecar are complete, exit 130, and the run says so."""
    import _thread
    import signal

    import pandas as pd

    from mechdsl.cli import main
    from mechdsl.commands import simulate as S

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    real = S.write_outputs

    def write_with_ctrl_c(*a, **k):
        _thread.interrupt_main()                   # arrives as the writing starts
        import time
        time.sleep(0.05)                           # (delivered at the next bytecode)
        return real(*a, **k)

    monkeypatch.setattr(S, "write_outputs", write_with_ctrl_c)
    out = tmp_path / "run.csv"
    code = main(["simulate", str(MODELS / "pendulum.mech"), "--t-end", "1", "--points", "101", "-o", str(out)])
    assert code == 130
    assert len(pd.read_csv(out)) == 101 and (tmp_path / "run.json").is_file()
    assert "interrupted" in capsys.readouterr().err
