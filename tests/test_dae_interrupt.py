"""Ctrl-C stops a constrained run promptly (issue 18): before, CasADi took the interrupt
inside its solvers (IDAS' residual, the partitioned right-hand side's rootfinder) or as an
integrator failure that the driver retried, and the run went on to the end with success.

Scenario: IFToMM A01 (Cartesian pendulum, g = 9.81, released at rest horizontally) over
400 s at rtol = atol = 1e-12, 401 points (seconds of work); a thread calls
_thread.interrupt_main() 0.3 s into the run.
"""
import _thread
import signal
import threading
import time
import warnings

import numpy as np
import pytest

from dae_models import pendulum_eom, pendulum_exact
from mechdsl.dae import RunInterrupted, simulate_dae


@pytest.mark.slow_cases('partitioning', 'projection')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("formulation", ["projection", "baumgarte", "ggl", "partitioning"])
def test_ctrl_c_stops_a_constrained_run_and_keeps_partial_results(formulation):
    eom = pendulum_eom(gravity=9.81, v0=(0.0, 0.0))
    # a test run started in the background inherits an ignored SIGINT, and interrupt_main()
    # does nothing then: give this test Python's own handler, as in a terminal
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate_dae(eom, 0.5, points=3, formulation=formulation)      # build the integrators first
        timer = threading.Timer(0.3, _thread.interrupt_main)
        timer.start()
        t0 = time.perf_counter()
        try:
            with pytest.raises(KeyboardInterrupt) as info:
                simulate_dae(eom, 400.0, rtol=1e-12, atol=1e-12, points=401, formulation=formulation)
        finally:
            timer.cancel()
    waited = time.perf_counter() - t0
    assert isinstance(info.value, RunInterrupted)
    r = info.value.result
    assert r.failure.cause == "interrupted" and r.metadata["interrupted"]
    assert 0.0 <= r.t[-1] < 400.0 and waited < 60.0
    # what was kept is the solution (against the exact elliptic-function solution)
    x, y = pendulum_exact(r.t)
    tol = 1e-3 if formulation == "baumgarte" else 1e-6
    assert np.all(np.isfinite(r.q)) and np.max(np.hypot(r["x"] - x, r["y"] - y)) < tol
    # the run leaves Python's own Ctrl-C handler in place
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_sigint_to_a_process_stops_the_run():
    """A real SIGINT (as Ctrl-C in a terminal) to a process in a long GGL run (IDAS, where
    CasADi lost the interrupt inside the residual callback)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    tests = Path(__file__).resolve().parent
    code = (
        "import sys, warnings\n"
        f"sys.path.insert(0, {str(tests)!r})\n"
        "warnings.simplefilter('ignore')\n"
        "from dae_models import pendulum_eom\n"
        "from mechdsl.dae import RunInterrupted, simulate_dae\n"
        "eom = pendulum_eom(gravity=9.81, v0=(0.0, 0.0))\n"
        "simulate_dae(eom, 0.5, points=3, formulation='ggl')\n"
        "print('ready', flush=True)\n"
        "try:\n"
        "    r = simulate_dae(eom, 400.0, rtol=1e-12, atol=1e-12, points=401, formulation='ggl')\n"
        "    print('finished', r.t[-1], flush=True)\n"
        "except RunInterrupted as e:\n"
        "    print('interrupted', e.result.t[-1], e.result.failure.cause, flush=True)\n"
        "    sys.exit(130)\n")
    # SIG_DFL in the child even when this test run ignores SIGINT (started in the background):
    # Python then installs its own Ctrl-C handler there, as in a terminal
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert p.stdout.readline().strip() == "ready"
        time.sleep(0.3)
        os.kill(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, (out, err)
    word, t_last, cause = out.split(maxsplit=2)
    assert word == "interrupted" and float(t_last) < 400.0 and cause.strip() == "interrupted"


@pytest.mark.slow
def test_sigint_to_mech_simulate_writes_partial_results_and_exits_130(tmp_path):
    """`mech simulate` of a constrained scene stopped by SIGINT: exit 130, the CSV holds the
    results up to the interrupt (main: the run went on to the end and exited 0)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from conftest import MODELS

    out = tmp_path / "a01.csv"
    # A01 over 20000 s at 1e-12: ~40 s of integration after about a second of start-up
    p = subprocess.Popen([sys.executable, "-m", "mechdsl", "simulate", str(MODELS / "pendulum_cartesian.mech"),
                          "--scene", "A01", "--t-end", "20000", "--points", "20001", "--no-progress", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        time.sleep(6.0)                            # loaded, derived, integrating
        os.kill(p.pid, signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, (stdout, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr
    rows = [ln for ln in out.read_text().splitlines() if ln and not ln.startswith("#")]
    assert 2 <= len(rows) - 1 < 20001                  # header + the points reached
    assert "interrupted" in stdout                      # the summary names the failure
