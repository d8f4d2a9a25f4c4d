"""The Andrews work-precision benchmark runs (quick mode; slow: about a minute)."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import CHECKOUT  # noqa: E402


@pytest.mark.slow
def test_andrews_work_precision_quick(tmp_path):
    out = tmp_path / "wp"
    res = subprocess.run([sys.executable, str(CHECKOUT / "benchmarks" / "andrews_wp.py"), str(out), "--quick",
                          "--repeats", "1", "--json", str(tmp_path / "wp.json")],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "wp.png").stat().st_size > 0 and (tmp_path / "wp.svg").stat().st_size > 0
    rows = json.loads((tmp_path / "wp.json").read_text())
    assert all(r["error"] is None for r in rows["idas index-3"])          # the unguarded index-3 run fails
    assert rows["projection"][-1]["error"] < 1e-7                        # tol 1e-10
    assert all(r["error"] is not None for name in ("projection", "ggl") for r in rows[name])
