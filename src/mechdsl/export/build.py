"""Sources, compilation and the zip of an FMU.

The FMU's sources are the CasADi-generated C of the model (model.c), its table
(model_data.c), the runtime units the model needs (mech_*.c, the same for every model: the
constraint and contact units only for models with constraints or contacts), the compiled
stepping loop of ``mech simulate`` (crk.c, copied unchanged from mechdsl/simulation/backends),
one FMI interface (fmi2.c or fmi3.c) and the official FMI headers.  They are compiled into one
shared library with the system C compiler (symbols hidden but the FMI functions); object
files are cached under the model cache by the hash of their text, flags and compiler, so an
export compiles only the model's own code.  The zip is deterministic (sorted entries, fixed
times) and written atomically (output/fileio.py)."""
from __future__ import annotations

import hashlib
import io
import logging
import os
import platform
import sys
import zipfile
from pathlib import Path

from ..diagnostics import Diagnostic, MechError

log = logging.getLogger(__name__)
HERE = Path(__file__).with_name("c")
RUNTIME = ("mech_fmu.h", "mech_runtime.c", "mech_cosim.c", "mech_state.c", "mech_crk.c")     # every FMU
CONSTRAINT_UNITS = ("mech_constraints.c", "mech_linalg.c")      # constraint rows: constraints, contacts, fixations
CONTACT_UNITS = ("mech_hybrid.c",)                               # contacts, fixations
HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
           3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
CFLAGS = ["-O2", "-fPIC", "-fvisibility=hidden", "-std=gnu11"]
# units off the stepping loop's hot path compile at -O1 (half gcc's time there; mech_hybrid's
# constrained accelerations run in the loop only while contacts are closed or points fixed)
LIGHT = ("mech_runtime.c", "mech_cosim.c", "mech_state.c", "mech_constraints.c", "mech_hybrid.c", "fmi2.c", "fmi3.c",
         "model_data.c", "mech_crk.c")
ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def platform_folder(fmi_version: int) -> tuple[str, str]:
    """(binaries/<folder>, library suffix) of the platform this runs on."""
    machine = platform.machine().lower()
    arch = {"amd64": "x86_64", "x86_64": "x86_64", "aarch64": "aarch64", "arm64": "aarch64"}.get(machine)
    if sys.platform.startswith("linux") and arch:
        if fmi_version == 2:
            if arch != "x86_64":
                raise MechError(Diagnostic("E893", f"FMI 2.0 names no platform folder for Linux on {machine}",
                                           help="export FMI 3.0 (--fmi-version 3)"))
            return "linux64", ".so"
        return f"{arch}-linux", ".so"
    if sys.platform == "darwin" and arch:
        return ("darwin64" if fmi_version == 2 else f"{arch}-darwin"), ".dylib"
    raise MechError(Diagnostic("E893", f"exporting an FMU is not supported on this platform ({sys.platform}, {machine})",
                               help="export on Linux or macOS with a C compiler"))


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


def _array(ctype: str, name: str, values, fmt=repr) -> str:
    vals = list(values)
    body = ", ".join(fmt(v) for v in vals) if vals else "0"
    return f"static const {ctype} {name}[] = {{{body}}};"


def _real(v: float) -> str:
    return float.hex(float(v))       # exact in C (a hexadecimal floating constant)


