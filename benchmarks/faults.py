"""Faults and attacks (issue 25): try each one against ``mech`` and print a table.

    python benchmarks/faults.py [-k SUBSTRING] [--list]

A fault is something going wrong around a run (Ctrl-C, a killed worker or process, a damaged
cache, a full device, a redundant or absurd model); it is *survived* when mech ends cleanly
(exit 0, 1, 2 or 130 with one clear line, never a traceback or exit 3) within its time limit,
keeps what it finished, and never reports a wrong result as a good one.  An attack is input
meant to make mech run code or exhaust memory (a planted pickle or library, a foreign port);
it *held* when nothing ran and nothing blew up.  Every case runs ``mech`` (or a small driver)
in child processes with a fresh cache and a time limit; the columns are

    internal   exit code 3 or a Python traceback (a bug)
    hang       the time limit passed
    silent     a wrong or missing result reported as success (exit 0)
    outcome    what happened, in words

Exit code 0 when every fault was survived and every attack held.  Known gaps are listed as
'pending' with their reason (they fail until fixed elsewhere) and counted apart.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
DP = MODELS / "double_pendulum.mech"
PY = sys.executable


@dataclass
class Outcome:
    ok: bool
    text: str
    internal: bool = False
    hang: bool = False
    silent: bool = False


@dataclass
class Case:
    name: str
    kind: str            # fault | attack
    fn: object
    pending: str = ""    # a known gap: why it fails today


CASES: list[Case] = []


def case(kind, pending=""):
    def deco(fn):
        CASES.append(Case(fn.__name__.replace("_", " "), kind, fn, pending))
        return fn
    return deco


# --------------------------------------------------------------------------- helpers


class Run:
    def __init__(self, proc_result, seconds, timed_out):
        self.code, self.out, self.err = proc_result
        self.seconds, self.timed_out = seconds, timed_out

    @property
    def internal(self) -> bool:
        return self.code == 3 or "Traceback (most recent call last)" in self.err or "internal error" in self.err


def mech(work: Path, *args, timeout=600, env=None, stdout=None) -> Run:
    return run([PY, "-m", "mechdsl", *map(str, args)], work, timeout, env, stdout)


def run(cmd, work: Path, timeout=600, env=None, stdout=None) -> Run:
    e = dict(os.environ, MECHDSL_CACHE=str(work / "cache"))
    e.update(env or {})
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=work, env=e, stdout=stdout or subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
        return Run((p.returncode, out or "", err), time.perf_counter() - t0, False)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
        return Run((None, out or "", err), time.perf_counter() - t0, True)


def interrupted(work: Path, cmd, ready, timeout=900, env=None) -> tuple[Run, float | None]:
    """Run ``cmd``; when ``ready()`` is true, Ctrl-C its process group; (run, seconds to exit)."""
    e = dict(os.environ, MECHDSL_CACHE=str(work / "cache"))
    e.update(env or {})
    p = subprocess.Popen(cmd, cwd=work, env=e, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    lines: dict = {"out": [], "err": []}

    def read(stream, key):
        for line in stream:
            lines[key].append(line)

    readers = [threading.Thread(target=read, args=(s, k), daemon=True) for k, s in (("out", p.stdout),
                                                                                     ("err", p.stderr))]
    for t in readers:
        t.start()
    t_end = time.time() + timeout
    while p.poll() is None and not ready("".join(lines["err"])) and time.time() < t_end:
        time.sleep(0.1)
    latency = None
    if p.poll() is None and time.time() < t_end:
        os.killpg(p.pid, signal.SIGINT)
        t0 = time.perf_counter()
        try:
            p.wait(timeout=60)
            latency = time.perf_counter() - t0
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    elif p.poll() is None:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    for t in readers:
        t.join(10)
    return Run((p.returncode, "".join(lines["out"]), "".join(lines["err"])), 0.0, latency is None), latency


def parts(out: Path) -> bool:
    return any((out.parent / f".{out.name}.parts").glob("chunk-*"))


def children(pid: int) -> list[int]:
    """The process ids of ``pid``'s children (Linux /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().split(") ")[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def sweep_args(out, n=600, scheduler=None, t_end="30", extra=()):
    a = ["sweep", DP, "--model", "DoublePendulum", "--grid", f"j1.phi.start=0.1:3:{n}", "--t-end", t_end,
         "--points", "5", "-o", out, "--no-progress", *extra]
    return a + (["--scheduler", scheduler] if scheduler else [])


