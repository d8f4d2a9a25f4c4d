"""Straight-line code from CasADi SX algorithms: C source in chunks, and interpreter programs.

An SX Function is a list of scalar instructions on work slots.  Two translations of that list:

``c_source(f, name)``
    C with CasADi's calling convention (``name(arg, res, iw, w, mem)``, ``name_work``,
    ``name_n_in``, ``name_sparsity_in``, ...), so ``casadi.external`` and the compiled loop
    (simulation/backends/crk.c) call it like CasADi's own generated code.  Unlike CasADi's code
    generator, which writes one C function holding every operation in local variables (gcc's
    register allocation then grows faster than linearly: the 200-link chain's 25,000
    operations took 10-14 s at -O1), the instructions are split into functions of
    ``CHUNK`` operations on a work array, so gcc's time grows linearly with the model
    (docs/internals/numerics.md, "Compiled code").
``program(f)``
    the instruction list for the interpreter of simulation/backends/vm.c: no compile at all.

Both write each operation as the C expression CasADi's code generator prints for it, in the
same order on the same operands, so compiled code, a program and CasADi's generated C give
the same bits (tests/test_sxcode.py).  Functions with other instructions (calls of other
Functions, ...) are refused with ``Unsupported``: callers use CasADi's code generator then.
"""
from __future__ import annotations

import numpy as np

from . import vmprog

CHUNK = 256          # operations per C function: gcc's time per operation stays flat


class Unsupported(ValueError):
    """The Function is not an SX Function of scalar instructions this module translates."""


# CasADi op name -> C expression of the generated code (calculus.hpp's print), {0}, {1} the operands
BINARY = {"ADD": "{0}+{1}", "SUB": "{0}-{1}", "MUL": "{0}*{1}", "DIV": "{0}/{1}", "POW": "pow({0},{1})",
          "CONSTPOW": "pow({0},{1})", "LT": "{0}<{1}", "LE": "{0}<={1}", "EQ": "{0}=={1}", "NE": "{0}!={1}",
          "AND": "{0}&&{1}", "OR": "{0}||{1}", "FMOD": "fmod({0},{1})", "COPYSIGN": "copysign({0},{1})",
          "IF_ELSE_ZERO": "{0}?{1}:0", "FMIN": "sx_fmin({0},{1})", "FMAX": "sx_fmax({0},{1})",
          "ATAN2": "atan2({0},{1})", "HYPOT": "sx_hypot({0},{1})", "REMAINDER": "remainder({0},{1})"}
UNARY = {"ASSIGN": "{0}", "NEG": "-{0}", "EXP": "exp({0})", "LOG": "log({0})", "SQRT": "sqrt({0})",
         "SQ": "{0}*{0}", "TWICE": "2.*{0}", "SIN": "sin({0})", "COS": "cos({0})", "TAN": "tan({0})",
         "ASIN": "asin({0})", "ACOS": "acos({0})", "ATAN": "atan({0})", "NOT": "!{0}", "FLOOR": "floor({0})",
         "CEIL": "ceil({0})", "FABS": "fabs({0})", "SIGN": "sx_sign({0})", "ERF": "erf({0})", "INV": "1./{0}",
         "SINH": "sinh({0})", "COSH": "cosh({0})", "TANH": "tanh({0})", "ASINH": "asinh({0})",
         "ACOSH": "acosh({0})", "ATANH": "atanh({0})", "LOG1P": "log1p({0})", "EXPM1": "expm1({0})"}

# fmin, fmax and hypot are commutative to gcc, which may swap their operands (and merge
# fmax(a, b) with fmax(b, a)); on signed zeros the C library's answer depends on the order, and
# CasADi's generated code calls them through a function of its own in the written order
_HELPERS = """#ifndef SX_HELPERS
#define SX_HELPERS
#if defined(__GNUC__)
#define SX_KEEP __attribute__((noinline))
#else
#define SX_KEEP
#endif
static double sx_sign(double x) { return x < 0 ? -1. : x > 0 ? 1. : x; }
static SX_KEEP double sx_fmin(double x, double y) { return fmin(x, y); }
static SX_KEEP double sx_fmax(double x, double y) { return fmax(x, y); }
static SX_KEEP double sx_hypot(double x, double y) { return hypot(x, y); }
#endif"""

