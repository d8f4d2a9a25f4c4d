"""The repository itself: no merge-conflict markers in any tracked text file."""
import re
import subprocess

from conftest import CHECKOUT

MARKER = re.compile(rb"^(<{7}|>{7}) |^={7}$", re.M)


def test_no_merge_conflict_markers():
    files = subprocess.run(["git", "ls-files"], cwd=CHECKOUT, capture_output=True, check=True).stdout.decode().split()
    bad = []
    for name in files:
        path = CHECKOUT / name
        if path.suffix in (".md", ".py", ".toml", ".mech", ".lark", ".txt", ".json", ".ipynb", "") and path.is_file():
            if MARKER.search(path.read_bytes()):
                bad.append(name)
    assert not bad, f"merge-conflict markers in {bad}"
