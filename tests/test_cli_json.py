"""``--json``, ``-q`` and ``-v`` on every command (issue 27): exactly one JSON document on stdout,
valid against the shipped schema (mechdsl/schemas/cli-output.schema.json), human text on stderr,
errors as the document too with the exit code unchanged; the library's messages via logging."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from mechdsl.cli import build_parser, main
from mechdsl.commands import COMMANDS

from cli_json import validate
from conftest import MODELS, TESTS

PENDULUM = str(MODELS / "pendulum.mech")


def run_json(capsys, *args) -> tuple[int, dict, str]:
    rc = main([*args, "--json"])
    cap = capsys.readouterr()
    doc = json.loads(cap.out)              # the whole of stdout is one JSON document
    validate(doc)
    assert doc["exit_code"] == rc and doc["ok"] == (rc == 0)
    return rc, doc, cap.err


def test_every_command_has_json_quiet_and_verbose():
    for name in COMMANDS:
        p = build_parser(name)
        sub = next(a for a in p._actions if a.dest == "command").choices[name]
        options = {s for a in sub._actions for s in a.option_strings}
        assert {"--json", "-q", "--quiet", "-v", "--verbose"} <= options, name


def test_simulate(capsys, tmp_path):
    out = tmp_path / "p.csv"
    rc, doc, err = run_json(capsys, "simulate", PENDULUM, "--t-end", "1", "--points", "11", "-o", str(out),
                            "--no-progress")
    assert rc == 0 and doc["command"] == "simulate" and doc["error"] is None
    r = doc["result"]
    assert r["model"] == "Pendulum" and r["scene"] == "Swing" and r["success"] and r["points"] == 11
    assert r["t_start"] == 0 and r["t_end"] == pytest.approx(1.0)
    assert r["statistics"]["steps"] > 0 and r["statistics"]["cpu_time"] >= 0
    assert r["accuracy"]["rtol"] > 0 and r["accuracy"]["energy_drift"] >= 0
    assert r["columns"][:3] == ["time", "theta", "der(theta)"]
    assert r["units"] == {**{c: r["units"][c] for c in r["columns"]}, "time": "s", "theta": "rad",
                          "der(theta)": "rad/s", "x": "m", "energy": "J"}
    assert json.loads((tmp_path / "p.json").read_text())["units"] == r["units"]     # the sidecar's
    assert doc["files_written"] == [str(out), str(tmp_path / "p.json")]
    assert "model Pendulum: t = 0 .. 1 s (11 points)" in err and "wrote" in err
    assert " s CPU, " in err and " s wall" in err and re.search(r"max \|E - E\(0\)\| = \S+ J ", err)


def test_a_failed_run_is_exit_1_with_its_result(capsys, tmp_path):
    f = tmp_path / "blowup.mech"
    f.write_text("model Blow\n  coordinate Real x(start = 1, speed = 0);\n"
                 "equation\n  kinetic = 1/2*der(x)^2;\n  potential = -x^4;\nend Blow;\n")
    rc, doc, _ = run_json(capsys, "simulate", str(f), "--t-end", "10", "--no-progress")
    assert rc == 1 and doc["error"]["kind"] == "simulation"
    assert doc["result"]["success"] is False and doc["result"]["failure"]["time"] < 10


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_check_ok_and_diagnostics(capsys):
    rc, doc, _ = run_json(capsys, "check", PENDULUM)
    assert rc == 0
    (f,) = doc["result"]["files"]
    assert f["ok"] and {(t["kind"], t["name"]) for t in f["targets"]} >= {("scene", "Swing"), ("model", "Pendulum")}
    bad = TESTS / "corpus" / "E201_undefined_in_binding.mech"
    rc, doc, err = run_json(capsys, "check", str(bad), PENDULUM)
    assert rc == 1 and doc["error"]["kind"] == "model"
    d = doc["diagnostics"][0]
    assert (d["code"], d["file"], d["line"], d["column"], d["severity"]) == ("E201", str(bad), 4, 22, "error")
    assert d["message"] and "hint" in d
    assert [f["ok"] for f in doc["result"]["files"]] == [False, True]
    assert f"{bad}:4:22: error[E201]" in err                  # the human form on stderr


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_model_error_and_usage_error_are_documents(capsys, tmp_path):
    rc, doc, _ = run_json(capsys, "simulate", str(tmp_path / "missing.mech"))
    assert rc == 1 and doc["diagnostics"][0]["code"] == "E001" and doc["diagnostics"][0]["line"] is None
    rc, doc, err = run_json(capsys, "simulate", PENDULUM, "--bogus")
    assert rc == 2 and doc["error"]["kind"] == "usage" and "--bogus" in doc["error"]["message"]
    assert "usage: mech" in err
    rc, doc, _ = run_json(capsys, "simulate", PENDULUM, "--set", "nosuch=1")
    assert rc == 2 and doc["error"]["kind"] == "usage"


@pytest.mark.parametrize("emit", ["ast", "model"])
def test_compile_text_is_the_result(capsys, emit):
    rc, doc, _ = run_json(capsys, "compile", PENDULUM, "--emit", emit)
    assert rc == 0 and doc["result"]["emit"] == emit and "Pendulum" in doc["result"]["text"]
    assert main(["compile", PENDULUM, "--emit", emit]) == 0
    assert capsys.readouterr().out == doc["result"]["text"]    # the same text as without --json


def test_equations(capsys):
    rc, doc, _ = run_json(capsys, "equations", PENDULUM, "--model", "PendulumLagrange")
    assert rc == 0 and doc["result"]["form"] == "lagrange" and "theta" in doc["result"]["text"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_equilibrium_and_linearize(capsys, tmp_path):
    rc, doc, _ = run_json(capsys, "equilibrium", PENDULUM, "--model", "PendulumLagrange")
    res = doc["result"]
    assert rc == 0 and res["count"] == 2 and res["coordinates"] == ["theta"]
    stable = [e for e in res["equilibria"] if e["stability"] == "stable"]
    assert len(stable) == 1 and abs(stable[0]["values"]["theta"]) < 1e-9
    rc, doc, _ = run_json(capsys, "linearize", PENDULUM, "--model", "PendulumLagrange", "-o", str(tmp_path / "l.json"))
    res = doc["result"]
    assert rc == 0 and res["K"][0][0] == pytest.approx(9.81) and res["M"][0][0] == pytest.approx(1.0)
    assert doc["files_written"] == [str(tmp_path / "l.json")]


def test_animate(capsys, tmp_path):
    out = tmp_path / "a.gif"
    rc, doc, _ = run_json(capsys, "animate", PENDULUM, "-o", str(out), "--t-end", "0.2", "--fps", "10",
                          "--speed", "1", "--size", "64x64")
    assert rc == 0 and doc["files_written"] == [str(out)] and out.is_file()
    assert doc["result"]["frames"] == 3 and doc["result"]["fps"] == 10


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_view(capsys, tmp_path):
    out = tmp_path / "p.html"
    rc, doc, err = run_json(capsys, "view", PENDULUM, "-o", str(out), "--t-end", "0.2", "--fps", "10", "--speed", "1")
    res = doc["result"]
    assert rc == 0 and doc["files_written"] == [str(out)] and out.is_file()
    assert res["model"] == "Pendulum" and res["mode"] == "3d" and not res["still"] and res["success"]
    assert res["frames"] == 3 and res["fps"] == 10 and res["speed"] == 1
    assert res["t_start"] == 0 and res["t_end"] == pytest.approx(0.2)
    assert "wrote" in err                                     # the human text went to stderr
    rc, doc, _ = run_json(capsys, "view", PENDULUM, "-o", str(out), "--still")
    assert rc == 0 and doc["result"]["still"] and doc["result"]["frames"] == 1 and doc["result"]["fps"] is None


def test_a_failed_view_is_exit_1_with_its_result(capsys, tmp_path):
    f = tmp_path / "blowup.mech"
    f.write_text("model Blow\n  coordinate Real x(start = 1, speed = 0);\n"
                 "equation\n  kinetic = 1/2*der(x)^2;\n  potential = -x^4;\nend Blow;\n")
    rc, doc, _ = run_json(capsys, "view", str(f), "-o", str(tmp_path / "b.html"), "--t-end", "10", "--fps", "5",
                          "--speed", "1")
    assert rc == 1 and doc["error"]["kind"] == "simulation" and "viewed up to" in doc["error"]["message"]
    assert doc["result"]["success"] is False and doc["result"]["t_end"] < 10
    assert doc["files_written"] == [str(tmp_path / "b.html")]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_export(capsys, tmp_path):
    out = tmp_path / "p.fmu"
    rc, doc, err = run_json(capsys, "export", PENDULUM, "--fmu", str(out), "--fmi-type", "cs")
    res = doc["result"]
    assert rc == 0 and doc["files_written"] == [str(out)] and out.stat().st_size == res["size"]
    assert res["model"] == "Pendulum" and res["fmi_version"] == "2.0" and res["interfaces"] == ["co-simulation"]
    assert res["identifier"] == "Pendulum" and res["variables"] > 0
    import zipfile

    xml = zipfile.ZipFile(out).read("modelDescription.xml").decode()
    assert 'modelIdentifier="Pendulum"' in xml and "<ModelExchange" not in xml
    assert "wrote" in err


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_import(capsys, tmp_path):
    src = TESTS / "corpus" / "urdf" / "W025_loop_left_out.urdf"
    out = tmp_path / "loop.mech"
    rc, doc, err = run_json(capsys, "import", str(src), "-o", str(out))
    res = doc["result"]
    assert rc == 0 and doc["files_written"] == [str(out)] and res["output"] == str(out)
    assert f"end {res['model']};\n" in out.read_text() and res["root"] == "base" and res["floating"] is False
    assert set(res["joints"]) == {"j1", "j2"} and res["left_out"] == ["j3"]
    assert res["kinds"] == {"j1": "revolute", "j2": "revolute"} and len(res["coordinates"]) == 2
    (d,) = doc["diagnostics"]                                  # the loop's warning, located in the URDF
    assert (d["code"], d["severity"], d["file"], d["line"], d["column"]) == ("W025", "warning", str(src), 9, 3)
    assert "warning[W025]" in err and "text" not in res
    # without -o the model is the product: result.text under --json, stdout without it
    rc, doc, _ = run_json(capsys, "import", str(src))
    assert rc == 0 and doc["files_written"] == [] and doc["result"]["output"] is None
    assert doc["result"]["text"] == out.read_text()
    assert main(["import", str(src), "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out == out.read_text() and "-> standard output" not in cap.err and "warning[W025]" in cap.err


def test_lsp_with_json_is_a_usage_error(capsys):
    """stdout is the protocol's: --json cannot apply, and says so (as a document, like every usage error)."""
    rc, doc, err = run_json(capsys, "lsp", "--json")
    assert rc == 2 and doc["error"]["kind"] == "usage" and "Language Server Protocol" in doc["error"]["message"]
    assert "--json does not apply" in err