# the interpreter's opcodes, in the order of vm.c's enum
VM_OPS = ("END", "OUT", "ASSIGN", "ADD", "SUB", "MUL", "DIV", "NEG", "EXP", "LOG", "POW", "SQRT", "SQ", "TWICE",
          "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "LT", "LE", "EQ", "NE", "NOT", "AND", "OR", "FLOOR", "CEIL",
          "FMOD", "FABS", "SIGN", "COPYSIGN", "IF_ELSE_ZERO", "ERF", "FMIN", "FMAX", "INV", "SINH", "COSH", "TANH",
          "ASINH", "ACOSH", "ATANH", "ATAN2", "LOG1P", "EXPM1", "HYPOT", "REMAINDER")
_VM_CODE = {name: i for i, name in enumerate(VM_OPS)}
_VM_CODE["CONSTPOW"] = _VM_CODE["POW"]

_NAMES: dict | None = None


def _op_names() -> dict:
    global _NAMES
    if _NAMES is None:
        import casadi as ca

        _NAMES = {getattr(ca, n): n[3:] for n in dir(ca) if n.startswith("OP_")}
    return _NAMES


def instructions(f) -> list[tuple[str, list, list, float]]:
    """(op name, inputs, outputs, constant) of every instruction of the SX Function ``f``
    (kept: in this process and on disk, see ``_kept``)."""
    return _kept(f, "instr", lambda: _instructions(f), _pack_instr, _unpack_instr)


def _instructions(f) -> list[tuple[str, list, list, float]]:
    if not f.is_a("SXFunction"):
        raise Unsupported(f"{f.name()} is a {f.class_name()}, not an SX Function")
    names = _op_names()
    iid, iin, iout = _accessors()
    out = []
    known = {*BINARY, *UNARY, "INPUT", "OUTPUT", "CONST"}
    for k in range(f.n_instructions()):
        code = iid(f, k)
        op = names.get(code, str(code))
        if op not in known:
            raise Unsupported(f"{f.name()} has an instruction {op} (not translated)")
        const = float(f.instruction_constant(k)) if op == "CONST" else 0.0
        out.append((op, list(iin(f, k)), list(iout(f, k)), const))
    return out


def _accessors():
    """CasADi's instruction accessors: SWIG's own functions where they are (the Python wrappers
    around them were a third of the 200-link ode's 0.14 s), else the wrappers."""
    import casadi as ca

    raw = getattr(ca, "_casadi", None)
    names = ("Function_instruction_id", "Function_instruction_input", "Function_instruction_output")
    if raw is not None and all(hasattr(raw, n) for n in names):
        return tuple(getattr(raw, n) for n in names)
    return ca.Function.instruction_id, ca.Function.instruction_input, ca.Function.instruction_output


def supported(f) -> bool:
    """Whether ``f`` is an SX Function of instructions this module translates (kept)."""
    if not f.is_a("SXFunction"):
        return False

    def check():
        try:
            instructions(f)
        except Unsupported:
            return False
        return True
    return _kept(f, "ok", check, lambda v: b"1" if v else b"0", lambda b: b == b"1")


# --------------------------------------------------------------------------- kept translations

# Reading an instruction list through CasADi's Python interface costs ~5 us an instruction (20
# ms of a 12-link chain's warm run, 125 ms at 200 links), and the C text and the program are
# built from it on every run: both are kept per Function in this process and on disk under
# <cache>/sxcode/, keyed by the SHA-256 of the serialized Function and of this module's code.
_MEMO: dict = {}
_MEMO_MAX = 64
_CODE: list = []


def _code_tag() -> str:
    if not _CODE:
        from ..digest import sha256
        from pathlib import Path

        _CODE.append(sha256(Path(__file__).read_bytes()).hexdigest()[:16])
    return _CODE[0]


_KEYS: dict = {}


def serialized(f, text: str) -> None:
    """``text`` is ``f.serialize()`` (``f`` was read from it): its hash, without serializing
    ``f`` again (1-3 ms a model Function on a warm run)."""
    from ..digest import sha256

    if len(_KEYS) >= _MEMO_MAX:
        _KEYS.pop(next(iter(_KEYS)), None)
    _KEYS[id(f)] = (f, sha256(text.encode()).hexdigest())


_TEXTS: dict = {}       # id -> (Function, its serialization): the last few (text_of)
_TEXTS_MAX = 4


