"""Generated C and its compile against the model's size (issue 24, item 3).

    PYTHONPATH=src python benchmarks/codegen_scaling.py [--sizes 10,25,50,100,200] [--quick]

For the N-link chain's ``ode`` (models/nlink_pendulum.mech) and the 7-joint arm
(models/arm7.mech; with --urdf also Franka's Panda imported from example-robot-data), each
compiled in a fresh cache folder by a fresh process, prints per case:

- ops: SX instructions of the Functions compiled (the model's size);
- C kB: bytes of C handed to the compiler, and kB per 1000 operations (flat = linear);
- gcc CPU s: user + system CPU of the compiler processes (resource.getrusage(RUSAGE_CHILDREN)
  of the process that compiled), and ms per 1000 operations (flat = linear);
- gcc peak MB: the largest resident size of a compiler process (ru_maxrss of the children);
- for the chain, CasADi's own code generator side by side (one C function per Function, the
  way compiled code was generated before): its C size and gcc CPU at the optimization level
  codegen.cflags_for gives that size (-O0 above 1 MB).

Cases: ``ode`` (what the stepping loop compiles, mechdsl.eom.sxcode chunks at -O1) and
``ode + 2nd derivatives`` (Model.casadi(compiled=True) with derivatives: fwd1_, adj1_,
fwd1_adj1_ of ode: what an exact-Hessian optimizer calls).  Goal: C size and gcc time grow
linearly with the model; a 7-joint arm with its derivatives under 10 s of CPU and 500 MB.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, os, re, resource, sys
sys.path.insert(0, {src!r})
import casadi as ca
import mechdsl
from mechdsl.eom.codegen import casadi_functions, compile_functions, derivative_functions, cflags_for
path, n, kind, gen = {path!r}, {n!r}, {kind!r}, {gen!r}
text = open(path).read()
if n:
    text = re.sub(r"parameter Integer N = \d+", f"parameter Integer N = {{n}}", text)
m = mechdsl.loads(text)
ode = casadi_functions(m.eom, names=("ode",), sx=True)["ode"]
funcs = [ode] + (derivative_functions([ode], 2) if kind == "deriv" else [])
ops = sum(f.n_instructions() for f in funcs)
r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
if gen == "sxcode":
    loaded, note, lib = compile_functions([ode], jacobian=False, derivatives=2 if kind == "deriv" else 0)
    size = int(re.search(r"compiled (\d+) kB", note).group(1)) * 1000 if note else 0
else:   # CasADi's code generator, one unit, the size rule's level (what compiled code used before)
    import subprocess, tempfile
    cg = ca.CodeGenerator("m.c", {{"with_header": False, "verbose": False}})
    for f in funcs:
        cg.add(f)
    code = cg.dump()
    size = len(code)
    d = tempfile.mkdtemp()
    open(os.path.join(d, "m.c"), "w").write(code)
    subprocess.run(["gcc", *cflags_for(size), "-fPIC", "-c", "m.c", "-o", "m.o"], cwd=d, check=True)
r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({{"ops": ops, "c_bytes": size, "gcc_cpu": r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime,
                  "gcc_mb": r1.ru_maxrss / 1024}}))
"""


def case(path, n, kind, gen):
    env = dict(os.environ)
    env["MECHDSL_CACHE"] = tempfile.mkdtemp(prefix="mechdsl-cg-")
    code = CHILD.format(src=str(ROOT / "src"), path=str(path), n=n, kind=kind, gen=gen)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=3600)
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-2000:])
    return json.loads(p.stdout.strip().splitlines()[-1])


def row(label, r):
    ops = max(r["ops"], 1)
    return (f"| {label} | {r['ops']} | {r['c_bytes'] / 1e3:.0f} | {r['c_bytes'] / ops:.0f} | {r['gcc_cpu']:.2f} | "
            f"{r['gcc_cpu'] / (ops / 1e3):.3f} | {r['gcc_mb']:.0f} |")


HEAD = ("| case | ops | C kB | C bytes / op | gcc CPU s | gcc CPU s / 1000 ops | gcc peak MB |\n"
        "|---|---:|---:|---:|---:|---:|---:|")


def table(sizes, casadi_upto=100, urdf=None) -> str:
    chain = ROOT / "models" / "nlink_pendulum.mech"
    lines = ["`benchmarks/codegen_scaling.py`: a fresh process and cache folder per case; gcc CPU = the compiler "
             "processes' user + system time.", "", HEAD]
    for n in sizes:
        lines.append(row(f"{n}-link chain ode, sxcode (-O1)", case(chain, n, "ode", "sxcode")))
        if n <= casadi_upto:
            lines.append(row(f"{n}-link chain ode, CasADi's generator (before)", case(chain, n, "ode", "casadi")))
    arms = [("7-joint arm (models/arm7.mech)", ROOT / "models" / "arm7.mech")] + ([("Panda (mech import)", urdf)]
                                                                               if urdf else [])
    for label, path in arms:
        lines.append(row(f"{label} ode, sxcode", case(path, 0, "ode", "sxcode")))
        lines.append(row(f"{label} ode + 2nd derivatives, sxcode", case(path, 0, "deriv", "sxcode")))
    return "\n".join(lines)


def panda_mech() -> Path | None:
    try:
        import importlib.metadata as md

        base = Path(md.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except Exception:  # noqa: BLE001 - not installed: the arm of models/ only
        return None
    urdf = base / "panda_description" / "urdf" / "panda.urdf"
    out = Path(tempfile.mkdtemp()) / "panda.mech"
    subprocess.run([sys.executable, "-m", "mechdsl", "import", str(urdf), "-o", str(out), "--force"], check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="10,25,50,100,200")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--urdf", action="store_true", help="also Franka's Panda (needs example-robot-data)")
    a = ap.parse_args(argv)
    sizes = [10, 25] if a.quick else [int(s) for s in a.sizes.split(",")]
    print(table(sizes, casadi_upto=25 if a.quick else 100, urdf=panda_mech() if a.urdf else None))


if __name__ == "__main__":
    main()
