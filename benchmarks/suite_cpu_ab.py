"""The test suite's CPU before and after a change, side by side: the tree of a base commit
(``git archive`` into a temporary folder, its own src/ first on PYTHONPATH) and the working
tree run the same test files at the same time, so both see the same machine load (two runs
one after the other differed by 16 % on untouched tests on the shared machine, CPU time too).

    nice python benchmarks/suite_cpu_ab.py 42ea9bd tests/test_golden.py tests/test_view.py

Prints the CPU (user + system of each pytest process and of the children it waited for:
subprocesses, gcc) of both, the ratio, and each session's last line.  POSIX only (os.wait4).
The default run's addopts apply to both (slow tests deselected).
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def start(tree: Path, files: list[str], log: Path, src_first: bool) -> subprocess.Popen:
    env = dict(os.environ)
    if src_first:
        env["PYTHONPATH"] = str(tree / "src") + os.pathsep + env.get("PYTHONPATH", "")
    with open(log, "w") as out:
        return subprocess.Popen([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", *files], cwd=tree,
                                env=env, stdout=out, stderr=subprocess.STDOUT)


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    base, files = argv[0], argv[1:]
    with tempfile.TemporaryDirectory(prefix="suite-ab-") as tmp:
        old = Path(tmp) / "base"
        old.mkdir()
        archive = subprocess.run(["git", "archive", base], cwd=HERE, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
        names = {}
        logs = {}
        for name, tree, first in ((f"base {base}", old, True), ("working tree", HERE, False)):
            logs[name] = Path(tmp) / f"{len(logs)}.log"
            names[start(tree, files, logs[name], first).pid] = name
        cpu = {}
        while len(cpu) < len(names):
            pid, _status, ru = os.wait4(-1, 0)
            if pid in names:
                cpu[names[pid]] = ru.ru_utime + ru.ru_stime
        for name in names.values():
            last = (logs[name].read_text(errors="replace").strip().splitlines() or [""])[-1]
            print(f"{name:24s} CPU {cpu[name]:7.1f} s   ({last.strip()})")
    a, b = (cpu[n] for n in names.values())
    print(f"working tree / base: {b / a:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