def text_of(f) -> str:
    """``f.serialize()``, once per Function and process for the last few serialized (the model
    cache stores the texts of the Functions a first run keyed here: ~50 ms a 200-link ode)."""
    hit = _TEXTS.get(id(f))
    if hit is not None and hit[0] is f:
        return hit[1]
    text = f.serialize()
    if len(_TEXTS) >= _TEXTS_MAX:
        _TEXTS.pop(next(iter(_TEXTS)), None)
    _TEXTS[id(f)] = (f, text)
    hit = _KEYS.get(id(f))
    if hit is None or hit[0] is not f:
        serialized(f, text)
    return text


def _key(f, extra: str = "") -> str:
    from ..digest import sha256

    hit = _KEYS.get(id(f))
    if hit is None or hit[0] is not f:      # one serialization per Function and process
        text_of(f)
        hit = _KEYS[id(f)]
    return sha256((hit[1] + _code_tag() + extra).encode()).hexdigest()[:32]


def entry_path(f, kind: str, extra: str = ""):
    """The cache file of ``f``'s entry of this kind (``<cache>/sxcode/<key>.<kind>``; the key: the
    Function's serialization, the code's tag and ``extra``)."""
    from . import cachefiles

    return cachefiles.cache_dir() / "sxcode" / f"{_key(f, extra)}.{kind}"


def _kept(f, kind: str, build, pack, unpack, extra: str = ""):
    mem = _MEMO.get((id(f), kind, extra))
    if mem is not None and mem[0] is f:
        return mem[1]
    value, path = None, None
    try:
        from . import cachefiles

        path = entry_path(f, kind, extra)
        data, _why = cachefiles.read_bytes(path)        # the cache's trust rule (issue 25)
        value = unpack(data) if data is not None else None
    except Exception:  # noqa: BLE001 - an unreadable entry is rebuilt
        value = None
    if value is None:
        value = build()
        if path is not None:
            cachefiles.write_bytes(path, pack(value))   # atomic, 0600 in a 0700 folder; False: only slower
    if len(_MEMO) >= _MEMO_MAX:
        _MEMO.pop(next(iter(_MEMO)), None)
    _MEMO[(id(f), kind, extra)] = (f, value)      # the Function kept: its id stays unique
    return value


def _pack_arrays(arrays: dict, **extra) -> bytes:
    """Arrays and small JSON values as bytes (a JSON header line, then the raw arrays): the
    cache entries of this module, read without numpy's npz (zipfile and shutil: 20 ms of
    imports on a warm run)."""
    import json

    head, blobs, at = {}, [], 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        head[name] = [a.dtype.str, list(a.shape), at]
        blobs.append(a.tobytes())
        at += len(blobs[-1])
    return json.dumps({"arrays": head, "extra": extra}).encode() + b"\n" + b"".join(blobs)


def _unpack_arrays(data: bytes):
    import json

    line = data.index(b"\n")
    head = json.loads(data[:line])
    body = memoryview(data)[line + 1:]
    out = {}
    for name, (dtype, shape, at) in head["arrays"].items():
        dt = np.dtype(dtype)
        count = int(np.prod(shape)) if shape else 1
        out[name] = np.frombuffer(body, dt, count, at).reshape(shape).copy()
    return out, head["extra"]


def _pack_instr(ins) -> bytes:
    names = {n: i for i, n in enumerate(sorted({op for op, _, _, _ in ins}))}
    arr = np.array([[names[op], *(list(a) + [-1, -1])[:2], *(list(o) + [-1, -1])[:2], len(a), len(o)]
                    for op, a, o, _ in ins], dtype=np.int64).reshape(-1, 7)
    return _pack_arrays({"arr": arr, "const": np.array([c for _, _, _, c in ins], float)},
                        ops=sorted(names, key=names.get))


def _unpack_instr(data: bytes):
    z, extra = _unpack_arrays(data)
    ops, arr, const = [str(o) for o in extra["ops"]], z["arr"], z["const"]
    return [(ops[r[0]], list(r[1:1 + r[5]]), list(r[3:3 + r[6]]), float(c))
            for r, c in zip(arr.tolist(), const.tolist())]


# --------------------------------------------------------------------------- C source


def _const(v: float) -> str:
    if v != v:
        return "NAN"
    if v in (float("inf"), float("-inf")):
        return "INFINITY" if v > 0 else "-INFINITY"
    return repr(v) if "." in repr(v) or "e" in repr(v) else repr(v) + "."


