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


# the tests run against the installed wheel from a copy of tests/ (.ci/run): a path built from
# the source tree's layout would find the checkout's files there, or nothing
SOURCE_LAYOUT = re.compile(r'parents\[\d\]|\.parent\.parent|rsplit\("/src/"|"\.\.", "models"|CHECKOUT / "(models|src)"'
                           r'|ROOT / "(models|src)"')
# the pages generated from the checkout's docs/ (they fall back to the folder above tests/)
ABOUT_THE_CHECKOUT = {"conftest.py", "api_doc.py", "errors_doc.py"}


def test_no_test_finds_files_through_the_source_layout():
    bad = []
    for path in sorted((CHECKOUT / "tests").glob("*.py")):
        if path.name in ABOUT_THE_CHECKOUT:
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if SOURCE_LAYOUT.search(line):
                bad.append(f"{path.name}:{n}: {line.strip()}")
    assert not bad, ("use conftest.MODELS / mechdsl.examples, conftest.TESTS, mechdsl.__file__, or conftest.CHECKOUT "
                     "for the repository's own docs:\n" + "\n".join(bad))