def small_sweep(work, out, values="0.1,0.2", t_end="0.5", *extra) -> Run:
    """A sweep of the double pendulum's start angle over ``values`` into ``out``."""
    return mech(work, "sweep", DP, "--model", "DoublePendulum", "--grid", f"j1.phi.start={values}", "--t-end", t_end,
                "--points", "5", "-o", out, "--no-progress", *extra)


def read_nc(path):
    import xarray as xr

    return xr.open_dataset(path, engine="h5netcdf")


def clean(r: Run, *codes) -> bool:
    return not r.internal and not r.timed_out and r.code in codes


# --------------------------------------------------------------------------- interrupts and workers


def _ctrl_c_sweep(work, scheduler):
    out = work / "s.nc"
    r, latency = interrupted(work, [PY, "-m", "mechdsl", *map(str, sweep_args(out, scheduler=scheduler))],
                             lambda err: parts(out))
    if latency is None:
        return Outcome(False, "did not stop within 60 s of Ctrl-C" if not r.internal else r.err[-200:],
                       internal=r.internal, hang=True)
    ds = read_nc(out)
    done, n = int(ds["success"].values.sum()), ds.sizes["run"]
    ok = clean(r, 130) and ds.attrs["interrupted"] == 1 and 0 < done < n and latency < 5
    return Outcome(ok, f"exit {r.code} {latency:.1f} s after Ctrl-C; {done} of {n} runs kept, the rest 'not run'",
                   internal=r.internal)


@case("fault")
def ctrl_c_vectorized_sweep(work):
    return _ctrl_c_sweep(work, None)


@case("fault")
def ctrl_c_process_pool_sweep(work):
    return _ctrl_c_sweep(work, "processes")


@case("fault")
def ctrl_c_dask_sweep(work):
    return _ctrl_c_sweep(work, "dask")