def _compress(sp) -> list[int]:
    return [int(v) for v in sp.compress()]


def c_source(f, name: str | None = None, chunk: int = CHUNK) -> str:
    """C for the SX Function ``f`` under ``name`` (default: its own), CasADi's calling convention."""
    name = name or f.name()
    return _kept(f, "c", lambda: _c_source(f, name, chunk), str.encode, bytes.decode, extra=f"{name}/{chunk}")


def _c_source(f, name: str, chunk: int) -> str:
    ins = instructions(f)
    n_in, n_out = f.n_in(), f.n_out()
    lines = ["#include <math.h>", "typedef long long sx_int;", _HELPERS]
    bodies, body, used_in, used_out = [], [], set(), set()

    def flush():
        head = "".join(f"const double *restrict i{a} = in[{a}]; " for a in sorted(used_in))
        head += "".join(f"double *restrict o{a} = out[{a}]; " for a in sorted(used_out))
        bodies.append(f"static void {name}_c{len(bodies)}(const double *const *in, double *const *out, "
                      f"double *restrict w) {{\n  {head}\n  " + "\n  ".join(body) + "\n}")
        body.clear(), used_in.clear(), used_out.clear()

    for op, a, o, const in ins:
        if op == "INPUT":
            used_in.add(a[0])
            body.append(f"w[{o[0]}]=i{a[0]}[{a[1]}];")
        elif op == "OUTPUT":
            used_out.add(o[0])
            body.append(f"o{o[0]}[{o[1]}]=w[{a[0]}];")
        elif op == "CONST":
            body.append(f"w[{o[0]}]={_const(const)};")
        elif op in BINARY:
            body.append(f"w[{o[0]}]=" + BINARY[op].format(f"w[{a[0]}]", f"w[{a[1]}]") + ";")
        else:
            body.append(f"w[{o[0]}]=" + UNARY[op].format(f"w[{a[0]}]") + ";")
        if len(body) >= chunk:
            flush()
    if body or not bodies:
        flush()
    lines += bodies
    max_in = max([f.nnz_in(i) for i in range(n_in)] + [1])
    max_out = max([f.nnz_out(i) for i in range(n_out)] + [1])
    call = "".join(f"  {name}_c{j}(in, out, w);\n" for j in range(len(bodies)))
    lines.append(
        f"static const double {name}_zeros[{max_in}];\n"
        f"int {name}(const double **arg, double **res, sx_int *iw, double *w, int mem) {{\n"
        f"  const double *in[{max(n_in, 1)}]; double *out[{max(n_out, 1)}]; double sink[{max_out}];\n"
        f"  for (int i = 0; i < {n_in}; i++) in[i] = arg[i] ? arg[i] : {name}_zeros;\n"
        f"  for (int i = 0; i < {n_out}; i++) out[i] = res[i] ? res[i] : sink;\n"
        f"{call}  return 0;\n}}")
    sps_in = [_compress(f.sparsity_in(i)) for i in range(n_in)]
    sps_out = [_compress(f.sparsity_out(i)) for i in range(n_out)]
    for kind, sps in (("in", sps_in), ("out", sps_out)):
        for i, sp in enumerate(sps):
            lines.append(f"static const sx_int {name}_sp_{kind}{i}[{len(sp)}] = {{{', '.join(map(str, sp))}}};")
        cases = "".join(f"    case {i}: return {name}_sp_{kind}{i};\n" for i in range(len(sps)))
        lines.append(f"const sx_int* {name}_sparsity_{kind}(sx_int i) {{\n  switch (i) {{\n{cases}"
                     f"    default: return 0;\n  }}\n}}")
        names = [f.name_in(i) for i in range(n_in)] if kind == "in" else [f.name_out(i) for i in range(n_out)]
        cases = "".join(f'    case {i}: return "{nm}";\n' for i, nm in enumerate(names))
        lines.append(f"const char* {name}_name_{kind}(sx_int i) {{\n  switch (i) {{\n{cases}"
                     f"    default: return 0;\n  }}\n}}")
    lines.append(
        f"sx_int {name}_n_in(void) {{ return {n_in}; }}\n"
        f"sx_int {name}_n_out(void) {{ return {n_out}; }}\n"
        f"double {name}_default_in(sx_int i) {{ return 0; }}\n"
        f"int {name}_work(sx_int *sz_arg, sx_int *sz_res, sx_int *sz_iw, sx_int *sz_w) {{\n"
        f"  if (sz_arg) *sz_arg = {n_in}; if (sz_res) *sz_res = {n_out}; if (sz_iw) *sz_iw = 0; "
        f"if (sz_w) *sz_w = {max(f.sz_w(), 1)}; return 0;\n}}\n"
        f"int {name}_checkout(void) {{ return 0; }}\nvoid {name}_release(int mem) {{ }}\n"
        f"void {name}_incref(void) {{ }}\nvoid {name}_decref(void) {{ }}")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- interpreter programs


