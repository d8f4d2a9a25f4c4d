"""Sweeps (issue 14): designs, back ends, results and failures.  Each run of a sweep is
compared with the same run done alone through Model.simulate (an independent route: a
single integrator call, not a mapped one)."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import mechdsl
from mechdsl import sample
from mechdsl.diagnostics import UsageError
from mechdsl.sweep import first_time, table, to_frame

import xarray  # noqa: F401 - the test extra installs it
import mechdsl.examples

DP = """
model DP
  parameter Real m(unit = "kg") = 1;
  parameter Real l(unit = "m") = 1;
  parameter Real g(unit = "m/s2") = 9.81;
  Gravity gravity(g = {0, -g, 0});
  Rod rod1(m = m, L = l, axis = {0, -1, 0});
  Rod rod2(m = m, L = l, axis = {0, -1, 0});
  Revolute j1(parent = world, child = rod1.a, axis = {0, 0, 1}, phi(start = 1, speed = 0));
  Revolute j2(parent = rod1.b, child = rod2.a, axis = {0, 0, 1}, phi(start = 0, speed = 0));
  output Real y2(unit = "m") = rod2.b.y;
end DP;
"""


@pytest.fixture(scope="module")
def dp():
    return mechdsl.loads(DP)


def _alone(m, i, ds, method):
    vals = {n: float(ds[n].values[i]) for n in ds.attrs["swept"].split(",")}
    params = {k: v for k, v in vals.items() if not k.endswith((".start", ".speed"))}
    x0 = {k[:-6]: v for k, v in vals.items() if k.endswith(".start")}
    return m.with_params(**params).simulate(float(ds.attrs["t_end"]), x0=x0 or None, method=method,
                                            points=ds.sizes["time"])


def test_grid_runs_equal_single_runs_and_coordinates(dp):
    ds = dp.sweep(params={"l": [0.5, 1.5]}, starts={"j1.phi": [0.3, 1.0, 2.0]}, t_end=1.0, points=21,
                  progress=False)
    assert ds.sizes == {"run": 6, "time": 21}
    assert ds.attrs["scheduler"] == "vectorized" and ds.attrs["n_failed"] == 0
    assert list(ds["l"].values) == [0.5, 0.5, 0.5, 1.5, 1.5, 1.5]
    assert list(ds["j1.phi.start"].values) == [0.3, 1.0, 2.0] * 2
    for i in (0, 4, 5):
        r = _alone(dp, i, ds, ds.attrs["method"])
        assert r.success
        np.testing.assert_allclose(ds["j1.phi"].values[i], r.q[:, 0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(ds["y2"].values[i], r.signals["y2"], rtol=0, atol=1e-12)
        assert ds["energy_drift"].values[i] == pytest.approx(r.stats["energy_drift"], rel=1e-6, abs=1e-15)
    # physics: the energy at t=0 is the potential of the release position (closed form, l rods of mass m)
    l, phi = ds["l"].values, ds["j1.phi.start"].values
    E0 = -1.0 * 9.81 * (l / 2 * np.cos(phi) + (l * np.cos(phi) + l / 2 * np.cos(phi)))
    np.testing.assert_allclose(ds["energy"].values[:, 0], E0, rtol=1e-9)


def test_table_dataframe_and_sampler(dp):
    import pandas as pd
    t = dp.sweep(params=table({"m": [1.0, 2.0], "l": [1.0, 0.5]}), t_end=0.5, points=5, progress=False)
    assert t.sizes["run"] == 2 and list(t["l"].values) == [1.0, 0.5]
    f = dp.sweep(params=pd.DataFrame({"m": [1.0, 2.0], "l": [1.0, 0.5]}), t_end=0.5, points=5, progress=False)
    np.testing.assert_array_equal(f["j1.phi"].values, t["j1.phi"].values)
    s1 = sample.uniform({"l": (0.5, 1.5)}, n=5, seed=3) & sample.normal(m=(1, 0.1), n=5, seed=3)
    s2 = sample.uniform({"l": (0.5, 1.5)}, n=5, seed=3) & sample.normal(m=(1, 0.1), n=5, seed=3)
    np.testing.assert_array_equal(s1.table()["l"], s2.table()["l"])
    assert not np.array_equal(sample.uniform(l=(0.5, 1.5), n=5, seed=4).table()["l"], s1.table()["l"])
    assert ((s1.table()["l"] >= 0.5) & (s1.table()["l"] < 1.5)).all()
    ds = dp.sweep(params=s1, t_end=0.5, points=5, progress=False)
    np.testing.assert_array_equal(ds["m"].values, s1.table()["m"])
    long = to_frame(ds)
    assert len(long) == 5 * 5 and {"run", "time", "m", "l", "j1.phi", "success"} <= set(long.columns)


def test_processes_match_vectorized_bit_for_bit(dp):
    grid = {"j1.phi": [0.5, 1.5, 2.5], "j2.phi": [0.0, 1.0]}
    a = dp.sweep(starts=grid, t_end=1.0, points=11, progress=False)
    b = dp.sweep(starts=grid, t_end=1.0, points=11, progress=False, scheduler="processes", workers=2)
    assert b.attrs["scheduler"] == "processes"
    for v in ("j1.phi", "der(j2.phi)", "energy"):
        np.testing.assert_array_equal(a[v].values, b[v].values)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_dask_local_cluster_matches(dp):
    import distributed  # noqa: F401 - the test extra installs it
    grid = {"j1.phi": [0.5, 2.5]}
    a = dp.sweep(starts=grid, t_end=0.5, points=6, progress=False)
    b = dp.sweep(starts=grid, t_end=0.5, points=6, progress=False, scheduler="dask", workers=1)
    np.testing.assert_array_equal(a["j1.phi"].values, b["j1.phi"].values)


def test_failures_are_rows_with_time_and_cause(dp):
    ds = dp.sweep(starts={"j1.phi": [0.1, 3.0]}, t_end=5.0, points=11, max_steps=30, method="cvodes-bdf",
                  progress=False)
    assert ds.attrs["n_failed"] >= 1 and "failed" in ds.attrs["summary"]
    bad = ~ds["success"].values
    assert bad.sum() == ds.attrs["n_failed"]
    assert np.isfinite(ds["failure_time"].values[bad]).all()
    assert all(str(c) for c in ds["cause"].values[bad])
    i = int(np.flatnonzero(bad)[0])
    r = dp.simulate(5.0, x0={"j1.phi": float(ds["j1.phi.start"].values[i])}, points=11, max_steps=30,
                    method="cvodes-bdf")
    assert not r.success and r.failure.time == pytest.approx(float(ds["failure_time"].values[i]))


def test_invalid_runs_are_rows_not_errors(dp):
    ds = dp.sweep(params={"m": [1.0, -1.0]}, t_end=0.2, points=3, progress=False)
    assert list(ds["success"].values) == [True, False]
    assert ds["cause"].values[1] == "invalid run" and "mass" in str(ds["detail"].values[1]).lower()


def test_bad_input_is_a_clear_error(dp, tmp_path):
    with pytest.raises(UsageError, match="did you mean 'm'"):
        dp.sweep(params={"mm": [1, 2]}, t_end=1)
    with pytest.raises(UsageError, match="n must be an integer >= 1"):
        sample.uniform(m=(1, 2), n=0)
    with pytest.raises(UsageError, match="no values"):
        dp.sweep(params={"m": []}, t_end=1)
    out = tmp_path / "x.nc"
    with pytest.raises(UsageError, match="cannot reach the Dask scheduler"):
        dp.sweep(params={"m": [1, 2]}, t_end=1, scheduler="tcp://127.0.0.1:9", out=str(out), connect_timeout=1)
    assert list(tmp_path.iterdir()) == []          # nothing half-written
    with pytest.raises(UsageError, match="unknown scheduler"):
        dp.sweep(params={"m": [1, 2]}, t_end=1, scheduler="vectorised")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_integer_parameter_needs_processes():
    m = mechdsl.load(mechdsl.examples.path("nlink_pendulum"))
    with pytest.raises(UsageError, match="Integer/Boolean parameter"):
        m.sweep(params={"N": [2, 3]}, t_end=0.1, scheduler="vectorized")
    ds = m.sweep(params={"N": [2]}, t_end=0.1, points=3, progress=False, workers=1)
    assert ds.attrs["scheduler"] == "processes" and ds.attrs["n_failed"] == 0


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_streamed_file_equals_memory(dp, tmp_path):
    import xarray as xr
    import h5netcdf  # noqa: F401 - the test extra installs it
    grid = {"j1.phi": [0.5, 1.0, 1.5]}
    a = dp.sweep(starts=grid, t_end=0.5, points=6, progress=False)
    out = tmp_path / "s.nc"
    b = dp.sweep(starts=grid, t_end=0.5, points=6, progress=False, out=str(out), chunk_size=1)
    assert [p.name for p in tmp_path.iterdir()] == ["s.nc"]
    c = xr.open_dataset(out, engine="h5netcdf")
    for v in ("j1.phi", "energy", "success", "cause"):
        np.testing.assert_array_equal(a[v].values, c[v].values)
    assert b.attrs["summary"] == a.attrs["summary"]
    b.close()
    c.close()


def test_model_pickles_with_parameters_and_scene():
    m = mechdsl.loads(DP + "\nscene S\n  model DP;\n  stop_time = 2;\nend S;\n", scene="S").with_params(l=0.7)
    m2 = pickle.loads(pickle.dumps(m))
    assert m2.parameters == m.parameters and m2.scene_settings == m.scene_settings
    np.testing.assert_array_equal(m.simulate(points=5).q, m2.simulate(points=5).q)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_flip_map_example_small(tmp_path):
    from mechdsl.cli import main

    png, nc = tmp_path / "flip.png", tmp_path / "flip.nc"
    path = str(mechdsl.examples.path("double_pendulum"))
    code = main(["sweep", path, "--model", "DoublePendulum", "--grid", "j1.phi.start=-3:3:4", "--grid",
                 "j2.phi.start=-3:3:3", "--t-end", "2", "--points", "41", "-o", str(nc), "--plot", str(png),
                 "--metric", "flip:j2.phi"])
    assert code == 0 and png.stat().st_size > 1000
    import xarray as xr
    ds = xr.open_dataset(nc, engine="h5netcdf")
    ft = first_time(ds, ds["j2.phi"], np.pi)
    v = np.abs(ds["j2.phi"].values)
    for i in range(ds.sizes["run"]):           # independent check of the metric: a plain loop
        idx = [k for k in range(v.shape[1]) if v[i, k] > np.pi]
        assert (np.isnan(ft[i]) and not idx) or ft[i] == ds["time"].values[idx[0]]
    ds.close()


def test_cli_csv_and_exit_codes(tmp_path):
    from mechdsl.cli import main

    path = str(mechdsl.examples.path("double_pendulum"))
    out = tmp_path / "s.csv"
    assert main(["sweep", path, "--model", "DoublePendulum", "--grid", "m=1,2", "--t-end", "0.2",
                 "--points", "3", "-o", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert len(lines) == 1 + 2 * 3 and lines[0].startswith("run,time")
    assert main(["sweep", path, "--model", "DoublePendulum", "--t-end", "1"]) == 2
    assert main(["sweep", path, "--model", "DoublePendulum", "--uniform", "m=1:2", "--samples", "0"]) == 2


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_ctrl_c_keeps_finished_runs(dp, tmp_path, monkeypatch):
    from sweep_util import interrupt_at_chunk

    interrupt_at_chunk(monkeypatch, 3)
    out = tmp_path / "part.nc"
    ds = dp.sweep(starts={"j1.phi": [0.5, 1.0, 1.5, 2.0]}, t_end=0.2, points=3, chunk_size=1, progress=False,
                  out=str(out))
    assert ds.attrs["interrupted"] == 1 and ds.attrs["n_finished"] == 2
    assert list(ds["success"].values) == [True, True, False, False]
    assert list(ds["cause"].values[2:]) == ["not run", "not run"]
    assert np.isfinite(ds["j1.phi"].values[:2]).all() and np.isnan(ds["j1.phi"].values[2:]).all()
    assert [p.name for p in tmp_path.iterdir()] == ["part.nc"]
    ds.close()


def test_vectorized_refused_for_a_dae_with_the_reason():
    m = mechdsl.load(mechdsl.examples.path("four_bar"))
    with pytest.raises(UsageError, match="constraints"):
        m.sweep(params={m.parameter_names[0]: [1.0, 2.0]}, t_end=0.1, scheduler="vectorized")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_results_larger_than_the_memory_limit_must_stream(dp, tmp_path):
    with pytest.raises(UsageError, match="stream them to disk"):
        dp.sweep(params={"m": [1.0, 2.0]}, t_end=0.1, points=11, memory_limit=1000)
    ds = dp.sweep(params={"m": [1.0, 2.0]}, t_end=0.1, points=11, memory_limit=1000, out=str(tmp_path / "s.nc"),
                  progress=False)
    assert ds.attrs["n_failed"] == 0 and ds.sizes["run"] == 2
    ds.close()


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_basic_cli_does_not_import_the_sweep_libraries():
    import subprocess
    import sys

    code = ("import sys; from mechdsl.cli import main\n"
            "try:\n    main(['check', sys.argv[1]])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('xarray', 'pandas', 'dask', 'distributed', 'h5netcdf') if m in sys.modules))")
    path = str(mechdsl.examples.path("pendulum"))
    out = subprocess.run([sys.executable, "-c", code, path], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr


@pytest.mark.slow
def test_ctrl_c_on_the_process_pool_keeps_finished_runs(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    import xarray as xr
    path = str(mechdsl.examples.path("double_pendulum"))
    out = tmp_path / "s.nc"
    p = subprocess.Popen([sys.executable, "-m", "mechdsl", "sweep", path, "--model", "DoublePendulum", "--grid",
                          "j1.phi.start=0.1:3:4000", "--t-end", "20", "--points", "11", "--scheduler", "processes",
                          "--workers", "2", "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))   # even if we ignore it
    from mechdsl.sweep.journal import parts_folder

    t_end = time.time() + 600
    while not list(parts_folder(out).glob("chunk-*")) and time.time() < t_end and p.poll() is None:
        time.sleep(0.2)                        # until a chunk has finished
    os.killpg(p.pid, signal.SIGINT)            # as a terminal's Ctrl-C: the whole process group
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, stdout + stderr
    assert "interrupted" in stdout and "Traceback" not in stderr
    ds = xr.open_dataset(out, engine="h5netcdf")
    ok = ds["success"].values
    assert ds.attrs["interrupted"] == 1 and 0 < ok.sum() < 4000
    assert set(ds["cause"].values[~ok]) == {"not run"}
    ds.close()


def test_default_sweep_is_one_ensemble_call_of_the_stepping_loop(dp, monkeypatch):
    """Issue 24 item 5: method auto sweeps through the stepping loop (as a single run resolves
    auto), the whole chunk in one C call (crk_run_batch), each run bit-identical to the same
    run alone (same steps, same states)."""
    from mechdsl.simulation.backends import crk

    if crk.compiler() is None:
        pytest.skip("no C compiler: auto is erk in the virtual machine (the mapped integrator)")
    sizes = []
    batch = crk.run_batch
    monkeypatch.setattr(crk, "run_batch", lambda loop, method, grid, X0, *a: sizes.append(len(X0)) or
                        batch(loop, method, grid, X0, *a))
    ds = dp.sweep(params={"l": [0.5, 1.5]}, starts={"j1.phi": [0.3, 1.0, 2.0]}, t_end=1.0, points=21,
                  progress=False)
    assert ds.attrs["scheduler"] == "vectorized" and ds.attrs["method"] == "dop853" and sizes == [6]
    for i in range(6):
        r = _alone(dp, i, ds, None)
        assert r.metadata["method"] == "dop853"
        np.testing.assert_array_equal(ds["j1.phi"].values[i], r.q[:, 0])
        np.testing.assert_array_equal(ds["der(j2.phi)"].values[i], r.qd[:, 1])
        assert int(ds["steps"].values[i]) == r.stats["steps"] and int(ds["rhs_evals"].values[i]) == r.stats["rhs_evals"]


def test_a_run_failing_in_the_ensemble_is_rerun_alone_with_its_cause(dp):
    from mechdsl.simulation.backends import crk

    if crk.compiler() is None:
        pytest.skip("no C compiler")
    # max_steps bounds the steps between two output times: 2 points, 60 steps for 5 s
    ds = dp.sweep(starts={"j1.phi": [0.1, 3.0]}, t_end=5.0, points=2, max_steps=60, rtol=1e-10, method="dop853",
                  progress=False)
    bad = ~ds["success"].values
    assert bad.any() and bad.sum() == ds.attrs["n_failed"]
    i = int(np.flatnonzero(bad)[0])
    r = dp.simulate(5.0, x0={"j1.phi": float(ds["j1.phi.start"].values[i])}, points=2, max_steps=60, rtol=1e-10,
                    method="dop853")
    assert not r.success and r.failure.time == pytest.approx(float(ds["failure_time"].values[i]))
    assert str(ds["cause"].values[i]) == r.failure.cause


def test_a_large_models_chunks_compile_once_they_have_paid(dp, monkeypatch, tmp_path):
    """The vectorized sweep of a model interpreted in the stepping loop (above COMPILE_OPS)
    counts its chunks' interpreted evaluations like single runs do (payback.py): once they have
    paid for the compile, the next chunks run compiled, with the same bits."""
    from mechdsl.simulation.backends import crk, payback

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))          # a count of its own
    kw = dict(params={"l": [0.5, 0.8, 1.1, 1.4, 1.7, 2.0]}, t_end=1.0, points=11, method="dop853",
              chunk_size=2, progress=False, scheduler="vectorized")
    compiled = dp.sweep(**kw)
    engines = []
    batch = crk.run_batch

    def spy(loop, *a, **k):
        engines.append(loop.engine)
        return batch(loop, *a, **k)
    monkeypatch.setattr(crk, "run_batch", spy)
    monkeypatch.setattr(crk, "COMPILE_OPS", 0)
    monkeypatch.setattr(payback, "PAYBACK_EVALS", 1)          # the first chunk pays
    paid = dp.sweep(**kw)
    assert engines == ["interpreted", "compiled", "compiled"]
    assert paid.attrs["n_failed"] == 0
    for name in ("j1.phi", "j2.phi", "y2"):
        assert np.array_equal(paid[name].values, compiled[name].values)
