"""N-link pendulum benchmark: mechdsl against sympy.physics.mechanics and Pinocchio.

    PYTHONPATH=src python benchmarks/nlink.py [--sizes 1,2,5,10,20,50,100] [--sympy-max 5]
                                              [--no-pin] [--no-sympy] [--no-compile]

For each N (uniform slender rods of 1 kg and 1 m, revolute joints about z, relative angles,
gravity 9.81 along -y; models/nlink_pendulum.mech with N set) it prints, measured in one run:

- text -> Function: .mech text -> parse/analyze -> derive (ABA in SX) -> casadi.Function
  of the forward dynamics (warm process: imports and per-link templates already built);
- one RHS evaluation: CasADi virtual machine called through Function.buffer() (includes
  ~0.5 us of Python call overhead) and the same Function as C (CodeGenerator + gcc -O3
  -march=native) timed in a C loop (pure compute; gcc build time shown separately);
- Pinocchio's ABA (pin, C++) timed in a C++ loop compiled with the same flags (Pinocchio's
  headers, -O3 -march=native), and the ratio compiled mechdsl / Pinocchio;
- accuracy: max |qdd - qdd_ref| / max(1, |qdd_ref|) at random states against Pinocchio
  (an independent implementation), the Lagrange route (AD of T, up to N = 20) and
  sympy.physics.mechanics (Kane's method, up to --sympy-max);
- sympy: time to derive (KanesMethod) and lambdify, and one RHS evaluation (numpy solve).

Timings are the minimum over repeats (the machine may be shared).  Build products go to
$MECHDSL_BENCH_DIR (default: <tmp>/mechdsl-bench); the Pinocchio harness takes a few minutes
to compile once and is cached there.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import casadi as ca  # noqa: E402

import mechdsl  # noqa: E402
from mechdsl.mechanics import derive  # noqa: E402

BUILD = Path(os.environ.get("MECHDSL_BENCH_DIR") or Path(tempfile.gettempdir()) / "mechdsl-bench")
CFLAGS = ["-O3", "-march=native"]
TEXT = (ROOT / "models" / "nlink_pendulum.mech").read_text()


def mech_text(N: int) -> str:
    out = re.sub(r"parameter Integer N = \d+", f"parameter Integer N = {N}", TEXT)
    assert out != TEXT or N == 3
    return out


def best(fn, repeat=5):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return min(ts)


# --------------------------------------------------------------------------- mechdsl

def text_to_function(N):
    import mechdsl.api

    mechdsl.api._EOM_CACHE.clear()        # time the derivation, not the structure cache
    m = mechdsl.loads(mech_text(N))
    e = m.eom
    f = ca.Function("rhs", [e.q, e.qd, e.p], [e.qdd], ["q", "qd", "p"], ["qdd"])
    return e, f, m.parameter_values


def vm_eval_us(f, n, pv, reps):
    buf, trigger = f.buffer()
    q, qd, out = np.linspace(-0.3, 0.4, n), np.linspace(-0.2, 0.3, n), np.zeros(n)
    p = np.asarray(pv, float)
    buf.set_arg(0, memoryview(q))
    buf.set_arg(1, memoryview(qd))
    buf.set_arg(2, memoryview(p))
    buf.set_res(0, memoryview(out))
    trigger()

    def loop():
        for _ in range(reps):
            trigger()

    return best(loop) / reps * 1e6


HARNESS_C = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "rhs.h"
int main(int argc, char** argv) {
  int n = atoi(argv[1]); long reps = atol(argv[2]); int np = atoi(argv[3]);
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  rhs_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  double* q = malloc(n * sizeof(double)); double* qd = malloc(n * sizeof(double));
  double* out = malloc(n * sizeof(double)); double* p = malloc((np + 1) * sizeof(double));
  for (int i = 0; i < np; ++i) p[i] = atof(argv[4 + i]);
  for (int i = 0; i < n; ++i) { q[i] = 0.1 * (i + 1) - 0.3; qd[i] = 0.05 * i - 0.2; }
  const double* arg[8] = {q, qd, p}; double* res[4] = {out};
  casadi_int* iw = malloc((sz_iw + 1) * sizeof(casadi_int)); double* w = malloc((sz_w + 1) * sizeof(double));
  double acc = 0, bestns = 1e300;
  for (int round = 0; round < 5; ++round) {
    struct timespec t0, t1; clock_gettime(CLOCK_MONOTONIC, &t0);
    for (long r = 0; r < reps; ++r) { q[0] += 1e-13; rhs(arg, res, iw, w, 0); acc += out[n - 1]; }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double ns = ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / reps;
    if (ns < bestns) bestns = ns;
  }
  printf("%.3f\n", bestns);
  return acc == 12345.678;
}
"""


