"""Result files: CSV layout, byte-identical reruns, JSON sidecar, plots."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mechdsl.output.plot import plot_result
from mechdsl.simulate import simulate
from sim_models import chain, pendulum


def test_csv_columns_and_values(tmp_path):
    r = simulate(chain(2), 1.0, points=11)
    out = tmp_path / "r.csv"
    r.to_csv(out)
    lines = out.read_text().splitlines()
    assert lines[0] == ("time,theta1,theta2,der(theta1),der(theta2),x_tip,y_tip,"
                        "kinetic_energy,potential_energy,energy")
    assert len(lines) == 12
    row = [float(v) for v in lines[5].split(",")]
    assert row[0] == r.t[4] and row[1] == r.q[4, 0] and row[4] == r.qd[4, 1]   # full precision (repr)
    assert row[-1] == r["energy"][4]


@pytest.mark.slow_cases('scipy-radau')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("method", ["auto", "cvodes-bdf", "scipy-radau", "rk"])
def test_csv_is_byte_identical_across_runs(tmp_path, method):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    simulate(chain(3), 1.0, method=method, points=51).to_csv(a)
    simulate(chain(3), 1.0, method=method, points=51).to_csv(b)
    assert a.read_bytes() == b.read_bytes()


def test_progress_does_not_change_numbers(tmp_path):
    a = simulate(chain(2), 2.0, points=21, progress=False).to_csv_text()
    b = simulate(chain(2), 2.0, points=21, progress=lambda t, t1: None).to_csv_text()
    assert a == b


def test_json_sidecar(tmp_path):
    r = simulate(pendulum(), 1.0, points=5, rtol=1e-7)
    r.to_csv(tmp_path / "p.csv")
    meta = json.loads((tmp_path / "p.json").read_text())
    m = meta["metadata"]
    assert m["model"] == "Pendulum" and m["method"] == "dop853" and "not stiff" in m["method_reason"]
    assert m["options"]["rtol"] == 1e-7 and m["options"]["points"] == 5
    assert m["options"]["parameters"] == {"m": 1.0, "L": 1.0, "g": 9.81}
    assert m["options"]["start"]["theta"] == pytest.approx(math.pi / 2)
    assert set(m["versions"]) >= {"mechdsl", "casadi", "numpy", "python"}
    assert meta["stats"]["steps"] > 0 and meta["stats"]["wall_time"] > 0
    assert meta["success"] is True and meta["failure"] is None
    assert meta["columns"][0] == "time"


def test_existing_output_is_not_overwritten_without_permission(tmp_path):
    from mechdsl.diagnostics import UsageError

    r = simulate(pendulum(), 1.0, points=3)
    out = tmp_path / "p.csv"
    r.to_csv(out)
    r.to_csv(out, overwrite=False)          # mechdsl's own output may be replaced by a rerun
    mine = tmp_path / "mine.csv"
    mine.write_text("time,mine\n0,1\n")     # a file the user wrote is not
    with pytest.raises(UsageError, match="exists"):
        r.to_csv(mine, overwrite=False)
    assert mine.read_text() == "time,mine\n0,1\n"


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("suffix,magic", [(".png", b"\x89PNG"), (".svg", b"<?xml")])
def test_plot_writes_file_atomically(tmp_path, suffix, magic):
    r = simulate(chain(2), 1.0, points=21)
    out = plot_result(r, tmp_path / f"plot{suffix}")
    assert out.read_bytes().startswith(magic)
    assert [p.name for p in tmp_path.iterdir()] == [f"plot{suffix}"]       # no temporary files left


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_plot_of_failed_run_and_bad_suffix(tmp_path):
    from mechdsl.diagnostics import UsageError
    from sim_models import blowup

    r = simulate(blowup(), 3.0, points=31)
    assert plot_result(r, tmp_path / "f.png").stat().st_size > 1000
    with pytest.raises(UsageError, match="png"):
        plot_result(r, tmp_path / "f.jpg")


def test_singularity_monitor_closest_approach_and_warning():
    import casadi as ca

    e = pendulum(theta0=0.3)
    e = e.replace(singularity_monitors={"theta=0": ca.sin(e.q[0])})   # "singular" where sin(theta) = 0
    r = simulate(e, 1.0, points=201)
    rep = r.metadata["singularity"]["theta=0"]
    i = int(np.argmin(np.abs(np.sin(r["theta"]))))
    assert rep["closest"] == pytest.approx(abs(np.sin(r["theta"][i]))) and rep["time"] == r.t[i]
    assert any("singular configuration of theta=0" in w for w in r.metadata["warnings"])
    far = pendulum(theta0=0.3)
    far = far.replace(singularity_monitors={"theta=pi/2": ca.cos(far.q[0])})
    r2 = simulate(far, 1.0, points=51)
    assert r2.metadata["singularity"]["theta=pi/2"]["closest"] > 0.9
    assert not r2.metadata["warnings"]