def test_the_schema_knows_the_result_of_every_command():
    from cli_json import schema

    s = schema()
    clauses = {c["if"]["properties"]["command"]["const"] for c in s["allOf"][1:]}
    assert clauses == set(COMMANDS) - {"lsp"}                  # lsp prints no document of its own
    for name in clauses:
        assert f"result_{name}" in s["$defs"], name


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_sweep(capsys, tmp_path):
    out = tmp_path / "s.csv"
    rc, doc, _ = run_json(capsys, "sweep", PENDULUM, "--grid", "L=1:2:2", "--t-end", "0.2", "--points", "5",
                          "-o", str(out), "--no-progress")
    res = doc["result"]
    assert rc == 0 and res["runs"] == 2 and res["succeeded"] == 2 and res["failed_by_cause"] == {}
    assert doc["files_written"] == [str(out), str(out.with_suffix(".json"))]     # the CSV and its sidecar


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_bench(capsys):
    rc, doc, _ = run_json(capsys, "bench", PENDULUM, "--scene", "Swing", "--t-end", "1", "--points", "11",
                          "--methods", "erk", "--tolerances", "1e-4", "--repeats", "1")
    assert rc == 0 and "Swing" in doc["result"]["target"]


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_examples_and_completion(capsys):
    rc, doc, _ = run_json(capsys, "examples")
    names = [e["name"] for e in doc["result"]["examples"]]
    assert rc == 0 and "double_pendulum" in names
    rc, doc, _ = run_json(capsys, "completion", "bash")
    assert rc == 0 and "_shtab_mech" in doc["result"]["text"]