def compiled_eval_us(f, n, pv, reps):
    d = BUILD / f"mech_n{n}"
    d.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    cg = ca.CodeGenerator("rhs.c", {"with_header": True})
    cg.add(f)
    cg.generate(str(d) + os.sep)
    (d / "harness.c").write_text(HARNESS_C)
    subprocess.run(["gcc", *CFLAGS, "harness.c", "rhs.c", "-o", "bench", "-lm"], cwd=d, check=True)
    build_s = time.perf_counter() - t
    r = subprocess.run([str(d / "bench"), str(n), str(reps), str(len(pv)), *map(repr, map(float, pv))],
                       capture_output=True, text=True, check=True)
    return float(r.stdout) / 1e3, build_s


# --------------------------------------------------------------------------- pinocchio

PIN_CPP = r"""
// pinocchio::aba on the N-link pendulum of uniform rods (revolute z, relative angles)
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
int main(int argc, char** argv) {
  using namespace pinocchio;
  int N = atoi(argv[1]); long reps = atol(argv[2]);
  Model model; JointIndex parent = 0; SE3 placement = SE3::Identity();
  for (int i = 0; i < N; ++i) {
    JointIndex j = model.addJoint(parent, JointModelRZ(), placement, "j" + std::to_string(i));
    Inertia I(1.0, Eigen::Vector3d(0, -0.5, 0), Eigen::Vector3d(1.0 / 12, 0, 1.0 / 12).asDiagonal().toDenseMatrix());
    model.appendBodyToJoint(j, I, SE3::Identity());
    parent = j; placement = SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, -1.0, 0));
  }
  model.gravity.linear(Eigen::Vector3d(0, -9.81, 0));
  Data data(model);
  Eigen::VectorXd q(N), v(N), tau = Eigen::VectorXd::Zero(N);
  for (int i = 0; i < N; ++i) { q[i] = 0.1 * (i + 1) - 0.3; v[i] = 0.05 * i - 0.2; }
  double acc = 0, best = 1e300;
  for (int round = 0; round < 5; ++round) {
    auto t0 = std::chrono::steady_clock::now();
    for (long r = 0; r < reps; ++r) { q[0] += 1e-13; aba(model, data, q, v, tau); acc += data.ddq[N - 1]; }
    auto t1 = std::chrono::steady_clock::now();
    double ns = std::chrono::duration<double, std::nano>(t1 - t0).count() / reps;
    if (ns < best) best = ns;
  }
  printf("%.3f\n", best);
  return acc == 12345.678 ? 1 : 0;
}
"""


def pin_harness():
    """Path of the compiled Pinocchio harness, or (None, why)."""
    try:
        import pinocchio  # noqa: F401
    except ImportError:
        return None, "pinocchio not installed (pip install pin)"
    import casadi

    prefix = Path(sys.prefix) / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages" / "cmeel.prefix"
    eigen = Path(casadi.__file__).parent / "include" / "eigen3"
    if not (prefix / "include" / "pinocchio").exists():
        return None, f"no Pinocchio headers under {prefix}"
    defs = ["-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
            "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12", "-DNDEBUG"]
    cmd = ["g++", *CFLAGS, "-std=c++17", "-w", *defs, f"-I{prefix / 'include'}", f"-I{eigen}", "pin_aba.cpp",
           "-o", "pin_aba", f"-L{prefix / 'lib'}", f"-Wl,-rpath,{prefix / 'lib'}"]
    key = hashlib.sha256((PIN_CPP + " ".join(cmd)).encode()).hexdigest()[:12]
    d = BUILD / f"pin_{key}"
    exe = d / "pin_aba"
    if exe.exists():
        return exe, None
    d.mkdir(parents=True, exist_ok=True)
    (d / "pin_aba.cpp").write_text(PIN_CPP)
    print(f"# compiling the Pinocchio harness once (a few minutes) in {d}", file=sys.stderr, flush=True)
    r = subprocess.run(cmd, cwd=d, capture_output=True, text=True)
    if r.returncode != 0:
        return None, "Pinocchio harness did not compile: " + r.stderr[-300:]
    return exe, None