@case("fault")
def worker_killed_during_a_sweep(work):
    """SIGKILL to one worker of a processes sweep once its first chunk is stored."""
    out = work / "s.nc"
    e = dict(os.environ, MECHDSL_CACHE=str(work / "cache"))
    p = subprocess.Popen([PY, "-m", "mechdsl", *map(str, sweep_args(out, n=64, scheduler="processes",
                                                                          t_end="20", extra=("--workers", "2")))],
                         cwd=work, env=e, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    t_end = time.time() + 900
    while not parts(out) and p.poll() is None and time.time() < t_end:
        time.sleep(0.2)
    workers = [c for c in children(p.pid) if b"spawn" in Path(f"/proc/{c}/cmdline").read_bytes()]
    if workers:
        os.kill(workers[0], signal.SIGKILL)
    try:
        stdout, stderr = p.communicate(timeout=900)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        return Outcome(False, "hung after a worker was killed", hang=True)
    r = Run((p.returncode, stdout, stderr), 0, False)
    ds = read_nc(out)
    ok = clean(r, 0) and bool(ds["success"].values.all()) and bool(workers)
    return Outcome(ok, f"killed worker {workers[0] if workers else '?'}; exit {r.code}, "
                       f"{int(ds['success'].values.sum())} of {ds.sizes['run']} runs succeeded "
                       f"({'retried on a fresh worker' if 'worker' in ds.attrs.get('warnings', '') else 'no retry noted'})",
                   internal=r.internal)


KILLER = textwrap.dedent("""
    import os, signal, sys
    if os.environ.get("MECHDSL_FAULT_KILLER"):
        from mechdsl.sweep import runs
        _run = runs.run_chunk
        def run_chunk(job, first, values):
            if any(abs(x - 1.0) < 1e-12 for v in values.values() for x in v):
                os.kill(os.getpid(), signal.SIGKILL)
            return _run(job, first, values)
        runs.run_chunk = run_chunk
""")


@case("fault")
def a_run_that_always_kills_its_worker(work):
    site = work / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(KILLER)
    out = work / "s.nc"
    r = mech(work, "sweep", DP, "--model", "DoublePendulum", "--grid", "j1.phi.start=0.2,0.4,0.6,0.8,1.0,1.2,1.4,1.6",
             "--t-end", "0.2", "--points", "3", "--scheduler", "processes", "--workers", "2", "-o", out,
             "--no-progress", env={"PYTHONPATH": str(site), "MECHDSL_FAULT_KILLER": "1"})
    ds = read_nc(out)
    bad = ds["cause"].values[4]
    ok = clean(r, 1) and bad == "worker died" and int(ds["success"].values.sum()) == 7
    return Outcome(ok, f"exit {r.code}; the killing run is a row '{bad}' ({ds['detail'].values[4]}); the other 7 "
                       "succeeded", internal=r.internal, silent=r.code == 0)


KILL_DRIVER = textwrap.dedent(r"""
    import os, signal, sys
    import numpy as np, mechdsl
    from mechdsl.sweep import store
    put, n = store.Store.put, []
    def killing_put(self, c):
        put(self, c); n.append(1)
        if len(n) == 2:
            os.kill(os.getpid(), signal.SIGKILL)
    store.Store.put = killing_put
    mechdsl.load(sys.argv[1], model="DoublePendulum").sweep(starts={"j1.phi": np.linspace(0.1, 3, 12)}, t_end=0.5,
                                                            points=5, chunk_size=3, progress=False, out=sys.argv[2])
""")


@case("fault")
def sweep_killed_then_resumed(work):
    out = work / "s.csv"
    k = run([PY, "-c", KILL_DRIVER, str(DP), str(out)], work)
    left = sorted(p.name for p in work.iterdir() if p.name != "cache")
    r = small_sweep(work, out, "0.1:3:12", "0.5", "--resume")
    fresh = small_sweep(work, work / "fresh.csv", "0.1:3:12")
    import mechdsl.sweep

    a, b = mechdsl.sweep.read(out), mechdsl.sweep.read(work / "fresh.csv")
    same = bool((a["j1.phi"].values == b["j1.phi"].values).all())
    ok = k.code == -signal.SIGKILL and clean(r, 0) and clean(fresh, 0) and same and int(a.attrs["n_resumed"]) == 6
    return Outcome(ok, f"killed (left {', '.join(left)}); --resume kept {a.attrs['n_resumed']} runs, ran the rest; "
                       f"equal to a fresh sweep bit for bit: {same}", internal=r.internal)


@case("fault")
def leftovers_of_a_killed_sweep(work):
    out = work / "s.nc"
    run([PY, "-c", KILL_DRIVER, str(DP), str(out)], work)
    r = small_sweep(work, out)
    left = sorted(p.name for p in work.iterdir() if p.name != "cache")
    ok = clean(r, 0) and left == ["s.nc"]
    return Outcome(ok, f"next run without --resume: exit {r.code}, folder holds {left}", internal=r.internal)


@case("fault")
def resume_with_other_settings(work):
    out = work / "s.nc"
    small_sweep(work, out)
    r = small_sweep(work, out, "0.1,0.2", "0.6", "--resume")
    ok = clean(r, 2) and "settings" in r.err
    return Outcome(ok, f"exit {r.code}: {r.err.strip().splitlines()[-1][:110]}", internal=r.internal)


@case("fault")
def csv_and_sidecar_out_of_step(work):
    """A kill between the two renames: a new CSV beside an old sidecar."""
    out = work / "s.csv"
    small_sweep(work, out)
    side = out.with_suffix(".json").read_text()
    small_sweep(work, out, "0.3,0.4")
    out.with_suffix(".json").write_text(side)          # the old sidecar back beside the new CSV
    r = run([PY, "-c", "import sys, mechdsl.sweep as s\ntry:\n    s.read(sys.argv[1])\nexcept Exception as e:\n"
                       "    print(type(e).__name__, e)", str(out)], work)
    ok = "UsageError" in r.out and "does not match its sidecar" in r.out
    return Outcome(ok, r.out.strip()[:120], internal=r.internal, silent="UsageError" not in r.out)


@case("fault")
def replacing_a_big_output(work):
    """Memory to replace an own 200 MB CSV: the old file must not be read whole."""
    out = work / "r.csv"
    with open(out, "w") as f:
        f.write("time,x\n")
        row = "0.0,1.0\n" * 1_000_000
        for _ in range(25):
            f.write(row)
    out.with_suffix(".json").write_text('{"generator": "mechdsl"}\n')
    code = ("import resource, sys\nfrom mechdsl.output.fileio import check_writable\n"
            "a = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\ncheck_writable(sys.argv[1])\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - a)")
    r = run([PY, "-c", code, str(out)], work)
    grown = int(r.out.strip() or -1)
    return Outcome(clean(r, 0) and 0 <= grown < 20_000, f"{out.stat().st_size / 1e6:.0f} MB own CSV: replace check "
                   f"grew the memory by {grown} kB", internal=r.internal)


@case("fault")
def ctrl_c_animate(work):
    out = work / "a.gif"
    r, latency = interrupted(work, [PY, "-m", "mechdsl", "animate", str(DP), "--model", "DoublePendulum",
                                    "--t-end", "20", "-o", str(out)],
                             lambda err: any(work.glob(".a.gif.*")) and time.sleep(8) is None)
    ok = latency is not None and clean(r, 130) and out.exists() and latency < 5
    return Outcome(ok, f"exit {r.code}" + (f" {latency:.1f} s after Ctrl-C" if latency else "") + "; "
                   + (r.out.strip().splitlines()[-1][:100] if r.out.strip() else "no output"), internal=r.internal,
                   hang=latency is None)


@case("fault")
def ctrl_c_bench(work):
    out = work / "b"
    r, latency = interrupted(work, [PY, "-m", "mechdsl", "bench", str(MODELS / "pendulum.mech"), "--t-end", "300",
                                    "--methods", "erk,rk4", "--tolerances", "1e-4,1e-6,1e-8,1e-10", "--repeats", "1",
                                    "-o", str(out), "--no-chart"],
                             lambda err: err.count(" tol=") >= 2)      # two rows measured
    rows = json.loads((out / "bench.json").read_text())["rows"] if (out / "bench.json").exists() else []
    kept = sum(1 for x in rows if x["status"] != "skipped")
    ok = latency is not None and clean(r, 130) and kept > 0 and latency < 10
    return Outcome(ok, f"exit {r.code}" + (f" {latency:.1f} s after Ctrl-C" if latency else "")
                   + f"; {kept} rows measured kept, {len(rows) - kept} skipped", internal=r.internal,
                   hang=latency is None)


def _ctrl_c_simulate(work, model, *extra):
    out = work / "r.csv"
    short = [a if i == 0 or extra[i - 1] != "--t-end" else "0.01" for i, a in enumerate(extra)]
    mech(work, "simulate", model, *short, "--no-progress")            # warm caches
    t0 = [None]

    def ready(err):
        if t0[0] is None:
            t0[0] = time.time()
        return time.time() - t0[0] > 12
    r, latency = interrupted(work, [PY, "-m", "mechdsl", "simulate", str(model), *map(str, extra), "--no-progress",
                                    "--points", "100001", "--budget", "100000000", "-o", str(out)], ready)
    rows = len(out.read_text().splitlines()) - 1 if out.exists() else 0
    ok = latency is not None and clean(r, 130) and rows > 1 and latency < 5
    return Outcome(ok, f"exit {r.code}" + (f" {latency:.1f} s after Ctrl-C" if latency else " (no stop)")
                   + f"; {rows} rows written", internal=r.internal, hang=latency is None)


@case("fault")
def ctrl_c_simulate_dae(work):
    return _ctrl_c_simulate(work, MODELS / "four_bar.mech", "--t-end", "1e4")


@case("fault")
def ctrl_c_simulate_dae_ggl(work):
    return _ctrl_c_simulate(work, MODELS / "four_bar.mech", "--t-end", "1e4", "--formulation", "ggl")


@case("fault")
def ctrl_c_simulate_ode(work):
    return _ctrl_c_simulate(work, DP, "--t-end", "1e4", "--method", "erk")


@case("fault")
def ctrl_c_simulate_ode_cvodes(work):
    return _ctrl_c_simulate(work, DP, "--t-end", "1e4", "--method", "cvodes-bdf")


@case("fault")
def ctrl_c_simulate_ode_scipy(work):
    return _ctrl_c_simulate(work, DP, "--t-end", "1e4", "--method", "scipy-dop853")


@case("fault")
def ctrl_c_simulate_compiled_loop(work):
    return _ctrl_c_simulate(work, DP, "--t-end", "1e7", "--method", "dop853")


@case("fault")
def ctrl_c_simulate_fixed_step(work):
    return _ctrl_c_simulate(work, DP, "--t-end", "1e4", "--method", "stormer-verlet", "--dt", "1e-4")


@case("fault")
def ctrl_c_simulate_rattle(work):
    return _ctrl_c_simulate(work, MODELS / "pendulum_cartesian.mech", "--t-end", "1e4", "--method", "rattle",
                            "--dt", "1e-4")


@case("fault")
def ctrl_c_simulate_contacts(work):
    return _ctrl_c_simulate(work, MODELS / "bouncing_ball.mech", "--t-end", "1e4")


# --------------------------------------------------------------------------- caches


def _key(work, path) -> str:
    r = run([PY, "-c", f"import mechdsl; m = mechdsl.load({str(path)!r}); m.eom; print(m._cache.key)"], work)
    return r.out.strip().splitlines()[-1]


@case("fault")
def model_cache_entry_swapped(work):
    k1, k2 = _key(work, DP), _key(work, MODELS / "pendulum.mech")
    d = work / "cache" / "models"
    (d / f"{k1}.pkl").write_bytes((d / f"{k2}.pkl").read_bytes())
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress")
    ok = clean(r, 0) and "model DoublePendulum" in r.out
    return Outcome(ok, f"exit {r.code}: '{r.out.splitlines()[1][:60] if len(r.out.splitlines()) > 1 else ''}'",
                   internal=r.internal, silent="model Pendulum" in r.out)


@case("fault")
def model_cache_entry_truncated(work):
    k = _key(work, DP)
    p = work / "cache" / "models" / f"{k}.pkl"
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress")
    return Outcome(clean(r, 0) and "DoublePendulum" in r.out, f"exit {r.code}, entry rebuilt", internal=r.internal)


@case("fault")
def first_integrals_entry_damaged(work):
    args = ("--t-end", "0.05", "--points", "3", "--no-progress", "--method", "erk")
    mech(work, "simulate", MODELS / "heavy_top.mech", *args)
    outcomes = []
    for damage in ("empty", "garbage", "swapped"):
        (entry,) = [p for p in (work / "cache" / "integrals").iterdir() if p.stat().st_size > 0][:1] or [None]
        good = entry.read_bytes()
        if damage == "empty":
            entry.write_bytes(b"")
        elif damage == "garbage":
            entry.write_bytes(good[: len(good) // 2])
        else:
            mech(work, "simulate", MODELS / "pendulum.mech", *args)
            other = [p for p in (work / "cache" / "integrals").iterdir() if p != entry][0]
            entry.write_bytes(other.read_bytes())
        r = mech(work, "simulate", MODELS / "heavy_top.mech", *args, "-o", work / "t.csv", "--force")
        header = (work / "t.csv").read_text().splitlines()[0] if (work / "t.csv").exists() else ""
        outcomes.append((damage, clean(r, 0) and "p_tip.phi" in header and entry.read_bytes() == good, r.internal))
    return Outcome(all(o[1] for o in outcomes), ", ".join(f"{d}: {'rebuilt' if ok else 'NOT rebuilt'}"
                                                         for d, ok, _ in outcomes),
                   internal=any(o[2] for o in outcomes))


@case("fault")
def compiled_library_truncated(work):
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress", "--compiled")
    libs = list((work / "cache").glob("*.so"))
    if not libs:
        return Outcome(clean(r, 0), "no compiler: nothing compiled (the virtual machine ran)", internal=r.internal)
    libs[0].write_bytes(libs[0].read_bytes()[:1000])
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress", "--compiled")
    return Outcome(clean(r, 0) and "rebuilt" in r.out + r.err, f"exit {r.code}; "
                   + ("a note says rebuilt" if "rebuilt" in r.out + r.err else "no note"), internal=r.internal)


# --------------------------------------------------------------------------- models, inputs, environment


DOOR = (ROOT / "tests" / "test_faults_inputs.py").read_text().split('DOOR = """')[1].split('"""')[0]
GUIDES = (ROOT / "tests" / "test_faults_inputs.py").read_text().split('GUIDES = """')[1].split('"""')[0]


@case("fault")
def door_on_two_coaxial_hinges(work):
    (work / "door.mech").write_text(DOOR)
    r = mech(work, "simulate", "door.mech", "--t-end", "0.5", "--no-progress", "-o", "d.csv")
    return Outcome(clean(r, 0), f"exit {r.code}" + ("; simulated (dependent rows dropped)" if r.code == 0 else
                                                    ": " + r.err.strip()[-100:]), internal=r.internal)


@case("fault")
def block_on_two_identical_guides(work):
    (work / "g.mech").write_text(GUIDES)
    r = mech(work, "simulate", "g.mech", "--t-end", "1", "--points", "3", "--no-progress", "-o", "g.csv")
    last = (work / "g.csv").read_text().splitlines()[-1].split(",") if (work / "g.csv").exists() else ["", "nan"]
    ok = clean(r, 0) and abs(float(last[1]) - 4.905) < 1e-6
    return Outcome(ok, f"exit {r.code}; s(1) = {last[1]} (free fall: 4.905)", internal=r.internal,
                   silent=r.code == 0 and not ok)


@case("fault")
def planar_axis_1e32(work):
    text = (MODELS / "falling_rod.mech").read_text().replace("Planar fly(parent = world, child = rod, axis = {0, 0, 1},",
                                                             "Planar fly(parent = world, child = rod, axis = {1e32, 0, 1},")
    (work / "rod.mech").write_text(text)
    r = mech(work, "simulate", "rod.mech", "--no-progress", timeout=120)
    ok = clean(r, 1) and "error[E513]" in r.err and "rod.mech:" in r.err
    return Outcome(ok, f"exit {r.code} after {r.seconds:.1f} s: " + (r.err.strip().splitlines()[0][:100]
                                                                     if r.err.strip() else ""),
                   internal=r.internal, hang=r.timed_out)


@case("fault")
def start_time_minus_1e308(work):
    (work / "p.mech").write_text("model P\n  Rod rod(m = 1, L = 1, axis = {0, -1, 0});\n  Gravity g(g = {0, -9.81, 0});\n"
                                 "  Revolute j(parent = world, child = rod.a, axis = {0, 0, 1}, phi(start = 1));\nend P;\n"
                                 "scene S\n  model P;\n  start_time = -1e308;\nend S;\n")
    r = mech(work, "check", "p.mech")
    ok = clean(r, 1) and "p.mech:6:1: error[E604]" in r.err
    return Outcome(ok, f"exit {r.code}: {r.err.strip().splitlines()[0][:100]}", internal=r.internal)


@case("fault")
def output_name_of_300_characters(work):
    codes = []
    for cmd in (["simulate", MODELS / "pendulum.mech", "--t-end", "0.1", "--no-progress", "-o", "a" * 300 + ".csv"],
                ["sweep", MODELS / "pendulum.mech", "--grid", "m=1,2", "--t-end", "0.1", "--no-progress",
                 "-o", "a" * 300 + ".nc"],
                ["animate", MODELS / "pendulum.mech", "--t-end", "0.1", "-o", "a" * 300 + ".gif"]):
        r = mech(work, *cmd)
        codes.append((r.code, r.internal))
    ok = all(c == 2 and not i for c, i in codes)
    return Outcome(ok, f"exit codes {[c for c, _ in codes]} (usage errors: the name is too long)",
                   internal=any(i for _, i in codes))


@case("fault")
def standard_output_on_a_full_device(work):
    with open("/dev/full", "w") as full:
        r = mech(work, "check", MODELS / "pendulum.mech", stdout=full)
    ok = clean(r, 1) and "No space left on device" in r.err
    return Outcome(ok, f"exit {r.code}: {r.err.strip()[:80]}", internal=r.internal)


@case("fault")
def scheduler_that_is_not_listening(work):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()                                  # nothing listens there now
    r = mech(work, "sweep", MODELS / "pendulum.mech", "--grid", "m=1,2", "--t-end", "0.1", "--no-progress",
             "--scheduler", f"tcp://127.0.0.1:{port}")
    return Outcome(clean(r, 2), f"exit {r.code}: {r.err.strip()[:100]}", internal=r.internal)


@case("fault")
def scheduler_port_that_says_nothing(work):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    try:
        r = run([PY, "-c", "import sys, mechdsl\nm = mechdsl.load(sys.argv[1])\ntry:\n"
                 "    m.sweep(params={'m': [1.0, 2.0]}, t_end=0.1, scheduler=sys.argv[2], connect_timeout=3, "
                 "progress=False)\nexcept Exception as e:\n    print(type(e).__name__, e)",
                 str(MODELS / "pendulum.mech"), f"tcp://127.0.0.1:{s.getsockname()[1]}"], work, timeout=120)
    finally:
        s.close()
    ok = not r.timed_out and "UsageError" in r.out
    return Outcome(ok, f"{r.seconds:.1f} s: {r.out.strip()[:100]}", internal=r.internal, hang=r.timed_out)


# --------------------------------------------------------------------------- attacks


class Boom:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _plant_pickle(work, key, marker):
    from mechdsl.eom import modelcache

    payload = pickle.dumps(Boom(marker))
    path = work / "cache" / "models" / f"{key}.pkl"
    path.write_bytes(modelcache.header(key, payload) + payload)
    return path


@case("attack")
def pickle_in_a_cache_folder_others_can_write(work):
    marker = work / "pwned"
    k = _key(work, MODELS / "pendulum.mech")
    _plant_pickle(work, k, marker)
    os.chmod(work / "cache" / "models", 0o777)
    r = mech(work, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    ok = clean(r, 0) and not marker.exists() and "writable by other users" in r.err
    return Outcome(ok, ("code ran! " if marker.exists() else "nothing ran; ") + r.err.strip().splitlines()[0][:90]
                   if r.err.strip() else "no message", internal=r.internal)


@case("attack")
def pickle_entry_others_can_write(work):
    marker = work / "pwned"
    k = _key(work, MODELS / "pendulum.mech")
    os.chmod(_plant_pickle(work, k, marker), 0o666)
    r = mech(work, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    ok = clean(r, 0) and not marker.exists() and "writable by other users" in r.err
    return Outcome(ok, "code ran!" if marker.exists() else "nothing ran; the entry was refused", internal=r.internal)


@case("attack")
def cache_owned_by_another_user(work):
    if os.geteuid() != 0:
        return Outcome(True, "needs root to give the folder away: covered by tests/test_faults_caches.py "
                             "(a process that is another user)")
    marker = work / "pwned"
    k = _key(work, MODELS / "pendulum.mech")
    p = _plant_pickle(work, k, marker)
    os.chown(p, 65534, 65534)
    r = mech(work, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    ok = clean(r, 0) and not marker.exists() and "owned by another user" in r.err
    return Outcome(ok, "code ran!" if marker.exists() else "nothing ran; " + r.err.strip()[:80], internal=r.internal)


@case("attack")
def symlinked_cache_entry(work):
    marker = work / "pwned"
    k = _key(work, MODELS / "pendulum.mech")
    elsewhere = work / "elsewhere.pkl"
    p = _plant_pickle(work, k, marker)
    shutil.move(p, elsewhere)
    os.symlink(elsewhere, p)
    r = mech(work, "simulate", MODELS / "pendulum.mech", "--t-end", "0.01", "--points", "3", "--no-progress")
    return Outcome(clean(r, 0) and not marker.exists(), "code ran!" if marker.exists() else
                   "nothing ran (links are not followed)", internal=r.internal)


EVIL_C = r"""
#include <stdio.h>
#include <stdlib.h>
__attribute__((constructor)) static void boom(void) { FILE *f = fopen(getenv("FAULT_MARKER"), "w"); if (f) fclose(f); }
"""


def _plant_library(work):
    mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress", "--compiled")
    libs = list((work / "cache").glob("*.so"))
    if not libs or shutil.which("cc") is None:
        return None
    (work / "evil.c").write_text(EVIL_C)
    subprocess.run(["cc", "-shared", "-fPIC", str(work / "evil.c"), "-o", str(work / "evil.so")], check=True)
    data = (work / "evil.so").read_bytes()
    for lib in libs:
        lib.write_bytes(data)
        lib.with_suffix(".sha256").write_text(hashlib.sha256(data).hexdigest() + "\n")
    return libs


@case("attack")
def library_with_its_file_hash(work):
    marker = work / "pwned"
    if _plant_library(work) is None:
        return Outcome(True, "no compiler here: no library to plant")
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress", "--compiled",
             env={"FAULT_MARKER": str(marker)})
    ok = clean(r, 0) and not marker.exists()
    return Outcome(ok, ("its constructor ran!" if marker.exists() else "not loaded (no key in its record): rebuilt"),
                   internal=r.internal)


@case("attack")
def library_in_a_folder_others_can_write(work):
    marker = work / "pwned"
    libs = _plant_library(work)
    if libs is None:
        return Outcome(True, "no compiler here: no library to plant")
    os.chmod(work / "cache", 0o777)
    r = mech(work, "simulate", DP, "--t-end", "0.01", "--points", "3", "--no-progress", "--compiled",
             env={"FAULT_MARKER": str(marker)})
    ok = clean(r, 0) and not marker.exists() and "writable by other users" in r.err
    return Outcome(ok, ("its constructor ran!" if marker.exists() else "not loaded; built privately for the run"),
                   internal=r.internal)


@case("attack")
def first_integrals_entry_with_another_function(work):
    """A JSON entry under the right key holding a Function of another signature."""
    args = ("--t-end", "0.05", "--points", "3", "--no-progress", "--method", "erk")
    mech(work, "simulate", MODELS / "heavy_top.mech", *args)
    (entry,) = list((work / "cache" / "integrals").iterdir())
    data = json.loads(entry.read_text())
    import casadi as ca

    x = ca.SX.sym("x")
    data["function"] = ca.Function("first_integrals", [x], [x * 2]).serialize()
    entry.write_text(json.dumps(data))
    r = mech(work, "simulate", MODELS / "heavy_top.mech", *args, "-o", work / "t.csv")
    header = (work / "t.csv").read_text().splitlines()[0] if (work / "t.csv").exists() else ""
    ok = clean(r, 0) and "p_tip.phi" in header
    return Outcome(ok, f"exit {r.code}; " + ("refused and searched again" if ok else "used!"), internal=r.internal,
                   silent=r.code == 0 and not ok)


def junk_server(payload: bytes):
    """A TCP server on 127.0.0.1 answering every connection with ``payload`` (another protocol);
    returns (socket, stop) - call stop() to end it."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    done = threading.Event()

    def serve():
        srv.settimeout(0.2)
        while not done.is_set():
            try:
                c, _ = srv.accept()
            except OSError:
                continue
            try:
                c.sendall(payload)
            except OSError:
                pass
            finally:
                c.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()

    def stop():
        done.set()
        th.join()
        srv.close()

    return srv, stop


@case("attack")
def port_speaking_another_protocol(work):
    srv, stop = junk_server(b"HTTP/1.1 200 OK\r\nContent-Length: 999999999999\r\n\r\n" + b"x" * 1000)
    try:
        code = ("import resource, sys\nfrom mechdsl.cli import main\nc = main(sys.argv[1:])\n"
                "print(c, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)")
        r = run([PY, "-c", code, "sweep", str(MODELS / "pendulum.mech"), "--grid", "m=1,2", "--t-end", "0.1",
                 "--no-progress", "--scheduler", f"tcp://127.0.0.1:{srv.getsockname()[1]}"], work, timeout=120)
    finally:
        stop()
    parts_ = r.out.split()
    code_, rss = (int(parts_[0]), int(parts_[1])) if len(parts_) == 2 else (None, None)
    ok = code_ == 2 and rss is not None and rss < 1_000_000 and "not a Dask scheduler" in r.err
    return Outcome(ok, f"exit {code_}, peak memory {rss} kB: {r.err.strip()[:90]}", internal=r.internal,
                   hang=r.timed_out)


@case("attack")
def malformed_scheduler_addresses(work):
    results = []
    for a in ("tcp://", "tcp://[::1", "tls://127.0.0.1:1", "tcp://host:99999", "udp://x:1"):
        r = mech(work, "sweep", MODELS / "pendulum.mech", "--grid", "m=1,2", "--t-end", "0.1", "--no-progress",
                 "--scheduler", a)
        results.append((a, r.code, r.internal))
    ok = all(c == 2 and not i for _, c, i in results)
    return Outcome(ok, ", ".join(f"{a} -> {c}" for a, c, _ in results), internal=any(i for *_, i in results))


# --------------------------------------------------------------------------- main


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-k", default="", help="run the cases whose name contains this")
    ap.add_argument("--list", action="store_true")
    args = ap.parse_args(argv)
    cases = [c for c in CASES if args.k in c.name]
    if args.list:
        for c in cases:
            print(f"{c.kind:6} {c.name}" + (f"  (pending: {c.pending})" if c.pending else ""))
        return 0
    rows = []
    for c in cases:
        work = Path(tempfile.mkdtemp(prefix="mechdsl-fault-"))
        (work / "cache").mkdir(mode=0o700)
        t0 = time.perf_counter()
        try:
            o = c.fn(work)
        except Exception as e:  # noqa: BLE001 - the script's own failure is a failed case, with its text
            o = Outcome(False, f"the case itself failed: {type(e).__name__}: {e}"[:160])
        finally:
            shutil.rmtree(work, ignore_errors=True)
        rows.append((c, o, time.perf_counter() - t0))
        status = ("survived" if c.kind == "fault" else "held") if o.ok else ("PENDING" if c.pending else "FAILED")
        print(f"{c.kind:6} | {c.name:45} | {status:8} | internal {'yes' if o.internal else 'no '} | "
              f"hang {'yes' if o.hang else 'no '} | silent {'yes' if o.silent else 'no '} | {o.text}", flush=True)
    faults = [r for r in rows if r[0].kind == "fault"]
    attacks = [r for r in rows if r[0].kind == "attack"]
    pending = [r for r in rows if not r[1].ok and r[0].pending]
    print()
    print(f"faults tried {len(faults)}, survived {sum(r[1].ok for r in faults)}; attacks tried {len(attacks)}, "
          f"held {sum(r[1].ok for r in attacks)}; internal errors {sum(r[1].internal for r in rows)}, hangs "
          f"{sum(r[1].hang for r in rows)}, silent results {sum(r[1].silent for r in rows)}; pending (known, "
          f"fixed elsewhere) {len(pending)}")
    bad = [r for r in rows if not r[1].ok and not r[0].pending]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
