"""The front end's size and work budgets (mechdsl/frontend/limits.py, docs/language.md "Limits").

Each example below was found by a fuzzer on a shipped model and used to crash (SystemError,
a CasADi or C++ exception) or hang; now `mech check` stops it with a located E-code, exit 1.
They run in a subprocess with a timeout: a hang fails the test instead of stalling the run.
"""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from mechdsl.frontend import limits
from mechdsl.cli import main

from conftest import CHECKOUT, MODELS, TESTS

HANG = 60  # seconds: these examples used to run for hours; they now stop in about one second


def mutant(tmp_path, model: str, old: str, new: str, name: str = "mutant.mech"):
    text = (MODELS / model).read_text(encoding="utf-8")
    assert old in text, f"{model} changed: the mutation no longer applies"
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def check_cli(path, *extra: str) -> tuple[int, str]:
    p = subprocess.run([sys.executable, "-m", "mechdsl", "check", *extra, str(path)], capture_output=True,
                       text=True, timeout=HANG, cwd=TESTS)
    return p.returncode, p.stderr


def first_error(err: str, path) -> tuple[str, int, int]:
    m = re.match(rf"{re.escape(str(path))}:(\d+):(\d+): error\[(E\d\d\d)\]: ", err)
    assert m, err[:2000]
    assert "Traceback" not in err and "internal error" not in err
    return m[3], int(m[1]), int(m[2])


# CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.slow_cases('andrews-qq100000', 'double-name900k', 'nfourbar-N1000', 'nfourbar-N10000', 'pendulum-unit500k')
@pytest.mark.parametrize("model,old,new,code,line", [
    # a SystemError in the DOF report (an array of 100,000 coordinates)
    ("andrews.mech", '  coordinate Real Theta(start = 0, speed = 0, unit = "rad");\n',
     '  coordinate Real Theta(start = 0, speed = 0, unit = "rad");\n  coordinate Real qq[100000];\n',
     "E316", 61),
    # a C++ std exception when simulated: 100,000 parameters
    ("coupled_pendulums.mech", '  parameter Real k(unit = "N/m") = 2 "spring stiffness";\n',
     '  parameter Real k(unit = "N/m") = 2 "spring stiffness";\n  parameter Real big[100000] = zeros(100000);\n',
     "E316", 33),
    # 100,000 outputs: derivation, rendering and code generation hung
    ("double_pendulum.mech", "  output Real E(unit = \"J\") = energy();\n",
     "  output Real E(unit = \"J\") = energy();\n  output Real oo[100000] = fill(rod2.b.y, 100000);\n",
     "E316", 25),
    # N = 10000 in the N-four-bar: the loop search hung (30,000 component instances)
    ("nfourbar.mech", "parameter Integer N = 2 ", "parameter Integer N = 10000 ", "E316", None),
    # N = 1000: 2001 coordinates, the derivation ran for minutes
    ("nfourbar.mech", "parameter Integer N = 2 ", "parameter Integer N = 1000 ", "E316", None),
    # a million-character name: unit parsing hung, and its CSV did not parse back (900,000 here:
    # a file of a million characters is over the file_bytes limit, E005)
    ("double_pendulum.mech", "output Real x2(", "output Real " + "x" * 900_000 + "(", "E314", 22),
    # a unit string of 500,000 characters: pint's parser ran for minutes
    ("pendulum.mech", '(unit = "kg")', '(unit = "' + "x" * 500_000 + '")', "E314", 12),
], ids=["andrews-qq100000", "coupled-big100000", "double-outputs100000", "nfourbar-N10000", "nfourbar-N1000",
        "double-name900k", "pendulum-unit500k"])   # short ids: pytest puts the id into the environment of
                                                 # every subprocess (PYTEST_CURRENT_TEST), 128 kB at most
def test_budget_examples_stop_with_a_located_error(tmp_path, model, old, new, code, line):
    path = mutant(tmp_path, model, old, new)
    rc, err = check_cli(path)
    assert rc == 1, err[-2000:]
    got_code, got_line, col = first_error(err, path)
    assert got_code == code
    if line is not None:
        assert got_line == line
    assert "--limit " in err  # the hint says how to raise the budget


def test_file_over_the_size_limit_is_refused_before_parsing(tmp_path):
    path = mutant(tmp_path, "double_pendulum.mech", "output Real x2(", "output Real " + "x" * 1_000_000 + "(")
    rc, err = check_cli(path)
    assert rc == 1 and err.startswith(f"{path}: error[E005]: file is too large (1,00")


def test_budget_reported_once_at_the_declaration_that_passes_it(tmp_path, capsys):
    path = mutant(tmp_path, "coupled_pendulums.mech", '  parameter Real k(unit = "N/m") = 2 "spring stiffness";\n',
                  '  parameter Real k(unit = "N/m") = 2 "spring stiffness";\n'
                  '  parameter Real big[100000] = zeros(100000);\n')
    assert main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("error[E316]") == 1 and "more than 20,000 scalars" in err


def test_limits_can_be_lowered_and_raised_from_the_command_line(tmp_path, capsys):
    model = MODELS / "double_pendulum.mech"
    assert main(["check", "--limit", "coordinates=1", str(model)]) == 1
    err = capsys.readouterr().err
    assert "error[E316]: model 'DoublePendulum' has more than 1 generalized coordinates" in err
    big = TESTS / "corpus" / "E315_integer_parameter_too_large.mech"
    assert main(["check", str(big)]) == 1
    assert main(["check", "--limit", "integers=10_000_000", str(big)]) == 0


def test_limits_override_in_the_api():
    import mechdsl

    with limits.override(coordinates=1):
        assert limits.get("coordinates") == 1
        with pytest.raises(mechdsl.MechError) as e:
            mechdsl.load(MODELS / "double_pendulum.mech")
        assert e.value.diagnostics[0].code == "E316"
    assert limits.get("coordinates") == limits.DEFAULTS["coordinates"]  # restored after the block
    assert len(mechdsl.load(MODELS / "double_pendulum.mech").coordinates) == 2


@pytest.mark.parametrize("bad", ["arrays", "arrays=", "arrays=0", "arrays=-3", "arrays=1.5", "arrays=nan",
                                 "arrays=inf", "arrays=lots", "nolimit=5"])
def test_bad_limit_option_is_a_usage_error(bad, capsys):
    assert main(["check", "--limit", bad, str(MODELS / "pendulum.mech")]) == 2
    err = capsys.readouterr().err
    assert "--limit" in err and "Traceback" not in err


def test_unknown_limit_in_the_api():
    with pytest.raises(ValueError, match="unknown limit 'nolimit'"):
        with limits.override(nolimit=3):
            pass


def test_every_limit_is_documented():
    text = (CHECKOUT / "docs" / "language.md").read_text(encoding="utf-8")
    for lim in limits.LIMITS.values():
        assert f"`{lim.name}`" in text and f"{lim.default:,}" in text, lim.name


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_shipped_models_are_far_inside_the_budgets():
    # the defaults must never bite a real model: every shipped model passes with a quarter of them
    tight = {k: max(1, v // 4) for k, v in limits.DEFAULTS.items() if k not in ("nesting", "depth")}
    from mechdsl.frontend.parser import parse_file
    from mechdsl.semantic import analyze

    with limits.override(tight):
        for path in sorted(MODELS.glob("*.mech")):
            program = analyze(parse_file(path))
            parts = program.part_users()
            for name in program.model_names():
                if name not in parts:
                    program.model(name)  # raises MechError (E316, ...) if a budget bit
            for name in program.scene_names():
                program.scene(name)