def pin_model(N):
    import pinocchio as pin

    model = pin.Model()
    parent, placement = 0, pin.SE3.Identity()
    for i in range(N):
        j = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i}")
        model.appendBodyToJoint(j, pin.Inertia(1.0, np.array([0, -0.5, 0]), np.diag([1 / 12, 0, 1 / 12])),
                                pin.SE3.Identity())
        parent, placement = j, pin.SE3(np.eye(3), np.array([0, -1.0, 0]))
    model.gravity.linear = np.array([0, -9.81, 0])
    return model, model.createData()


def pin_eval_us(exe, N, reps):
    r = subprocess.run([str(exe), str(N), str(reps)], capture_output=True, text=True, check=True)
    return float(r.stdout) / 1e3


# --------------------------------------------------------------------------- sympy

def sympy_nlink(N):
    import sympy as sp
    import sympy.physics.mechanics as me

    t = time.perf_counter()
    q = me.dynamicsymbols(f"q1:{N + 1}")
    u = me.dynamicsymbols(f"u1:{N + 1}")
    Nf = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(Nf, 0)
    prev, P = Nf, O
    bodies, loads = [], []
    for i in range(N):
        A = prev.orientnew(f"A{i}", "Axis", [q[i], prev.z])
        A.set_ang_vel(prev, u[i] * prev.z)
        G = P.locatenew(f"G{i}", -0.5 * A.y)
        G.v2pt_theory(P, Nf, A)
        Pn = P.locatenew(f"P{i}", -1.0 * A.y)
        Pn.v2pt_theory(P, Nf, A)
        bodies.append(me.RigidBody(f"B{i}", G, A, 1.0, (me.inertia(A, 1 / 12, 0, 1 / 12), G)))
        loads.append((G, -9.81 * Nf.y))
        prev, P = A, Pn
    km = me.KanesMethod(Nf, q_ind=q, u_ind=u, kd_eqs=[q[i].diff() - u[i] for i in range(N)])
    km.kanes_equations(bodies, loads)
    f = sp.lambdify([q, u], [km.mass_matrix, km.forcing], "numpy")

    def qdd(qv, uv):
        M, F = f(qv, uv)
        return np.linalg.solve(np.asarray(M, float), np.asarray(F, float).ravel())

    return qdd, time.perf_counter() - t


# --------------------------------------------------------------------------- main

COLD = r"""
import sys, time
t0 = time.perf_counter()
import casadi as ca
import mechdsl
from mechdsl.mechanics import derive
t1 = time.perf_counter()
m = mechdsl.loads(sys.stdin.read())
t2 = time.perf_counter()
e = derive(m.model)
f = ca.Function("rhs", [e.q, e.qd, e.p], [e.qdd])
t3 = time.perf_counter()
print(f"imports {t1 - t0:.2f} s, then text -> Function {t3 - t1:.2f} s "
      f"(parse + analyze {t2 - t1:.2f} s, derive + Function {t3 - t2:.2f} s)")
"""


def cold_run(N):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    r = subprocess.run([sys.executable, "-c", COLD], input=mech_text(N), capture_output=True, text=True, env=env)
    return r.stdout.strip() or r.stderr.strip()[-300:]