def model_data(meta: dict, plan, fn_counts: dict) -> str:
    """model_data.c: the MechModel table of mech_fmu.h."""
    lines = ['/* model_data.c: the table of this model for the mechdsl FMU runtime (generated) */',
             '#include "mech_fmu.h"', ""]
    for name in fn_counts:
        lines.append(f"extern int {name}(const double **arg, double **res, cint *iw, double *w, int mem);")
        lines.append(f"extern int {name}_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);")
    lines.append("")
    lines.append(_array("int", "FREE_INDEX", meta["free_index"], str))
    lines.append(_array("double", "P_DEFAULT", meta["p_default"], _real))
    lines.append(_array("double", "U_DEFAULT", meta["u_default"], _real))
    lines.append(_array("int", "START_CALCULATED", [int(b) for b in meta["start_calculated"]], str))
    lines.append(_array("int", "FIXED_Q", [int(b) for b in meta["fixed_q"]], str))
    lines.append(_array("int", "FIXED_QD", [int(b) for b in meta["fixed_qd"]], str))
    lines.append(_array("double", "FIX_TIME", plan.fix_times, _real))
    lines.append(_array("int", "BASE_ROWS", plan.base_rows, str))
    lines.append(_array("double", "INT_VALUES", meta["int_values"], _real))
    lines.append(_array("char *const", "PARAM_NAMES", meta["params"], _c_string))
    lines.append(_array("char *const", "COORDS", meta["coords"], _c_string))
    lines.append(_array("char *const", "ROWS", meta["rows"], _c_string))
    lines.append(_array("int", "FRIC_COL", plan.fric_col, str))
    rs, is_, ru = meta["real_settings"], meta["int_settings"], meta["rules"]

    def fn(key):
        name = f"mech_{key}"
        if name not in fn_counts:
            return "{0, 0, 0, 0}"
        n_in, n_out = fn_counts[name]
        return f"{{{name}, {name}_work, {n_in}, {n_out}}}"

    lines += ["", "const MechModel MECH = {",
              f"  {_c_string(meta['model'])}, {_c_string(meta['token'])}, {int(meta['me'])}, {int(meta['cs'])},",
              f"  {plan.n}, {plan.nu}, {plan.np}, {len(meta['free_index'])}, {plan.m}, {plan.k}, {plan.nfix}, "
              f"{plan.nrows}, {plan.nout}, {len(meta['int_values'])},",
              "  FREE_INDEX, P_DEFAULT, U_DEFAULT, START_CALCULATED, FIXED_Q, FIXED_QD, FIX_TIME,",
              f"  BASE_ROWS, {len(plan.base_rows)}, INT_VALUES,",
              "  {" + ", ".join(_real(v) for v in rs) + "},",
              "  {" + ", ".join(str(int(v)) for v in is_) + "},",
              f"  {_real(meta['acc_tol'])}, {int(meta['samples'])},",
              "  PARAM_NAMES, COORDS, ROWS, FRIC_COL,",
              "  " + ", ".join(fn(k) for k in ("ode", "out", "jvp", "start", "params", "dyn", "cons", "gap", "e", "fric")) + ",",
              "  /* the tolerance rules (mechdsl/export/problem.py rules) */",
              "  {" + ", ".join(_real(v) for v in (*ru["drift"], ru["offset"][0], *ru["touch"], ru["v_eps"],
                                                   ru["init_tol"], ru["rank_tol"])) + f", {int(ru['zeno_events'])}, "
              + _real(ru["zeno_span"]) + "},",
              "  " + ("&mech_constraint_ops" if plan.nrows else "0") + ", " + ("&mech_contact_ops" if plan.k or plan.nfix else "0"),
              "};", ""]
    return "\n".join(lines)


def casadi_source(functions) -> str:
    import casadi as ca

    g = ca.CodeGenerator("model.c", {"with_header": False, "verbose": False})
    for f in functions:
        g.add(f)
    return g.dump()


def sources(meta: dict, plan, fmi_version: int) -> dict[str, str]:
    """name -> text of every file of sources/ (the token still a placeholder)."""
    out = {"model.c": casadi_source(plan.functions)}
    counts = {f.name(): (f.n_in(), f.n_out()) for f in plan.functions}
    out["model_data.c"] = model_data(meta, plan, counts)
    units = RUNTIME + (CONSTRAINT_UNITS if plan.nrows else ()) + (CONTACT_UNITS if plan.k or plan.nfix else ())
    for name in units:
        out[name] = (HERE / name).read_text()
    out["crk.c"] = (HERE.parent.parent / "simulation" / "backends" / "crk.c").read_text()
    out[f"fmi{fmi_version}.c"] = (HERE / f"fmi{fmi_version}.c").read_text()
    for name in HEADERS[fmi_version]:
        out[name] = (HERE / "fmi" / name).read_text()
    return out


def c_files(srcs: dict) -> list[str]:
    order = ["model.c", "model_data.c", "mech_runtime.c", "mech_cosim.c", "mech_state.c", "mech_constraints.c",
             "mech_hybrid.c", "mech_linalg.c", "mech_crk.c", "crk.c", "fmi2.c", "fmi3.c"]
    return [f for f in order if f in srcs]


