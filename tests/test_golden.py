"""Golden dumps per phase: `mech compile FILE --emit FORM` for every shipped model and every form
is compared with tests/golden/<model>.<form>.txt (the file's default target, as `mech compile`
picks it).

Rewrite them, after checking that a change is intended, with

    python -m pytest tests/test_golden.py --update-golden

which writes the files that differ, removes those of models that no longer exist and lists
both at the end of the run.  Text must match exactly; numbers match to a relative 1e-8 (plus
1e-13 absolute), since computed values (the eom dump's values at its states) may differ in their
last bits between platforms, libm or CasADi versions.
"""
import difflib
import math
import re
from pathlib import Path

import pytest

from mechdsl.cli import main
from mechdsl.commands.compile import EMITS

from conftest import MODELS, TESTS, model_files

GOLDEN = TESTS / "golden"
FORMS = EMITS                                  # every form `mech compile --emit` offers
UPDATE = "python -m pytest tests/test_golden.py --update-golden"
REL, ABS = 1e-8, 1e-13

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|\bnan\b|-?\binf\b")


def same_text(expected: str, actual: str) -> bool:
    """Equal text, numbers equal within REL/ABS (the tokens around them exactly equal)."""
    if expected == actual:
        return True
    a, b = _NUMBER.split(expected), _NUMBER.split(actual)
    if a != b:
        return False
    for x, y in zip(_NUMBER.findall(expected), _NUMBER.findall(actual)):
        fx, fy = float(x), float(y)
        if x == y or (math.isnan(fx) and math.isnan(fy)):
            continue
        if not math.isclose(fx, fy, rel_tol=REL, abs_tol=ABS):
            return False
    return True


def emit(path: Path, form: str, capsys) -> str:
    assert main(["compile", str(path), "--emit", form]) == 0, capsys.readouterr().err
    return capsys.readouterr().out


def _diff(expected: str, actual: str, name: str, limit: int = 40) -> str:
    lines = list(difflib.unified_diff(expected.splitlines(), actual.splitlines(),
                                      f"tests/golden/{name} (committed)", f"{name} (now)", lineterm="", n=1))
    more = f"\n... {len(lines) - limit} more diff lines" if len(lines) > limit else ""
    return "\n".join(lines[:limit]) + more


def check_golden(golden: Path, actual: str, what: str, update: bool, changes: list) -> None:
    """Compare `actual` with the file `golden`; under --update-golden write it when it differs
    (beyond the numeric tolerance) and record that in `changes`."""
    name = golden.name
    expected = golden.read_text(encoding="utf-8") if golden.exists() else None
    if update:
        if expected is None or not same_text(expected, actual):
            golden.parent.mkdir(exist_ok=True)
            golden.write_text(actual, encoding="utf-8")
            changes.append(f"{'created' if expected is None else 'rewritten'}: tests/golden/{name}")
        return
    if expected is None:
        pytest.fail(f"missing golden file tests/golden/{name}; create it with: {UPDATE}", pytrace=False)
    if not same_text(expected, actual):
        pytest.fail(f"`{what}` differs from tests/golden/{name}:\n"
                    f"{_diff(expected, actual, name)}\nif the change is intended: {UPDATE}", pytrace=False)


@pytest.mark.slow_cases('nfourbar-eom', 'nfourbar-model')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.stem)
def test_golden(path, form, capsys, update_golden, golden_changes):
    check_golden(GOLDEN / f"{path.stem}.{form}.txt", emit(path, form, capsys),
                 f"mech compile models/{path.name} --emit {form}", update_golden, golden_changes)


def test_no_stale_golden_files(update_golden, golden_changes):
    wanted = {f"{p.stem}.{f}.txt" for p in model_files() for f in FORMS}
    stale = sorted(p for p in GOLDEN.glob("*.txt") if p.name not in wanted)
    if update_golden:
        for p in stale:
            p.unlink()
            golden_changes.append(f"removed (no such model or form): tests/golden/{p.name}")
        return
    assert not stale, f"golden files of no shipped model: {[p.name for p in stale]}; remove them with: {UPDATE}"


# ----------------------------------------------------------------------------- the mechanism itself


def test_check_golden_fails_creates_and_rewrites_only_on_change(tmp_path):
    g = tmp_path / "golden" / "m.eom.txt"
    with pytest.raises(pytest.fail.Exception, match="missing golden file .*--update-golden"):
        check_golden(g, "x = 1\n", "cmd", False, [])
    changes: list = []
    check_golden(g, "x = 1\n", "cmd", True, changes)
    assert g.read_text() == "x = 1\n" and changes == ["created: tests/golden/m.eom.txt"]
    check_golden(g, "x = 1.0000000000001\n", "cmd", True, changes)        # within tolerance: kept
    assert g.read_text() == "x = 1\n" and len(changes) == 1
    with pytest.raises(pytest.fail.Exception, match=r"(?s)`cmd` differs.*-x = 1\n\+x = 2"):
        check_golden(g, "x = 2\n", "cmd", False, [])
    check_golden(g, "x = 2\n", "cmd", True, changes)
    assert g.read_text() == "x = 2\n" and changes[-1] == "rewritten: tests/golden/m.eom.txt"