def rel_err(a, b):
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def fmt(x, spec=".3g"):
    return "n/a" if x is None else format(x, spec)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1,2,5,10,20,50,100")
    ap.add_argument("--sympy-max", type=int, default=5)
    ap.add_argument("--no-pin", action="store_true")
    ap.add_argument("--no-sympy", action="store_true")
    ap.add_argument("--no-compile", action="store_true")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]

    text_to_function(2)        # warm up: imports, per-link templates
    exe, why = (None, "--no-pin") if args.no_pin else pin_harness()
    if why:
        print(f"# Pinocchio: {why}")
    rows = []
    for N in sizes:
        reps_vm = max(200, 20000 // N)
        reps_c = max(2000, 2_000_000 // N)
        t_fn = best(lambda: text_to_function(N), repeat=3)
        e, f, pv = text_to_function(N)
        vm = vm_eval_us(f, N, pv, reps_vm)
        comp, build = (None, None) if args.no_compile else compiled_eval_us(f, N, pv, reps_c)
        rng = np.random.default_rng(N)
        states = [(rng.uniform(-np.pi, np.pi, N), rng.uniform(-2, 2, N)) for _ in range(5)]
        ours = [np.array(f(q, qd, pv)).ravel() for q, qd in states]
        err_pin = err_lag = err_sym = None
        pin_us = None
        if exe is not None:
            import pinocchio as pin

            pm, pd = pin_model(N)
            err_pin = max(rel_err(a, pin.aba(pm, pd, q, qd, np.zeros(N))) for a, (q, qd) in zip(ours, states))
            pin_us = pin_eval_us(exe, N, reps_c)
        if N <= 20:
            el = derive(e.model, route="lagrange")
            mb = ca.Function("mb", [el.q, el.qd, el.p], [el.M, el.bias])
            errs = []
            for a, (q, qd) in zip(ours, states):
                M, b = mb(q, qd, pv)
                errs.append(rel_err(a, np.linalg.solve(np.array(M), np.array(b).ravel())))
            err_lag = max(errs)
        sym_t = sym_us = None
        if not args.no_sympy and N <= args.sympy_max:
            sq, sym_t = sympy_nlink(N)
            err_sym = max(rel_err(a, sq(q, qd)) for a, (q, qd) in zip(ours, states))
            q, qd = states[0]
            sym_us = best(lambda: [sq(q, qd) for _ in range(200)]) / 200 * 1e6
        size = f.n_instructions()
        rows.append(dict(N=N, fn_ms=t_fn * 1e3, ops=size, vm=vm, comp=comp, build=build, pin=pin_us,
                         ratio=None if comp is None or pin_us is None else comp / pin_us,
                         err_pin=err_pin, err_lag=err_lag, err_sym=err_sym, sym_t=sym_t, sym_us=sym_us))
        print(f"# N={N} done", file=sys.stderr, flush=True)

    head = ("| N | text->Function ms | SX ops | VM eval us | compiled eval us | gcc s | Pinocchio ABA us "
            "| compiled/Pinocchio | err vs Pinocchio | err vs Lagrange-AD | err vs sympy | sympy derive s "
            "| sympy eval us |")
    print(head)
    print("|" + "|".join("---" for _ in range(head.count("|") - 1)) + "|")
    for r in rows:
        print(f"| {r['N']} | {r['fn_ms']:.1f} | {r['ops']} | {r['vm']:.2f} | {fmt(r['comp'])} | {fmt(r['build'], '.2f')} "
              f"| {fmt(r['pin'])} | {fmt(r['ratio'], '.2f')} | {fmt(r['err_pin'], '.1e')} | {fmt(r['err_lag'], '.1e')} "
              f"| {fmt(r['err_sym'], '.1e')} | {fmt(r['sym_t'], '.2f')} | {fmt(r['sym_us'], '.1f')} |")
    ok50 = [r for r in rows if r["N"] == 50]
    if ok50:
        print(f"\ntarget text->Function for N = 50 <= 1000 ms: {ok50[0]['fn_ms']:.0f} ms (warm process)")
        print("fresh process, N = 50: " + cold_run(50))
    rat = [r for r in rows if 2 <= r["N"] <= 50 and r["ratio"] is not None]
    if rat:
        print("target compiled RHS <= 0.5 x Pinocchio ABA for N = 2..50: "
              + ", ".join(f"N={r['N']}: {r['ratio']:.2f}" for r in rat))
    return 0


if __name__ == "__main__":
    sys.exit(main())
