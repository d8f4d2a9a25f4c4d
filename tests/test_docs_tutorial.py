"""The tutorial runs as written (docs/tutorial.md): its shell sessions, replayed in order on the
files the reader builds, print what the text shows; its Python snippet runs."""
import re
import shlex

import numpy as np
import pytest

from conftest import CHECKOUT


def test_tutorial_python_snippet(tmp_path, monkeypatch):
    text = (CHECKOUT / "docs" / "tutorial.md").read_text()
    model = re.search(r"```\n(model Pendulum \"A point mass.*?end Pendulum;)\n```", text, re.S).group(1)
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pendulum.mech").write_text(model + "\n")
    ns: dict = {}
    exec(compile(code, "tutorial.md", "exec"), ns)
    assert ns["r"].q.shape == (501, 1)
    assert abs(ns["lin"].modes().frequencies[0] - np.sqrt(9.81)) < 1e-9
    assert [e.stable for e in ns["eq"]] == [True, False]
    # the reprs the text shows in comments (`name  # <...>`) are what Python shows ("..." elides)
    shown = re.findall(r"^(\w+)(?: = [^#]*?)?\s+# (\[?<.*>\]?)$", code, flags=re.M)
    assert {name for name, _ in shown} >= {"m", "r", "eq", "lin"}
    for name, text in shown:
        pattern = ".*?".join(re.escape(part) for part in text.split("..."))
        assert re.fullmatch(pattern, repr(ns[name])), f"tutorial shows {text!r}, Python {ns[name]!r}"


def _blocks(text):
    return re.findall(r"```\n(.*?)```", text, re.S)


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_tutorial_shell_sessions_print_what_the_text_shows(tmp_path, monkeypatch, capsys):
    """Every `$ mech ...` line of the tutorial is run in order, in a folder where the reader's
    files are written as the text says (the model of step 1, the scene of step 5 appended, the
    component pendulum in its own file); each output line the text shows (not elided with '...',
    timings aside) must be printed."""
    from mechdsl.cli import main

    monkeypatch.chdir(tmp_path)
    ran = 0
    for block in _blocks((CHECKOUT / "docs" / "tutorial.md").read_text()):
        if block.startswith("model Pendulum \"A point mass"):
            (tmp_path / "pendulum.mech").write_text(block)
        elif block.startswith("model Pendulum2"):
            (tmp_path / "pendulum2.mech").write_text(block)
        elif block.startswith("scene Swing"):
            with open(tmp_path / "pendulum.mech", "a") as f:
                f.write("\n" + block)
        elif block.startswith("$ mech"):
            for session in re.split(r"^(?=\$ )", block, flags=re.M):
                if not session.strip():
                    continue
                command, *shown = session.rstrip("\n").split("\n")
                assert main(shlex.split(command[2:])[1:]) == 0, command
                printed = {" ".join(ln.split()) for ln in capsys.readouterr().out.splitlines()}
                for line in shown:
                    if line.strip() and "..." not in line and not line.startswith("statistics:"):
                        assert " ".join(line.split()) in printed, f"{command}: the text shows {line!r}"
                ran += 1
    assert ran >= 5


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_tutorial_says_what_animate_draws(tmp_path, monkeypatch, capsys):
    """The T-and-V pendulum has no bodies (bars of the coordinates), the component one has (a
    drawing of the mechanism): the tutorial says which, and the command agrees."""
    from mechdsl.cli import main

    text = (CHECKOUT / "docs" / "tutorial.md").read_text()
    assert "no bodies to draw" in text and "`mech animate pendulum2.mech -o swing.gif`" in text
    monkeypatch.chdir(tmp_path)
    blocks = _blocks(text)
    (tmp_path / "pendulum.mech").write_text(next(b for b in blocks if b.startswith("model Pendulum \"A point")))
    (tmp_path / "pendulum2.mech").write_text(next(b for b in blocks if b.startswith("model Pendulum2")))
    args = ["--t-end", "0.2", "--fps", "10", "--size", "80x60", "--speed", "0.1"]
    assert main(["animate", "pendulum.mech", "-o", "a.gif", *args]) == 0
    assert "bars of the coordinates (no bodies to draw)" in capsys.readouterr().out
    assert main(["animate", "pendulum2.mech", "-o", "b.gif", *args]) == 0
    out = capsys.readouterr().out
    assert "wrote b.gif" in out and "no bodies" not in out
