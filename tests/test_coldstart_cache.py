"""Issue 24 item 8 (cold start): what a warm ``mech simulate`` no longer does, and that the
shortcuts give what the long way gives.  Times are measured in benchmarks/first_run.py and
benchmarks/coldstart.py, never here."""
import hashlib
import os
import subprocess
import sys

import casadi as ca
import pytest

import mechdsl
from mechdsl import digest, numbers
from mechdsl.eom import modelcache, sxcode
from mechdsl.model import units as U
from mechdsl.output.units import signal_units

from conftest import MODELS, drop_prepared_runs


# ----------------------------------------------------------------------------- SHA-256


@pytest.mark.parametrize("data", [b"", b"abc", bytes(range(256)) * 4099])
def test_the_builtin_sha256_is_hashlibs(data):
    assert digest.sha256(data).hexdigest() == hashlib.sha256(data).hexdigest()
    assert digest._builtin(data).hexdigest() == hashlib.sha256(data).hexdigest()     # (hashlib is loaded here)
    h, g = digest._builtin(), hashlib.sha256()
    for k in range(0, len(data), 1000):
        h.update(data[k:k + 1000])
        g.update(data[k:k + 1000])
    assert h.hexdigest() == g.hexdigest()


def test_small_inputs_do_not_load_openssl_large_ones_do():
    code = ("import sys, mechdsl.digest as d; d.sha256(b'x' * (d.LARGE - 1)).hexdigest(); "
            "print('_hashlib' in sys.modules); d.sha256(b'x' * d.LARGE).hexdigest(); print('_hashlib' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True"]


# ----------------------------------------------------------------------------- units


def test_the_units_kept_as_written_are_what_the_unit_parser_says():
    for u in numbers.SI_AS_WRITTEN:
        assert U.si_unit(u) == u, u
        assert numbers.si_unit(u) == u
    # the others still go through the parser
    assert numbers.si_unit("deg") == "rad" and numbers.si_unit("mm") == "m" and numbers.si_unit("deg/s") == "rad/s"
    assert numbers.si_unit(None) is None and numbers.si_unit("") is None


def test_column_units_of_a_degree_model_are_still_si():
    m = mechdsl.loads("""model D
  parameter Real L(unit = "m") = 1;
  parameter Real m(unit = "kg") = 1;
  coordinate Real a(start = 10, unit = "deg");
  coordinate Real x(start = 0, unit = "mm");
  output Real h(unit = "cm") = L*cos(a);
equation
  kinetic = 1/2*m*L^2*der(a)^2 + 1/2*m*der(x)^2;
  potential = m*9.81*L*(1 - cos(a));
end D;
""", cache=False)
    r = m.simulate(0.1, points=3, error_estimate="off")
    units = signal_units(r)
    assert units["a"] == "rad" and units["der(a)"] == "rad/s"
    assert units["x"] == "m" and units["h"] == "m" and units["energy"] == "J" and units["time"] == "s"


# ----------------------------------------------------------------------------- the code fingerprint


def test_the_code_fingerprint_sees_subfolders_and_new_files_not_bytecode(tmp_path, monkeypatch):
    pkg = tmp_path / "src" / "mechdsl"
    (pkg / "eom").mkdir(parents=True)
    (pkg / "eom" / "modelcache.py").write_text("# stand-in\n")
    deep = pkg / "simulation" / "backends"
    deep.mkdir(parents=True)
    (deep / "ode.py").write_text("x = 1\n")
    (tmp_path / "grammar").mkdir()
    (tmp_path / "grammar" / "mech.lark").write_text("start: NAME\n")
    monkeypatch.setattr(modelcache, "__file__", str(pkg / "eom" / "modelcache.py"))

    def fingerprint():
        monkeypatch.setattr(modelcache, "_FINGERPRINT", [])
        return modelcache.code_fingerprint()

    first = fingerprint()
    assert fingerprint() == first                                  # deterministic
    (deep / "__pycache__").mkdir()
    (deep / "__pycache__" / "ode.cpython-311.pyc").write_bytes(b"\0" * 10)
    (deep / "notes.txt").write_text("not code\n")
    assert fingerprint() == first                                  # bytecode and other files: no change
    (deep / "ode.py").write_text("x = 22\n")                       # a file two folders down, edited
    second = fingerprint()
    assert second != first
    (deep / "events.py").write_text("")                            # a new module
    third = fingerprint()
    assert third not in (first, second)
    (tmp_path / "grammar" / "mech.lark").write_text("start: NAME NAME\n")   # the grammar of the checkout
    assert fingerprint() not in (first, second, third)


