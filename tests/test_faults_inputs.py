"""Issue 25, models, inputs and the command line: odd inputs are clean errors or right answers.

Redundant joints simulate (checked against the single-hinge closed form and free fall), an
absurd joint axis and an absurd start time are located errors, and file names, scheduler
addresses and a full standard output are usage or I/O errors, never internal errors.
"""
from __future__ import annotations

import math
import os
import socket
import subprocess
import sys

import numpy as np
import re

import pytest

import mechdsl
from mechdsl.cli import main

from conftest import CHECKOUT, MODELS

DOOR = """
model Door "a trapdoor (a rod) on two coaxial hinges"
  parameter Real m(unit = "kg") = 2;
  parameter Real L(unit = "m") = 0.8;
  Gravity gravity(g = {0, -9.81, 0});
  Rod door(m = m, L = L, axis = {0, -1, 0});
  Point w1(body = world, r = {0, 0, 0.3});
  Point w2(body = world, r = {0, 0, -0.3});
  Point d1(body = door, r = {0, 0.4, 0.3});
  Point d2(body = door, r = {0, 0.4, -0.3});
  Revolute h1(parent = w1, child = d1, axis = {0, 0, 1}, phi(start = 1.2));
  Revolute h2(parent = w2, child = d2, axis = {0, 0, 1});
end Door;
"""

GUIDES = """
model Guides "a block on two identical prismatic guides"
  parameter Real m(unit = "kg") = 1;
  Gravity gravity(g = {0, -9.81, 0});
  PointMass b(m = m);
  Prismatic p1(parent = world, child = b, axis = {0, -1, 0}, s(start = 0));
  Prismatic p2(parent = world, child = b, axis = {0, -1, 0});
end Guides;
"""


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_door_on_two_coaxial_hinges_swings_as_on_one():
    """The second hinge adds only dependent rows: the door is a physical pendulum about the
    hinge line (I = m L^2/3, centre at L/2); its quarter period from 1.2 rad at rest is
    sqrt(I / (m g d)) K(sin^2(phi0/2)) (complete elliptic integral, parameter m = k^2)."""
    from scipy.special import ellipk

    m = mechdsl.loads(DOOR)
    mass, L, g, phi0 = 2.0, 0.8, 9.81, 1.2
    quarter = math.sqrt((mass * L**2 / 3) / (mass * g * L / 2)) * ellipk(math.sin(phi0 / 2) ** 2)
    r = m.simulate(1.5 * quarter, points=3001, rtol=1e-10, atol=1e-12)
    assert r.success, r.message
    phi = r["h1.phi"]
    i = int(np.flatnonzero(phi <= 0)[0])             # first zero crossing, linearly interpolated
    t0 = r.t[i - 1] + (r.t[i] - r.t[i - 1]) * phi[i - 1] / (phi[i - 1] - phi[i])
    assert abs(t0 - quarter) < 1e-5 * quarter
    assert phi.max() == pytest.approx(phi0, rel=1e-8)


def test_a_block_on_two_identical_guides_falls_freely():
    r = mechdsl.loads(GUIDES).simulate(1.0, points=11)
    assert r.success, r.message
    assert np.allclose(r["p1.s"], 0.5 * 9.81 * r.t**2, rtol=1e-7, atol=1e-9)


def test_redundant_joints_simulate_on_the_command_line(tmp_path, capsys):
    src = tmp_path / "door.mech"
    src.write_text(DOOR)
    assert main(["simulate", str(src), "--t-end", "0.5", "--no-progress", "-o", str(tmp_path / "d.csv")]) == 0


@pytest.mark.parametrize("axis", ["1e32, 0, 1", "1e10, 0, 1", "1, 0, 1e-16"])
def test_an_axis_with_components_far_apart_is_a_located_error(tmp_path, capsys, axis):
    """{1e32, 0, 1} on the falling rod hung the contact path for minutes: its small component
    is below what double precision resolves against the large one."""
    text = (MODELS / "falling_rod.mech").read_text()
    bad = text.replace("Planar fly(parent = world, child = rod, axis = {0, 0, 1},",
                       f"Planar fly(parent = world, child = rod, axis = {{{axis}}},", 1)
    assert bad != text
    path = tmp_path / "rod.mech"
    path.write_text(bad)
    line = bad[:bad.index(f"{{{axis}}}")].count("\n") + 1
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert f"{path}:{line}:" in err and "error[E513]" in err and "joint 'fly'" in err, err


def test_an_axis_with_comparable_components_is_fine(tmp_path, capsys):
    """Components 1e7 apart are resolved: no E513.  (The tilted plane turns the rod's start into
    the floor, which mech check reports as E861 since issue 23: the only error allowed.)"""
    text = (MODELS / "falling_rod.mech").read_text().replace(
        "Planar fly(parent = world, child = rod, axis = {0, 0, 1},",
        "Planar fly(parent = world, child = rod, axis = {1e-3, 0, 1e4},", 1)
    path = tmp_path / "rod.mech"
    path.write_text(text)
    rc = main(["check", str(path)])
    err = capsys.readouterr().err
    codes = set(re.findall(r"error\[(E\d+)\]", err))
    assert "E513" not in codes and codes <= {"E861"}, err
    assert rc == (1 if codes else 0)


