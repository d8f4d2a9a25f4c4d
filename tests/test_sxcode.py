"""Straight-line code from SX algorithms (mechdsl.eom.sxcode): chunked C and interpreter programs.

Both translations must give the bits of CasADi's own generated C of the same Function (the
stepping loop's two engines give the same numbers, tests/test_crk.py), on every operation the
translation knows, at random points, including the special values (signed zeros, infinities,
NaN) that branches and comparisons treat differently."""
from __future__ import annotations

import ctypes
import re

import casadi as ca
import numpy as np
import pytest
from conftest import needs_cc

from mechdsl.eom import sxcode
from mechdsl.eom.codegen import compile_functions
from mechdsl.simulation.backends import crk



def every_op():
    """An SX Function (x[3], p[2]) -> (y[...], z[2]) using every operation sxcode translates."""
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    a, b, c = x[0], x[1], x[2]
    ys = [a + b, a - b, a * b, a / b, -a, ca.exp(a), ca.log(ca.fabs(a)), ca.power(ca.fabs(a), b), ca.fabs(a) ** 2.5,
          ca.sqrt(ca.fabs(b)), a * a, 2 * a, ca.sin(a), ca.cos(b), ca.tan(c), ca.asin(ca.sin(a)), ca.acos(ca.cos(b)),
          ca.atan(a), a < b, a <= b, a == b, a != b, ca.logic_not(a), ca.logic_and(a, b), ca.logic_or(a, c),
          ca.floor(a), ca.ceil(b), ca.fmod(a, b), ca.fabs(c), ca.sign(c), ca.copysign(a, c),
          ca.if_else(a < b, a * 3 + p[0], b - p[1]), ca.erf(a), ca.fmin(a, b), ca.fmax(a, c), 1 / a, ca.sinh(a),
          ca.cosh(b), ca.tanh(c), ca.asinh(a), ca.acosh(1 + ca.fabs(b)), ca.atanh(ca.tanh(c)), ca.atan2(a, b),
          ca.log1p(ca.fabs(a)), ca.expm1(b), ca.hypot(a, b), ca.remainder(a, b), p[0] * p[1] + 0.1, -0.0 * a,
          a + 1e-300, a * 1.0000000000000002]
    z = ca.vertcat(ca.sin(a) * p[0], a * b * c)
    return ca.Function("every", [x, p], [ca.vertcat(*ys), z], ["x", "p"], ["y", "z"])


def points(rng, n):
    special = [0.0, -0.0, 1.0, -1.0, 0.5, np.inf, -np.inf, np.nan, 1e-310, 3.0]
    out = []
    for k in range(n):
        if k < len(special):
            x = np.array([special[k], 0.7, -special[k]])
        else:
            x = rng.normal(size=3) * rng.choice([0.1, 1.0, 10.0])
        out.append((x, rng.normal(size=2)))
    return out


def call(fn, f, *args):
    """Evaluate a CasADi-convention C function ``fn`` (ctypes) of the Function ``f``."""
    ins = [np.ascontiguousarray(a, float) for a in args]
    outs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
    arg = (ctypes.POINTER(ctypes.c_double) * len(ins))(*[a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in ins])
    res = (ctypes.POINTER(ctypes.c_double) * len(outs))(*[o.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for o in outs])
    w = np.zeros(max(f.sz_w(), 1) + 1000)
    iw = (ctypes.c_longlong * (f.sz_iw() + 1))()
    assert fn(arg, res, iw, w.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), 0) == 0
    return outs


def same_bits(a, b):
    return np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64)) or \
        (np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(np.where(np.isnan(a), 0, a).view(np.int64),
                                                                       np.where(np.isnan(b), 0, b).view(np.int64)))


def interpreter(f):
    """(vm_eval, vm_init, the Fun record) of ``f``'s interpreter program in the runtime."""
    loop, _ = crk.build_loop({f.name(): f}, "t", "interpreted")
    prog = loop.funs[f.name()]
    vm_eval = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                               ctypes.c_void_p)(prog.eval)
    vm_init = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(prog.init)
    return vm_eval, vm_init, prog, loop


