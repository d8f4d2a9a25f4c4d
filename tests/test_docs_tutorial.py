"""The tutorial's Python snippet runs as written (docs/tutorial.md, section 7)."""
import re

import numpy as np

from conftest import ROOT


def test_tutorial_python_snippet(tmp_path, monkeypatch):
    text = (ROOT / "docs" / "tutorial.md").read_text()
    model = re.search(r"```\n(model Pendulum \"A point mass.*?end Pendulum;)\n```", text, re.S).group(1)
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pendulum.mech").write_text(model + "\n")
    ns: dict = {}
    exec(compile(code, "tutorial.md", "exec"), ns)
    assert ns["r"].q.shape == (501, 1)
    assert abs(ns["lin"].modes().frequencies[0] - np.sqrt(9.81)) < 1e-9
    assert [e.stable for e in ns["eq"]] == [True, False]