def test_same_text_tolerates_last_digits_only():
    assert same_text("T = 0.1234567891; 2\n", "T = 0.1234567892; 2\n")
    assert same_text("x = 0\n", "x = 1e-16\n")
    assert not same_text("T = 0.1234567891\n", "T = 0.1234568891\n")     # 1e-7 relative
    assert not same_text("M[j1.phi,j1.phi] = 1\n", "M[j1.phi,j2.phi] = 1\n")
    assert not same_text("x = m1 * L\n", "x = m2 * L\n")                # digits in names count
    assert not same_text("x = 2.194e-06\n", "x = 2.195e-06\n")           # small values too
    assert not same_text("x = 1\n", "x = 1\ny = 2\n")


# ----------------------------------------------------------------------------- the eom dump


def _dump_values(text: str) -> dict[str, list[float]]:
    """name -> its values at the states, from an eom dump (state table and quantities)."""
    out, last = {}, None
    for line in text.splitlines():
        if line.startswith("  = ") and last:
            out[last] = [float(v) for v in line[4:].split("; ")]
        elif line.startswith("  ") and " = " in line:
            k, v = line.strip().split(" = ", 1)
            out[k] = [float(x) for x in v.split("; ")]
        elif " = " in line:
            last = line.split(" = ", 1)[0]
    return out


def test_eom_dump_values_match_the_closed_form_pendulum():
    """T = m L^2 w^2 / 2, V = -m g L cos(theta), theta'' = -(g/L) sin(theta) at every state of
    the dump, with parameters that are not 1 (so a swapped m and L would show).  The states are
    printed to 10 digits, hence the tolerance."""
    import mechdsl
    from mechdsl.eom.dump_eom import dump_eom

    m, L, g = 2.5, 0.7, 9.81
    text = dump_eom(mechdsl.load(MODELS / "pendulum.mech", model="Pendulum").with_params(m=m, L=L).eom)
    v = _dump_values(text)
    assert "parameters p = (m = 2.5, L = 0.7, g = 9.81)" in text
    th, w = v["theta"], v["der(theta)"]
    assert len(th) == 3 and th[0] == pytest.approx(math.pi / 2) and w[0] == 0
    for k in range(3):
        assert v["T"][k] == pytest.approx(0.5 * m * L**2 * w[k] ** 2, rel=1e-8, abs=1e-8)
        assert v["V"][k] == pytest.approx(-m * g * L * math.cos(th[k]), rel=1e-8, abs=1e-8)
        assert v["qdd[theta]"][k] == pytest.approx(-g / L * math.sin(th[k]), rel=1e-8)
    assert v["M[theta,theta]"] == [pytest.approx(m * L**2, rel=1e-9)]      # parameters only: one value


def test_eom_dump_names_symbols_by_the_model():
    text = (GOLDEN / "pendulum.eom.txt").read_text()
    assert "V = -m * g * cos(theta) * L" in text and "der(theta)" in text
    casadi_names = re.compile(r"\b(?:q|qd|p|lam)_\d+\b|@\d+=")
    for p in model_files():
        found = casadi_names.search((GOLDEN / f"{p.stem}.eom.txt").read_text())
        assert not found, f"{p.stem}.eom.txt prints CasADi's symbol {found.group()!r}"


def test_eom_dump_summarizes_large_expressions():
    text = (GOLDEN / "nlink_pendulum.eom.txt").read_text()
    assert re.search(r"^qdd\[q\[1\]\] = <\d+ operations in all 3 coordinates, all 3 speeds, .*>$", text, re.M)


def test_eom_dump_stops_counting_operations_past_its_budget(monkeypatch):
    """Counting each large expression's operations is quadratic in a big model; past the
    budget the dump says 'large expression' for it and every later one."""
    import mechdsl
    from mechdsl.eom import dump_eom as d

    eom = mechdsl.load(MODELS / "nlink_pendulum.mech").eom
    monkeypatch.setattr(d, "OPS_BUDGET", 200)
    heads = [ln for ln in d.dump_eom(eom).splitlines() if " = <" in ln]
    counted = [ln for ln in heads if " operations in " in ln]
    assert counted and heads[:len(counted)] == counted                 # counts first, then none
    assert all("<large expression in " in ln for ln in heads[len(counted):]) and len(heads) > len(counted)
