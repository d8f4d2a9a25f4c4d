"""CasADi Functions built from an EOM: names, numbers, laziness, compiled code, fast calls."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from mechdsl.eom.codegen import FastFunction, casadi_functions, compile_functions, find_compiler
from mechdsl.diagnostics import MechError
from mechdsl.simulate import simulate
from conftest import needs_cc
from sim_models import chain, pendulum

RNG = np.random.default_rng(12345)


def double_pendulum_accelerations(x, m1=1.0, m2=1.0, L1=1.0, L2=1.0, g=9.81):
    """Textbook equations of the double pendulum with point masses (independent of mechdsl)."""
    t1, t2, w1, w2 = x
    d = 2 * m1 + m2 - m2 * np.cos(2 * t1 - 2 * t2)
    a1 = (-g * (2 * m1 + m2) * np.sin(t1) - m2 * g * np.sin(t1 - 2 * t2)
          - 2 * np.sin(t1 - t2) * m2 * (w2**2 * L2 + w1**2 * L1 * np.cos(t1 - t2))) / (L1 * d)
    a2 = (2 * np.sin(t1 - t2) * (w1**2 * L1 * (m1 + m2) + g * (m1 + m2) * np.cos(t1)
                                 + w2**2 * L2 * m2 * np.cos(t1 - t2))) / (L2 * d)
    return np.array([a1, a2])


def test_function_names_and_signatures():
    f = casadi_functions(chain(3))
    assert list(f) == ["ode", "ode_jacobian", "mass_matrix", "bias", "energy", "outputs", "start", "parameters"]
    assert f["ode"].name_in() == ["t", "x", "u", "p"] and f["ode"].name_out() == ["xdot"]
    assert f["mass_matrix"].name_in() == ["q", "t", "p"] and f["mass_matrix"].name_out() == ["M"]
    assert f["energy"].name_out() == ["T", "V", "E"]
    assert f["outputs"].name_out() == ["x_tip", "y_tip"]
    with pytest.raises(KeyError):
        f["constraints"]


def test_ode_against_textbook_double_pendulum():
    f = casadi_functions(chain(2))
    ff = FastFunction(f["ode"])
    p = np.array([1.0, 1.0, 9.81])
    for _ in range(20):
        x = RNG.uniform(-3, 3, 4)
        xd = ff(0.0, x, [], p)
        np.testing.assert_array_equal(xd[:2], x[2:])
        np.testing.assert_allclose(xd[2:], double_pendulum_accelerations(x), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("N", [3, 12])
def test_numeric_qr_solve_matches_lapack(N):
    e = chain(N)
    f = casadi_functions(e)
    mm, bias, ode = FastFunction(f["mass_matrix"]), FastFunction(f["bias"]), FastFunction(f["ode"])
    for _ in range(5):
        x = RNG.uniform(-2, 2, 2 * N)
        M, b = mm(x[:N], 0.0, e.param_values), bias(0.0, x, [], e.param_values)
        qdd = ode(0.0, x, [], e.param_values)[N:]
        ref = np.linalg.solve(M, b)
        assert np.abs(qdd - ref).max() <= 1e-12 * np.abs(ref).max()
        assert np.linalg.norm(M @ qdd - b) <= 1e-14 * np.linalg.cond(M) * np.linalg.norm(b)


def test_ode_jacobian_matches_finite_differences():
    e = chain(3)
    f = casadi_functions(e)
    ode, jac = FastFunction(f["ode"]), FastFunction(f["ode_jacobian"])
    x = RNG.uniform(-1, 1, 6)
    J = jac(0.0, x, [], e.param_values)
    h = 1e-6
    Jfd = np.column_stack([(ode(0.0, x + h * ei, [], e.param_values) - ode(0.0, x - h * ei, [], e.param_values)) / (2 * h)
                           for ei in np.eye(6)])
    np.testing.assert_allclose(J, Jfd, rtol=1e-6, atol=1e-6)


def test_functions_are_lazy_and_outputs_selectable():
    e = chain(2)
    f = casadi_functions(e, outputs=["y_tip"])
    assert f._cache == {}
    f["energy"]
    assert list(f._cache) == ["energy"]
    assert f["outputs"].name_out() == ["y_tip"]
    assert casadi_functions(e, outputs=["y_tip"]) is f      # cached on the EOM


def test_fast_function_equals_plain_calls():
    e = chain(3)
    f = casadi_functions(e)
    p = e.param_values
    for name in ("ode", "ode_jacobian", "bias", "energy", "outputs"):
        fast = FastFunction(f[name])
        for _ in range(3):
            x = RNG.uniform(-2, 2, 6)
            plain = f[name](0.3, x, [], p)
            plain = plain if isinstance(plain, (list, tuple)) else [plain]
            got = fast(0.3, x, [], p)
            got = got if isinstance(got, tuple) else (got,)
            for a, b in zip(got, plain):
                np.testing.assert_array_equal(np.asarray(a).reshape(np.array(b).shape), np.array(b))
    fm = FastFunction(f["mass_matrix"])
    q = RNG.uniform(-2, 2, 3)
    np.testing.assert_array_equal(fm(q, 0.0, p), np.array(f["mass_matrix"](q, 0.0, p)))


def test_structurally_singular_mass_matrix_is_a_model_error():
    import casadi as ca

    from mechdsl import eom as E

    q, qd, t, p = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("t"), ca.SX.sym("p", 0)
    e = E.from_lagrangian("NoInertia", ["a", "b"], [], [], q, qd, t, p, 0.5 * qd[0] ** 2, q[1] ** 2)
    with pytest.raises(MechError, match="structurally singular: b has no inertia"):
        casadi_functions(e)["ode"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_compiled_functions_equal_virtual_machine(tmp_path, monkeypatch):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    e = chain(2)
    vm = casadi_functions(e)
    cf = casadi_functions(e, compiled=True)
    if find_compiler() is None:  # no compiler: the fallback must say so (never silently)
        cf["ode"]
        assert not cf.compiled and "no C compiler" in cf.notes[0]
        return
    assert cf["ode"].class_name() == "External" and cf.compiled
    assert "compiled" in cf.notes[0] and cf.library.startswith(str(tmp_path))
    flags = re.search(r"\(([^)]*)\) into", cf.notes[0]).group(1).split(", ")
    assert len(flags) == len(set(flags)), cf.notes[0]     # each set of flags once ("-O2, -O2" before)
    p = e.param_values
    for _ in range(10):
        x = RNG.uniform(-3, 3, 4)
        for name in ("ode", "ode_jacobian", "energy", "outputs"):
            a, b = cf[name](0.0, x, [], p), vm[name](0.0, x, [], p)
            for u, v in zip(a if isinstance(a, (list, tuple)) else [a], b if isinstance(b, (list, tuple)) else [b]):
                np.testing.assert_allclose(np.array(u), np.array(v), rtol=1e-13, atol=1e-13)
    # same right-hand side values -> the explicit method takes the same steps
    r_vm = simulate(e, 2.0, method="erk", points=11)
    r_c = simulate(e, 2.0, method="erk", points=11, compiled=True)
    assert r_c.metadata["options"]["compiled"] is True
    np.testing.assert_allclose(r_c.q, r_vm.q, rtol=1e-12, atol=1e-12)
    # BDF also uses the compiled Jacobian: step histories may differ, results agree to the tolerance
    b_vm = simulate(e, 2.0, method="cvodes-bdf", points=11)
    b_c = simulate(e, 2.0, method="cvodes-bdf", points=11, compiled=True)
    assert b_c.stats["jac_evals"] > 0
    np.testing.assert_allclose(b_c.q, b_vm.q, rtol=0, atol=1e-7)
    # second build: the same code is found in the cache
    from mechdsl.eom.codegen import _build

    _, note, lib = compile_functions([_build(e, "energy", None)])
    _, note2, lib2 = compile_functions([_build(e, "energy", None)])
    assert lib == lib2 and note2.startswith("loaded compiled model from cache")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@needs_cc
def test_cvodes_adams_compiles_no_jacobian(tmp_path, monkeypatch):
    """Functional iteration sets the Jacobian up but never evaluates it: the library holds the
    forward derivative (issue 16: 774 kB of Jacobian C and 51 s of gcc for the 12-link chain)."""
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    e = chain(3)
    fs = casadi_functions(e, compiled=True, names=("ode", "ode_jacobian"), jacobian="forward")
    fs["ode"]
    assert fs.compiled and "forward derivative" in fs.notes[0]
    x = RNG.uniform(-3, 3, 6)
    J, Jvm = fs["ode_jacobian"](0.0, x, [], e.param_values), casadi_functions(e)["ode_jacobian"](0.0, x, [], e.param_values)
    np.testing.assert_allclose(np.array(J), np.array(Jvm), rtol=1e-12, atol=1e-12)
    r = simulate(e, 1.0, method="cvodes-adams", points=11, compiled=True)
    assert r.success and any("forward derivative" in n for n in r.metadata["notes"])
    np.testing.assert_allclose(r.q, simulate(e, 1.0, method="cvodes-adams", points=11).q, rtol=0, atol=1e-12)


def test_missing_compiler_falls_back_with_a_note(monkeypatch, tmp_path):
    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "/nonexistent/cc")
    e = pendulum()
    f = casadi_functions(e, compiled=True)
    assert f["ode"].class_name() != "External"
    assert not f.compiled and "no C compiler" in f.notes[0]
    assert "$CC = '/nonexistent/cc' is not a program" in f.notes[0]     # not "looked for $CC, gcc, ..."
    r = simulate(e, 1.0, compiled=True, points=3)
    assert r.success and r.metadata["options"]["compiled"] is False
    assert any("compiled code unavailable" in w for w in r.metadata["warnings"])
    # said once, as the warning: not repeated as a note (the command line printed both)
    assert not any("no C compiler" in n for n in r.metadata["notes"])


def test_bound_fast_function_equals_plain_calls():
    e = chain(2)
    f = casadi_functions(e)
    rhs = FastFunction(f["ode"]).bind(u=[], p=e.param_values)
    jac = FastFunction(f["ode_jacobian"]).bind(u=[], p=e.param_values)
    for _ in range(3):
        x = RNG.uniform(-2, 2, 4)
        a = rhs(0.5, x)
        b = rhs(0.7, x + 1)
        np.testing.assert_array_equal(a, np.array(f["ode"](0.5, x, [], e.param_values)).ravel())
        np.testing.assert_array_equal(b, np.array(f["ode"](0.7, x + 1, [], e.param_values)).ravel())
        np.testing.assert_array_equal(jac(0.5, x), np.array(f["ode_jacobian"](0.5, x, [], e.param_values)))
    with pytest.raises(KeyError):
        FastFunction(f["ode"]).bind(q=1)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_concurrent_compilation_into_one_cache(tmp_path, monkeypatch):
    import threading

    from mechdsl.eom.codegen import _build

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    if find_compiler() is None:
        assert compile_functions([_build(pendulum(), "energy", None)])[0] is None
        return
    e = pendulum()
    results = []

    def work():
        results.append(compile_functions([_build(e, "energy", None), _build(e, "ode", None)], jacobian=False))

    threads = [threading.Thread(target=work) for _ in range(3)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    libs = {lib for _, _, lib in results}
    assert len(libs) == 1 and all(loaded is not None for loaded, _, _ in results)
    lib = Path(next(iter(libs)))
    # no debris (compilers: the compiler's version, kept for later runs; sxcode: the Functions'
    # instruction lists, mechdsl.eom.sxcode)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([lib.with_suffix(".sha256").name, lib.name,
                                                                 "compilers", "sxcode"])
    assert not [p.name for p in (tmp_path / "sxcode").iterdir() if p.name.startswith(".tmp")]
    x = np.array([0.3, -0.2])
    for loaded, _, _ in results:
        np.testing.assert_array_equal(np.array(loaded["ode"](0.0, x, [], e.param_values)),
                                      np.array(casadi_functions(e)["ode"](0.0, x, [], e.param_values)))


def test_compiler_version_is_asked_once_per_compiler(tmp_path, monkeypatch):
    """A warm run starts no `cc --version` process: the answer is kept by the compiler's path,
    size and time; a changed compiler is asked again."""
    import os
    import subprocess

    from mechdsl.eom.codegen import compiler_version

    monkeypatch.setenv("MECHDSL_CACHE", str(tmp_path))
    cc = tmp_path / "fakecc"
    cc.write_text("#!/bin/sh\necho fake cc 1.0\n")
    cc.chmod(0o755)
    calls = []
    real = subprocess.run
    monkeypatch.setattr(subprocess, "run", lambda *a, **k: calls.append(a) or real(*a, **k))
    assert compiler_version(str(cc)) == "fake cc 1.0" and len(calls) == 1
    assert compiler_version(str(cc)) == "fake cc 1.0" and len(calls) == 1       # kept
    cc.write_text("#!/bin/sh\necho fake cc 2.0 newer\n")
    os.utime(cc, ns=(1, 10**18))
    assert compiler_version(str(cc)) == "fake cc 2.0 newer" and len(calls) == 2
    assert compiler_version(str(tmp_path / "missing")) == str(tmp_path / "missing")