def unit_flags(name: str, text: str) -> list[str]:
    """gcc flags of one source file (the model's optimization level by its size, codegen.cflags_for)."""
    from ..eom.codegen import cflags_for

    flags = list(CFLAGS)
    if name == "model.c":
        flags[0] = cflags_for(len(text))[0]
    elif name in LIGHT:
        flags[0] = "-O1"
    return flags


def compile_library(srcs: dict, identifier: str, suffix: str) -> bytes:
    """The shared library of the sources (bytes); objects cached by content."""
    import subprocess
    import tempfile

    from ..eom.codegen import cache_dir, compiler_version, find_compiler

    cc = find_compiler()
    if cc is None:
        raise MechError(Diagnostic("E893", "cannot build the FMU's binary: no C compiler found (looked for $CC, gcc, cc, clang)",
                                   help="install a C compiler (gcc or clang), or set CC"))
    version = compiler_version(cc)
    headers = "".join(srcs[h] for h in sorted(srcs) if h.endswith(".h"))
    objdir = cache_dir() / "fmu-objects"
    try:
        objdir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise MechError(Diagnostic("E893", f"cannot create the object cache {objdir}: {e.strerror or e}")) from None
    with tempfile.TemporaryDirectory(prefix="mechdsl-fmu-") as tmp:
        for name, text in srcs.items():
            (Path(tmp) / name).write_text(text)
        procs, objs = [], []
        for name in c_files(srcs):
            flags = unit_flags(name, srcs[name])
            key = hashlib.sha256("\n".join([srcs[name], headers, repr(flags), version]).encode()).hexdigest()[:32]
            cached = objdir / f"{key}.o"
            obj = Path(tmp) / (name[:-2] + ".o")
            objs.append(obj)
            if cached.exists():
                obj.write_bytes(cached.read_bytes())
                continue
            procs.append((subprocess.Popen([cc, *flags, "-I.", "-c", name, "-o", obj.name], cwd=tmp,
                                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True), obj, cached, name))
        log.info("compiling %d of the FMU's %d C files with %s%s", len(procs), len(objs), Path(cc).name,
                 f" ({', '.join(name for *_, name in procs)})" if procs else ": all from the object cache")
        errors = []
        for pr, obj, cached, name in procs:
            out, err = pr.communicate()
            if pr.returncode != 0:
                errors.append(f"{name}: " + " | ".join((err or out).strip().splitlines()[-3:]))
                continue
            part = cached.with_name(f".{cached.name}.{os.getpid()}.tmp")
            try:
                part.write_bytes(obj.read_bytes())
                os.replace(part, cached)
            except OSError:
                pass
        if errors:
            raise MechError(Diagnostic("E893", f"C compilation of the FMU failed ({Path(cc).name}): {errors[0]}"))
        lib = Path(tmp) / f"{identifier}{suffix}"
        r = subprocess.run([cc, "-shared", *(o.name for o in objs), "-o", lib.name, "-lm"], cwd=tmp,
                           capture_output=True, text=True)
        if r.returncode != 0:
            tail = " | ".join((r.stderr or r.stdout).strip().splitlines()[-3:])
            raise MechError(Diagnostic("E893", f"linking the FMU's binary failed ({Path(cc).name}): {tail}"))
        return lib.read_bytes()


def token_of(parts) -> str:
    """A GUID-shaped content hash: the same model and options give the same token."""
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode() if isinstance(p, str) else p)
        h.update(b"\0")
    d = h.hexdigest()
    return "{" + f"{d[:8]}-{d[8:12]}-{d[12:16]}-{d[16:20]}-{d[20:32]}" + "}"


def zip_bytes(files: dict[str, bytes]) -> bytes:
    """A deterministic zip: entries sorted (modelDescription.xml first), fixed times."""
    buf = io.BytesIO()
    names = sorted(files, key=lambda n: (n != "modelDescription.xml", n))
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in names:
            info = zipfile.ZipInfo(name, ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            zf.writestr(info, files[name])
    return buf.getvalue()