def interpret(vm, f, *args):
    vm_eval, vm_init, prog, _ = vm
    w = np.zeros(prog.sz_w)
    vm_init(prog.ctx, w.ctypes.data)
    outs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
    ins = [np.ascontiguousarray(a, float) for a in args]
    arg = (ctypes.c_void_p * len(ins))(*[v.ctypes.data for v in ins])
    res = (ctypes.c_void_p * len(outs))(*[o.ctypes.data for o in outs])
    assert vm_eval(prog.ctx, arg, res, None, w.ctypes.data) == 0
    return outs


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_chunked_c_and_the_interpreter_give_the_bits_of_casadis_generated_code(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    f = every_op()
    src = sxcode.c_source(f, "mine", chunk=7)       # many chunks: values cross function boundaries
    assert src.count("static void mine_c") == -(-sum(1 for _ in range(f.n_instructions())) // 7) or \
        src.count("static void mine_c") > 5
    loaded, note, path = compile_functions([f], jacobian=False, extra_units=(src,), extra_flags=["-O2"])
    assert loaded is not None, note
    lib = ctypes.CDLL(path)
    theirs, mine = lib.every, lib.mine
    vm = interpreter(f)
    rng = np.random.default_rng(5)
    n = 0
    for x, p in points(rng, 60):
        a = call(theirs, f, x, p)
        b = call(mine, f, x, p)
        outs = interpret(vm, f, x, p)
        for i in range(f.n_out()):
            assert same_bits(a[i], b[i]), (x, p, i, a[i], b[i])
            assert same_bits(a[i], outs[i]), (x, p, i, a[i], outs[i])
        ref = np.array(f(x, p)[0]).ravel()        # and the virtual machine, to round-off
        ok = np.isfinite(ref) & np.isfinite(a[0])
        assert np.allclose(a[0][ok], ref[ok], rtol=1e-13, atol=1e-300)
        n += ok.sum()
    assert n > 1000


def blocks(code) -> list[tuple[int, int]]:
    """(kind, count) of the blocks of an interpreter program (vm.c's V_BLOCK headers)."""
    out, k = [], 0
    while k < len(code):
        if code[k] == sxcode._BLOCK:
            out.append((int(code[k + 2]), int(code[k + 1])))
            k += 4 * int(code[k + 1])
        k += 4
    return out


@needs_cc
def test_the_rescheduled_program_of_a_chain_gives_casadis_bits(tmp_path, monkeypatch):
    """The interpreter runs a program rescheduled into blocks of one operation and with its
    registers allocated again (sxcode._grouped): an 8-link chain's ode (sin, cos, x*x, -x, /,
    outputs) gives the bits of CasADi's generated C at random states, and most of its
    operations run in blocks."""
    import mechdsl
    from conftest import MODELS
    from mechdsl.eom.codegen import casadi_functions

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    text = (MODELS / "nlink_pendulum.mech").read_text()
    m = mechdsl.loads(re.sub(r"parameter Integer N = \d+", "parameter Integer N = 8", text))
    f = casadi_functions(m.eom, names=("ode",))["ode"]
    loaded, note, path = compile_functions([f], jacobian=False, extra_flags=["-O1"])
    assert loaded is not None, note
    theirs = getattr(ctypes.CDLL(path), f.name())
    code = sxcode.program(f).ins
    found = blocks(code)
    in_blocks = sum(c for _, c in found)
    assert len(found) > 10 and in_blocks > 0.5 * f.n_instructions(), (len(found), in_blocks)
    vm = interpreter(f)
    rng = np.random.default_rng(8)
    for _ in range(20):
        args = [rng.normal(size=f.nnz_in(i)) * 2 for i in range(f.n_in())]
        a, b = call(theirs, f, *args), interpret(vm, f, *args)
        for i in range(f.n_out()):
            assert same_bits(a[i], b[i]), (i, a[i], b[i])
        assert np.allclose(np.array(f.call(args)[0]).ravel(), a[0], rtol=1e-12, atol=1e-12)


@needs_cc
def test_the_compiled_code_works_through_casadi_external(tmp_path, monkeypatch):
    """The chunked C keeps CasADi's calling convention: casadi.external loads and calls it."""
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    f = every_op()
    loaded, note, path = compile_functions([], jacobian=False, extra_units=(sxcode.c_source(f, "ext"),))
    ext = ca.external("ext", path)
    assert ext.name_in() == ["x", "p"] and ext.name_out() == ["y", "z"]
    x, p = np.array([0.3, -1.2, 2.0]), np.array([0.5, -0.25])
    for a, b in zip(ext(x, p), f(x, p)):
        np.testing.assert_allclose(np.array(a, float), np.array(b, float), rtol=1e-14)


def test_unknown_instructions_are_refused():
    x = ca.SX.sym("x")
    inner = ca.Function("inner", [x], [ca.sin(x)])
    mx = ca.MX.sym("x")
    with pytest.raises(sxcode.Unsupported):
        sxcode.c_source(ca.Function("m", [mx], [inner(mx)]))
    assert not sxcode.supported(ca.Function("m", [mx], [inner(mx)]))
    assert sxcode.supported(every_op())


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_c_size_and_chunks_grow_linearly_with_the_operations():
    """The C of an N-link chain's ode: bytes per operation flat from N = 10 to 80, every chunk
    at most CHUNK operations (gcc's time then grows linearly; benchmarks/codegen_scaling.py)."""
    import mechdsl
    from conftest import MODELS
    from mechdsl.eom.codegen import casadi_functions

    text = (MODELS / "nlink_pendulum.mech").read_text()
    per_op = []
    for n in (10, 40, 80):
        m = mechdsl.loads(re.sub(r"parameter Integer N = \d+", f"parameter Integer N = {n}", text))
        f = casadi_functions(m.eom, names=("ode",))["ode"]
        src = sxcode.c_source(f)
        bodies = re.findall(r"static void ode_c\d+\([^)]*\) \{(.*?)\n\}", src, flags=re.S)
        assert max(b.count(";") for b in bodies) <= sxcode.CHUNK + 10
        per_op.append(len(src) / f.n_instructions())
    assert max(per_op) <= 1.25 * min(per_op), per_op


@needs_cc
def test_an_operation_repeated_on_the_same_values_is_computed_once(tmp_path, monkeypatch):
    """x*y written twice is two instructions of CasADi's Function and one of the rescheduled
    program (the same IEEE operation on the same values: the same bits), with the outputs of
    CasADi's generated C."""
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    a, b = x * y, x * y                        # two nodes: CasADi keeps both
    f = ca.Function("twice", [x, y], [ca.vertcat(a + 1, b - 2, ca.sin(a) / ca.sin(b))])
    assert [op for op, *_ in sxcode.instructions(f)].count("MUL") == 2
    code = sxcode.program(f).ins.reshape(-1)
    ungrouped = sxcode.program(f, grouped=False).ins.reshape(-1)
    mul = sxcode._VM_CODE["MUL"]
    assert sum(1 for k in range(0, len(ungrouped), 4) if ungrouped[k] == mul) == 2
    # the grouped program: MUL singles (a block needs two of a kind in a row)
    singles = [k for k in range(0, len(code), 4) if code[k] == mul]
    assert len(singles) == 1 and not any(kind == sxcode._BLOCKED[mul] for kind, _ in blocks(code))
    loaded, note, path = compile_functions([f], jacobian=False, extra_flags=["-O1"])
    assert loaded is not None, note
    theirs = getattr(ctypes.CDLL(path), "twice")
    vm = interpreter(f)
    for xv, yv in ((0.3, -1.7), (2.0, 1e-300), (-0.0, 3.0)):
        r = call(theirs, f, [xv], [yv])[0]
        assert same_bits(r, interpret(vm, f, [xv], [yv])[0]), (xv, yv)