class Program(vmprog.Program):
    """An SX Function as vm.c's program (eom/vmprog.py): ``prog`` (a ctypes record the
    interpreter reads; this object keeps its arrays alive) and ``nreg``, the work memory it
    needs (doubles)."""

    def __init__(self, f=None, arrays=None, grouped: bool = True):
        if arrays is None:
            arrays = (*_kept(f, "prog" if grouped else "prog1", lambda: _program_arrays(f, grouped), _pack_prog,
                             _unpack_prog), f.n_in(), f.n_out())
        super().__init__(arrays)


def _pack_prog(value) -> bytes:
    code, consts, in_off, in_nnz, nreg = value
    return _pack_arrays({"code": code, "consts": consts, "in_off": in_off, "in_nnz": in_nnz}, nreg=int(nreg))


def _unpack_prog(data: bytes):
    z, extra = _unpack_arrays(data)
    return (np.ascontiguousarray(z["code"], dtype=np.intc), np.ascontiguousarray(z["consts"], float),
            np.ascontiguousarray(z["in_off"], dtype=np.int64), np.ascontiguousarray(z["in_nnz"], dtype=np.int64),
            int(extra["nreg"]))


def _program_arrays(f, grouped: bool = True):
    """(instructions (4 ints each), constants, inputs' offsets, inputs' sizes, registers);
    ``grouped``: rescheduled into blocks (``_grouped``), for Functions evaluated many times."""
    ins = instructions(f)
    nnz = [f.nnz_in(i) for i in range(f.n_in())]
    off = np.cumsum([0, *nnz])
    consts: dict = {}
    for op, _, _, c in ins:
        if op == "CONST":
            consts.setdefault(np.float64(c).tobytes(), c)      # -0.0 and 0.0 kept apart
    const_off = int(off[-1])
    creg = {k: const_off + j for j, k in enumerate(consts)}
    base = const_off + len(consts)
    where: dict[int, int] = {}     # work slot -> register holding its current value
    code = []
    for op, a, o, c in ins:
        if op == "INPUT":
            where[o[0]] = int(off[a[0]] + a[1])
        elif op == "CONST":
            where[o[0]] = creg[np.float64(c).tobytes()]
        elif op == "OUTPUT":
            code.append((_VM_CODE["OUT"], o[1], where[a[0]], o[0]))
        else:
            code.append((_VM_CODE[op], base + o[0], where[a[0]], where[a[1]] if len(a) > 1 else 0))
            where[o[0]] = base + o[0]
    code, nwork = _grouped(code, base) if grouped else (code, f.sz_w())
    code.append((_VM_CODE["END"], 0, 0, 0))
    return (np.ascontiguousarray(np.array(code, dtype=np.intc).ravel()), np.array(list(consts.values()), float),
            np.ascontiguousarray(off[:-1], dtype=np.int64), np.ascontiguousarray(nnz, dtype=np.int64),
            max(base + nwork, 1))


# operations vm.c runs in blocks: one dispatch for a run of the same operation
_OUT = _VM_CODE["OUT"]
_BLOCKED = {_VM_CODE[n]: k for k, n in enumerate(("OUT", "ADD", "SUB", "MUL", "DIV"))}
_BLOCK = len(VM_OPS)       # vm.c's V_BLOCK: (V_BLOCK, count, operation, 0), then count records
_ONE_OPERAND = frozenset(_VM_CODE[n] for n in UNARY) | {_OUT}