def test_an_absurd_start_time_without_a_stop_time_is_located(tmp_path, capsys):
    path = tmp_path / "p.mech"
    path.write_text("model P\n  Rod rod(m = 1, L = 1, axis = {0, -1, 0});\n  Gravity g(g = {0, -9.81, 0});\n"
                    "  Revolute j(parent = world, child = rod.a, axis = {0, 0, 1}, phi(start = 1));\nend P;\n"
                    "scene S\n  model P;\n  start_time = -1e308;\nend S;\n")
    for cmd in (["check", str(path)], ["simulate", str(path), "--no-progress"]):
        assert main(cmd) == 1
        err = capsys.readouterr().err
        assert f"{path}:6:1: error[E604]" in err and "start_time" in err, err


# ------------------------------------------------------------------ the command line


LONG = "a" * 300


@pytest.mark.parametrize("cmd", [
    ["simulate", "{model}", "--t-end", "0.1", "--no-progress", "-o", "{dir}/" + LONG + ".csv"],
    ["sweep", "{model}", "--grid", "m=1,2", "--t-end", "0.1", "--points", "3", "--no-progress",
     "-o", "{dir}/" + LONG + ".nc"],
    ["sweep", "{model}", "--grid", "m=1,2", "--t-end", "0.1", "--points", "3", "--no-progress",
     "-o", "{dir}/" + LONG + ".csv"],
    ["animate", "{model}", "--t-end", "0.1", "-o", "{dir}/" + LONG + ".gif"],
    ["simulate", "{model}", "--t-end", "0.1", "--no-progress", "--plot", "{dir}/" + LONG + ".png"],
])
def test_a_file_name_too_long_is_a_usage_error(tmp_path, capsys, cmd):
    args = [a.format(model=MODELS / "pendulum.mech", dir=tmp_path) for a in cmd]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "too long" in err and "internal error" not in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_full_standard_output_is_an_io_error():
    """`mech check ... >/dev/full`: exit 1 with one line on stderr, no traceback."""
    if not os.path.exists("/dev/full"):
        pytest.fail("this test needs /dev/full (Linux)")
    with open("/dev/full", "w") as full:
        p = subprocess.run([sys.executable, "-m", "mechdsl", "check", str(MODELS / "pendulum.mech")],
                           stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    assert p.returncode == 1, p.stderr
    assert "No space left on device" in p.stderr and "Traceback" not in p.stderr
    assert "internal error" not in p.stderr and "Exception ignored" not in p.stderr


@pytest.mark.parametrize("address, text", [
    ("tcp://", "no host"),
    ("tcp://[::1", "address"),
    ("tcp://host:99999", "port"),
    ("tcp://host:http", "port"),
    ("tls://127.0.0.1:1", "TLS"),
    ("udp://127.0.0.1:8786", "unknown scheduler"),
])
def test_bad_scheduler_addresses_are_usage_errors(capsys, address, text):
    code = main(["sweep", str(MODELS / "pendulum.mech"), "--grid", "m=1,2", "--t-end", "0.1", "--no-progress",
                 "--scheduler", address])
    err = capsys.readouterr().err
    assert code == 2 and text in err and "internal error" not in err, err


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_port_that_speaks_another_protocol_is_refused_cheaply(capsys):
    """Dask read the junk's first 8 bytes as a frame length and tried to allocate 2.8 EiB."""
    import resource

    sys.path.insert(0, str(CHECKOUT / "benchmarks"))
    from faults import junk_server

    srv, stop = junk_server(b"SSH-2.0-OpenSSH_9.6 junk junk junk junk\r\n" * 4)
    try:
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        code = main(["sweep", str(MODELS / "pendulum.mech"), "--grid", "m=1,2", "--t-end", "0.1", "--no-progress",
                     "--scheduler", f"tcp://127.0.0.1:{srv.getsockname()[1]}"])
        grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    finally:
        stop()
    err = capsys.readouterr().err
    assert code == 2 and "not a Dask scheduler" in err and "internal error" not in err, err
    assert grown < 200_000          # kB: no huge buffer


def test_a_silent_port_times_out(capsys):
    """A server that accepts and says nothing: an error after connect_timeout, not a hang."""
    import time

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    try:
        t0 = time.perf_counter()
        m = mechdsl.load(MODELS / "pendulum.mech")
        with pytest.raises(mechdsl.diagnostics.UsageError, match="Dask scheduler"):
            m.sweep(params={"m": [1.0, 2.0]}, t_end=0.1, scheduler=f"tcp://127.0.0.1:{srv.getsockname()[1]}",
                    connect_timeout=2, progress=False)
        assert time.perf_counter() - t0 < 30
    finally:
        srv.close()