def test_quiet_prints_only_errors(capsys, tmp_path):
    assert main(["simulate", PENDULUM, "--t-end", "0.5", "-q", "--no-progress"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""
    assert main(["simulate", str(tmp_path / "missing.mech"), "-q"]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "error[E001]" in cap.err
    # a command whose product is text still prints it (-q silences the talk, not the answer)
    assert main(["compile", PENDULUM, "--emit", "source", "-q"]) == 0
    assert "model Pendulum" in capsys.readouterr().out


@pytest.mark.slow_cases('export---fmu')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("command", [
    ["animate", PENDULUM, "-o", "{tmp}/a.gif", "--t-end", "0.2", "--fps", "5", "--size", "64x64"],  # picks a speed
    ["view", PENDULUM, "-o", "{tmp}/v.html", "--t-end", "0.2", "--fps", "5"],
    ["view", PENDULUM, "-o", "{tmp}/v.html", "--still"],
    ["export", PENDULUM, "--fmu", "{tmp}/p.fmu", "--fmi-type", "cs"],
    ["import", "{tmp}/arm.urdf", "-o", "{tmp}/arm.mech", "--force"],
    ["compile", PENDULUM, "--emit", "model", "-o", "{tmp}/m.txt", "--force"],
    ["simulate", PENDULUM, "-o", "{tmp}/p.csv", "--model", "Pendulum", "--no-progress"],   # no stop time: 10 s
], ids=lambda c: "-".join(w for w in c[:4] if not w.startswith(("/", "{"))))
def test_quiet_is_silent_on_every_command(capsys, tmp_path, command):
    """-q: no results text and no notes (the picked speed, the default end time, the target line),
    on stdout or stderr; the files are written all the same."""
    words = [w.replace("{tmp}", str(tmp_path)) for w in command]
    (tmp_path / "arm.urdf").write_text(ARM_URDF)
    assert main([*words, "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""
    assert len(list(tmp_path.iterdir())) > 1
    assert main(words) == 0                                   # and without -q they do speak
    cap = capsys.readouterr()
    assert "Pendulum" in cap.out + cap.err or "->" in cap.out


ARM_URDF = """<robot name="arm">
  <link name="base"/>
  <link name="rod"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
    <inertia ixx="0.0833" iyy="0.0833" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="continuous"><parent link="base"/><child link="rod"/><axis xyz="0 1 0"/></joint>
</robot>
"""


def _fresh_model(tmp_path, k: int):
    """A model no other test derives (the derived equations are kept per structure in-process)."""
    f = tmp_path / f"fresh{k}.mech"
    f.write_text(f"model Fresh{k}\n  coordinate Real x(start = 1, speed = 0);\nequation\n"
                 f"  kinetic = 1/2*der(x)^2;\n  potential = {k + 2}*x^2 + x^{k + 4};\nend Fresh{k};\n")
    return str(f)


def test_verbose_shows_the_library_log(capsys, monkeypatch, tmp_path):
    def check(k, *extra):
        assert main(["linearize", _fresh_model(tmp_path, k), "--no-cache", *extra]) == 0
        return capsys.readouterr().err

    assert "deriving the equations" not in check(0)
    err = check(1, "-v")
    assert "mech: deriving the equations of motion of Fresh1" in err and "debug" not in err
    assert "mech: debug: " in check(2, "-vv")
    monkeypatch.setenv("MECHDSL_DEBUG", "1")                    # MECHDSL_DEBUG: the debug log too
    assert "mech: debug: " in check(3)


def test_the_log_handler_is_removed_after_a_command():
    import logging

    before = list(logging.getLogger("mechdsl").handlers)
    assert main(["examples", "-v"]) == 0
    assert logging.getLogger("mechdsl").handlers == before


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_json_from_a_process_keeps_stdout_clean(tmp_path):
    """In a real process, also what C code prints goes to stderr (descriptor 1 is redirected)."""
    r = subprocess.run([sys.executable, "-m", "mechdsl", "simulate", PENDULUM, "--t-end", "0.5", "--json",
                        "--method", "cvodes-bdf", "--no-progress"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    validate(doc)
    assert doc["result"]["run"]["integrator"].startswith("casadi:cvodes")


@pytest.mark.parametrize("shell", ["bash", "zsh", "tcsh"])
def test_completion_scripts_know_every_command(capsys, tmp_path, shell):
    assert main(["completion", shell]) == 0
    script = capsys.readouterr().out
    for name in COMMANDS:
        assert name in script, name
    assert "json" in script and "t-end" in script
    if shell == "bash":                     # generated, so at least it parses
        line = next(x for x in script.splitlines() if x.startswith("_shtab_mech_subparsers=("))
        assert line[len("_shtab_mech_subparsers=("):-1].replace("'", "").split() == list(COMMANDS)  # quoted by newer shtab
        assert "_shtab_mech_export___fmu_COMPGEN=_shtab_compgen_files" in script
        assert "_shtab_mech_import_pos_0_COMPGEN=_shtab_compgen_files" in script
        f = tmp_path / "mech.bash"
        f.write_text(script)
        r = subprocess.run(["bash", "-n", str(f)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_the_schema_rejects_a_wrong_document(capsys):
    import jsonschema

    main(["examples", "--json"])
    doc = json.loads(capsys.readouterr().out)
    validate(doc)
    for broken in ({**doc, "ok": "yes"}, {**doc, "result": {"examples": [{"name": 1}]}},
                   {**doc, "diagnostics": [{"code": "E201"}]}, {k: v for k, v in doc.items() if k != "error"}):
        with pytest.raises(jsonschema.ValidationError):
            validate(broken)