def _grouped(code: list, base: int) -> tuple[list, int]:
    """``code`` (registers from ``base`` on written, CasADi's slot reuse) rescheduled so that
    operations of one kind run in blocks, and its registers allocated again (few live); an
    operation repeated on the same operand values is computed once (4 % of the 200-link ode).

    The interpreter's cost was its dispatch (~3 ns an operation, one unpredictable indirect jump
    each); a block of k operations is one dispatch and a counted loop.  The schedule: of the
    operations whose operands are computed, run every one of a kind (and those it makes ready),
    the kind with the most ready first, outputs last.  Every operation keeps its operands (the
    same values: the order only follows the data), so the bits are those of CasADi's order
    (tests/test_sxcode.py).  Returns (instructions with block headers, work registers used)."""
    n = len(code)
    defn: dict[int, int] = {}           # register -> instruction defining its current value
    da, db = [0] * n, [None] * n        # operands: an instruction's index, or ~register (input, constant)
    users: list[list] = [[] for _ in range(n)]
    indeg = [0] * n
    ops = [c[0] for c in code]
    seen: dict[tuple, int] = {}         # (operation, operands) -> the instruction computing it first
    kept = 0
    for i, (op, o, a, b) in enumerate(code):
        x = defn.get(a, ~a)
        y = None if op in _ONE_OPERAND else defn.get(b, ~b)
        if op != _OUT:
            j = seen.setdefault((op, x, y), i)
            if j != i:                  # the same operation on the same values: the same bits, computed once
                defn[o] = j
                indeg[i] = -1
                continue
            defn[o] = i
        da[i], db[i] = x, y
        kept += 1
        if x >= 0:
            users[x].append(i)
            indeg[i] += 1
        if y is not None and y >= 0 and y != x:
            users[y].append(i)
            indeg[i] += 1
    ready: dict[int, list] = {}
    for i in range(n):
        if not indeg[i]:
            ready.setdefault(ops[i], []).append(i)
    order, runs, cur, stack = [], [], None, []
    while len(order) < kept:
        if not stack:
            cur = max((k for k, v in ready.items() if v), key=lambda k: (k != _OUT, len(ready[k]), -k))
            runs.append(len(order))
            stack = ready[cur]
        i = stack.pop()
        order.append(i)
        for u in users[i]:
            indeg[u] -= 1
            if not indeg[u]:
                ready[ops[u]].append(u) if ops[u] in ready else ready.setdefault(ops[u], [u])
    last = [-1] * n                     # an instruction's value -> position of its last reader
    for pos, i in enumerate(order):
        if da[i] >= 0:
            last[da[i]] = pos
        if db[i] is not None and db[i] >= 0:
            last[db[i]] = pos
    reg, free, top, new = [0] * n, [], base, []
    for pos, i in enumerate(order):
        op, o, a, b = code[i]
        x, y = da[i], db[i]
        ra = reg[x] if x >= 0 else ~x
        rb = (reg[y] if y >= 0 else ~y) if y is not None else 0
        if x >= 0 and last[x] == pos:
            free.append(ra)
        if y is not None and y >= 0 and y != x and last[y] == pos:
            free.append(rb)
        if op == _OUT:
            new.append((op, o, ra, b))
            continue
        if free:
            r = free.pop()
        else:
            r, top = top, top + 1
        reg[i] = r
        if last[i] < 0:                 # never read: its register is free again at once
            free.append(r)
        new.append((op, r, ra, rb))
    out, bounds = [], runs + [kept]
    for s, e in zip(bounds, bounds[1:]):
        op = new[s][0]
        if e - s > 1 and op in _BLOCKED:
            out.append((_BLOCK, e - s, _BLOCKED[op], 0))
            out += [(0, r, x, y) for _, r, x, y in new[s:e]]
        else:
            out += new[s:e]
    return out, top - base


def program(f, grouped: bool = True) -> Program:
    """``f`` as an interpreter program; ``grouped = False`` for a few evaluations (a recorder on
    the output grid: rescheduling costs ~3.5 us an operation, what ~2000 evaluations save)."""
    return Program(f, grouped=grouped)


def c_unit(funcs, unit: str = "mechdsl_model.c") -> str:
    """One translation unit for ``funcs``: SX Functions as chunked C (``c_source``), the others
    through CasADi's code generator (MX Functions: calls, linear solves)."""
    import casadi as ca

    mine = [f for f in funcs if supported(f)]
    rest = [f for f in funcs if not any(f is g for g in mine)]
    parts = [c_source(f) for f in mine]
    if rest or not parts:
        cg = ca.CodeGenerator(unit, {"with_header": False, "verbose": False})
        for f in rest:
            cg.add(f)
        parts.insert(0, cg.dump())
    return "\n".join(parts)
