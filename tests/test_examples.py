"""The example models installed with mechdsl (issue 27): mechdsl.examples, ``mech examples``, and
the first steps of a new user in an empty folder after ``pip install`` (CI runs these against the
installed wheel, from a copy of tests/ outside the repository: .ci/run)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import mechdsl
import mechdsl.examples as ex
from mechdsl.cli import main
from mechdsl.diagnostics import UsageError

from cli_json import validate


def _declared_description(path: Path) -> str:
    """The description string of the model ``mech simulate FILE`` runs, read with a regular
    expression (independently of the parser that mechdsl.examples.description uses)."""
    text = path.read_text(encoding="utf-8")
    models = dict(re.findall(r'^model\s+(\w+)\s+"([^"]*)"', text, flags=re.M))
    scene = re.search(r"^scene\s+\w+.*?^\s*model\s+(\w+)", text, flags=re.M | re.S)
    name = scene.group(1) if scene else list(re.findall(r"^model\s+(\w+)", text, flags=re.M))[-1]
    return models.get(name, "")


def test_every_shipped_model_is_an_example_with_its_description():
    names = ex.names()
    assert len(names) >= 20 and "double_pendulum" in names and "pendulum" in names
    for name in names:
        p = ex.path(name)
        assert p.is_file() and p.suffix == ".mech" and p.stem == name
        assert ex.description(name) == _declared_description(p) != ""
        assert ex.description(name)[0].isupper(), f"{name}: a description reads as a sentence in `mech examples`"
    assert ex.path("pendulum.mech") == ex.path("pendulum")
    assert dict(ex.catalog())["double_pendulum"] == "Two uniform rods hinged in series"


def test_an_unknown_example_is_a_usage_error_with_a_suggestion():
    with pytest.raises(UsageError, match=r"no example named 'pendulm'; did you mean 'pendulum'\?"):
        ex.path("pendulm")


def test_an_example_loads_and_runs():
    r = mechdsl.load(ex.path("pendulum"), scene="Swing").simulate(0.5, points=11)
    assert r.success and len(r.t) == 11


def test_mech_examples_lists_names_and_descriptions(capsys):
    assert main(["examples"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == len(ex.names())
    for line, (name, desc) in zip(out, ex.catalog()):
        assert line.split()[0] == name and line.rstrip().endswith(desc)
    assert main(["examples", "--path", "kepler"]) == 0
    assert capsys.readouterr().out.split() == ["kepler", str(ex.path("kepler"))]


def test_copy_never_overwrites_without_force(tmp_path, capsys):
    dest = tmp_path / "ex"
    assert main(["examples", "--copy", str(dest)]) == 0
    copied = sorted(p.name for p in dest.iterdir())
    assert copied == sorted(n + ".mech" for n in ex.names())
    assert (dest / "pendulum.mech").read_bytes() == ex.path("pendulum").read_bytes()
    mine = dest / "pendulum.mech"
    mine.write_text("// my edits\n")
    capsys.readouterr()
    assert main(["examples", "--copy", str(dest)]) == 2
    err = capsys.readouterr().err
    assert "already exist" in err and "--force" in err
    assert mine.read_text() == "// my edits\n"                      # untouched
    assert main(["examples", "--copy", str(dest), "pendulum", "--force"]) == 0
    assert mine.read_bytes() == ex.path("pendulum").read_bytes()
    assert main(["examples", "--copy", str(tmp_path / "no" / "such")]) == 2   # no chain of new folders


def test_copy_follows_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        written = ex.copy(tmp_path / "ex", only=["kepler"])
    finally:
        os.umask(old)
    assert [p.name for p in written] == ["kepler.mech"]
    assert written[0].stat().st_mode & 0o777 == 0o640


# --------------------------------------------------------------------------- a new user's first steps


def _mech(*args, cwd):
    """``mech`` as installed (the console script beside this Python), in ``cwd``."""
    script = Path(sys.executable).with_name("mech")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "mechdsl"]
    return subprocess.run([*cmd, *args], cwd=cwd, capture_output=True, text=True, timeout=600)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_first_steps_in_an_empty_folder(tmp_path):
    """Issue 27's 'done': from an empty folder, `mech examples --copy ex`, `mech simulate
    ex/double_pendulum.mech -o dp.csv` and `mech simulate ex/pendulum.mech --json` work."""
    assert Path(sys.executable).with_name("mech").exists(), "the mech console script is not installed"
    r = _mech("examples", "--copy", "ex", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "ex" / "double_pendulum.mech").is_file()

    r = _mech("simulate", "ex/double_pendulum.mech", "-o", "dp.csv", "--no-progress", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    header = (tmp_path / "dp.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["time", "j1.phi", "j2.phi"]
    assert json.loads((tmp_path / "dp.json").read_text())["metadata"]["scene"] == "Chaos"

    r = _mech("simulate", "ex/pendulum.mech", "--json", "--no-progress", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)                   # exactly one JSON document on stdout
    validate(doc)
    res = doc["result"]
    assert doc["ok"] and res["model"] == "Pendulum" and res["scene"] == "Swing" and res["success"]
    assert res["t_end"] == pytest.approx(10.0) and res["points"] > 2
    assert res["accuracy"]["energy_drift_relative"] < 1e-6
    assert "model Pendulum" in r.stderr          # the human summary went to stderr


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_readme_shows_the_installed_form_and_it_works(tmp_path):
    """README.md's command for an installed package (no checkout) runs as written in an empty folder."""
    import shlex

    from conftest import CHECKOUT

    line = next(ln.strip() for ln in (CHECKOUT / "README.md").read_text().splitlines()
                if ln.strip().startswith("mech examples --copy "))
    for command in line.split("&&"):
        words = shlex.split(command)
        assert words[0] == "mech"
        r = _mech(*words[1:], cwd=tmp_path)
        assert r.returncode == 0, f"{command}: {r.stderr}"
    assert (tmp_path / "double_pendulum.csv").is_file() and (tmp_path / "double_pendulum.png").is_file()


# --------------------------------------------------------------------------- the rest of issue 27's 'done'


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """`mech examples --copy ex` and `mech sweep ex/pendulum.mech ... -o s.nc` with the installed
    `mech`, in an empty folder; the netCDF file opened with xarray."""
    import xarray as xr

    folder = tmp_path_factory.mktemp("sweep")
    assert _mech("examples", "--copy", "ex", "pendulum", cwd=folder).returncode == 0
    r = _mech("sweep", "ex/pendulum.mech", "--grid", "L=1:2:3", "--t-end", "1", "--points", "11", "-o", "s.nc",
              "--no-progress", cwd=folder)
    assert r.returncode == 0, r.stderr
    with xr.open_dataset(folder / "s.nc") as ds:
        yield ds.load(), r


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_a_sweep_to_netcdf_from_an_empty_folder(swept):
    ds, r = swept
    assert "3 runs, 3 succeeded" in r.stdout
    assert ds.sizes == {"run": 3, "time": 11} and list(ds["L"].values) == [1.0, 1.5, 2.0]
    assert ds.attrs["model"] == "Pendulum" and bool(ds["success"].all())
    # a longer rod swings slower: at t = 1 s the bob dropped from theta = pi/2 the least for L = 2
    assert float(ds["theta"].isel(time=-1, run=2)) > float(ds["theta"].isel(time=-1, run=0))


# issue 27: a sweep file from the installed package carries units, long names and provenance
@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_sweep_file_carries_units_and_provenance(swept):
    ds, _ = swept
    units = {name: ds[name].attrs.get("units") for name in ("time", "theta", "der(theta)", "x", "E", "L")}
    assert units == {"time": "s", "theta": "rad", "der(theta)": "rad/s", "x": "m", "E": "J", "L": "m"}
    assert ds["theta"].attrs.get("long_name") and ds["L"].attrs.get("long_name")
    assert ds.attrs.get("mechdsl_version") == mechdsl.__version__
    assert ds.attrs.get("model_hash")


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_lsp_answers_an_editor(tmp_path):
    """The installed `mech lsp` (the console script), started in an empty folder as an editor starts
    it: initialize, a copied example opened (its diagnostics: none), a hover, shutdown and exit."""
    from lsp_client import LspClient

    script = Path(sys.executable).with_name("mech")
    assert script.exists(), "the mech console script is not installed"
    path = ex.copy(tmp_path / "ex", only=["pendulum"])[0]
    text = path.read_text()
    c = LspClient({"debounceMs": 0}, command=[str(script), "lsp"], cwd=tmp_path)
    try:
        info = c.init_result["result"]
        assert info["serverInfo"]["name"] == "mechdsl" and info["serverInfo"]["version"] == mechdsl.__version__
        assert info["capabilities"]["hoverProvider"]
        uri = path.as_uri()
        c.open(uri, text)
        assert c.diagnostics(uri, 1)["diagnostics"] == []
        line = next(i for i, ln in enumerate(text.splitlines()) if "parameter Real L(" in ln)
        col = text.splitlines()[line].index("L(")
        hover = c.result("textDocument/hover", {"textDocument": {"uri": uri},
                                                "position": {"line": line, "character": col}})
        assert "length of the rod" in hover["contents"]["value"] and "m" in hover["contents"]["value"]
        assert c.internal_errors() == []
    finally:
        code = c.close()
    assert code == 0 and c.raw_out == []