# ----------------------------------------------------------------------------- stored Functions


def test_stored_functions_of_one_text_are_read_once_and_keep_their_sxcode_key():
    x = ca.SX.sym("x", 2)
    f = ca.Function("ode", [x], [ca.vertcat(x[1], -ca.sin(x[0]))])
    text = f.serialize()
    g = ca.Function("energy", [x], [x[1] ** 2 / 2 - ca.cos(x[0])])
    funcs = modelcache._functions_of({("ode", None, False): text, ("ode", None, True): text,
                                      ("energy", None, False): g.serialize()})
    a, b, e = funcs[("ode", None, False)], funcs[("ode", None, True)], funcs[("energy", None, False)]
    assert a is b and a is not e
    assert a.serialize() == text                                   # the round trip is the text
    # the key from the stored text is the key from serializing the Function again
    key = sxcode._key(a)
    sxcode._KEYS.pop(id(a))
    assert sxcode._key(a) == key
    assert [float(v) for v in ca.DM(a([0.3, 0.2])).nonzeros()] == [float(v) for v in ca.DM(f([0.3, 0.2])).nonzeros()]


# ----------------------------------------------------------------------------- a warm process


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_warm_run_loads_neither_openssl_nor_the_unit_parser(tmp_path):
    """The 12-link chain (coordinates in rad, outputs in m) with an output file: its cache keys,
    checks and CSV hash use CPython's SHA-256, its units need no parser."""
    env = {**os.environ, "MECHDSL_CACHE": str(tmp_path)}
    args = ["simulate", str(MODELS / "nlink_pendulum.mech"), "--set", "N=3", "--t-end", "0.2", "--points", "5",
            "--no-progress", "-o", str(tmp_path / "r.csv"), "--force"]
    subprocess.run([sys.executable, "-m", "mechdsl", *args], capture_output=True, env=env)     # fills the cache
    names = set()
    for path in ("mechdsl.simulation.warm_run", "mechdsl.simulation.backends.ode"):   # prepared, then normal
        r = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], capture_output=True,
                           text=True, env=env)
        assert r.returncode == 0, r.stderr[-2000:]
        seen = {line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time")}
        assert path in seen                                            # the check sees the imports
        names |= seen
        drop_prepared_runs(tmp_path)
    base = subprocess.run([sys.executable, "-c", "import sys, numpy, casadi; print(chr(10).join(sys.modules))"],
                          capture_output=True, text=True).stdout.split()
    assert {"hashlib", "_hashlib", "fractions", "decimal", "mechdsl.model.units"} & names - set(base) == set()


# ----------------------------------------------------------------------------- probe states in one call


def test_probe_states_in_one_map_call_are_the_calls_one_by_one():
    import numpy as np

    from mechdsl.analysis.core import Probe, at_states, dense

    q, qd, t, p = ca.SX.sym("q", 3), ca.SX.sym("qd", 3), ca.SX.sym("t"), ca.SX.sym("p", 2)
    outs = [ca.sin(q) * p[0] + qd * t, ca.SX.zeros(0, 3), ca.mtimes(q, qd.T) / (1 + p[1] * q[0] ** 2),
            ca.sqrt(q[1]) + ca.sum1(qd)]                      # a matrix, an empty one, NaN where q[1] < 0
    pr = Probe.states(3, count=9)
    pv = np.array([1.5, -0.25])
    for f in (ca.Function("f", [q, qd, t, p], outs), ca.Function("g", [q, qd, t, p], [outs[2]])):
        batch = at_states(f, pr, pv)
        one = [[dense(o) for o in (f(pr.q[i], pr.qd[i], pr.t[i], pv) if f.n_out() > 1
                                   else [f(pr.q[i], pr.qd[i], pr.t[i], pv)])] for i in range(len(pr))]
        assert len(batch) == len(one) == 9
        for a, b in zip(batch, one):
            assert [x.shape for x in a] == [y.shape for y in b]
            assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))    # bit for bit
    assert any(not np.all(np.isfinite(r[3])) for r in at_states(ca.Function("f", [q, qd, t, p], outs), pr, pv))
