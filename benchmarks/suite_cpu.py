"""Where the test suite's CPU goes: pytest with a plugin that records the CPU time (user + system,
this process and its waited-for children: subprocesses, gcc) of every test's setup, call and
teardown, then prints the session's total and the most expensive files and tests.

    nice python benchmarks/suite_cpu.py                 # the default run (-m 'not slow')
    nice python benchmarks/suite_cpu.py -m slow tests/test_dae_bench.py
    nice python benchmarks/suite_cpu.py --tsv cpu.tsv   # every phase of every test, tab-separated

Arguments other than --tsv and --top go to pytest.  CPU, not wall time: the machines the suite
runs on are shared, and a test that waits costs nothing.  The budget (docs/internals.md,
"Testing"): the default run stays under about 2 minutes of CPU on 2 cores.
"""
from __future__ import annotations

import collections
import re
import resource
import sys

import pytest


def cpu() -> tuple[float, float]:
    """(own, children) CPU seconds, user + system."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


class CpuRecorder:
    def __init__(self):
        self.rows = []                    # (nodeid, phase, own s, children s)

    def _wrap(self, item, phase):
        a = cpu()
        yield
        b = cpu()
        self.rows.append((item.nodeid, phase, b[0] - a[0], b[1] - a[1]))

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(self, item):
        yield from self._wrap(item, "setup")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item):
        yield from self._wrap(item, "call")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(self, item):
        yield from self._wrap(item, "teardown")


def report(rows, total, top: int) -> str:
    by_file, by_test, by_function = collections.Counter(), collections.Counter(), collections.Counter()
    kids = collections.Counter()
    for nodeid, _phase, own, child in rows:
        path = nodeid.split("::")[0]
        by_file[path] += own + child
        kids[path] += child
        by_test[nodeid] += own + child
        by_function[re.sub(r"\[.*\]$", "", nodeid)] += own + child
    in_tests = sum(by_file.values())
    lines = [f"CPU of the session: {total[0] + total[1]:.1f} s (own {total[0]:.1f} s, children {total[1]:.1f} s); "
             f"in tests {in_tests:.1f} s, the rest (start, collection, imports) {total[0] + total[1] - in_tests:.1f} s",
             "", f"files (CPU s, of which children), the {top} most expensive:"]
    lines += [f"{v:8.2f} {kids[k]:7.2f}  {k}" for k, v in by_file.most_common(top)]
    lines += ["", f"tests (CPU s), the {top} most expensive:"]
    lines += [f"{v:8.2f}  {k}" for k, v in by_test.most_common(top)]
    lines += ["", f"test functions summed over their parameters (CPU s), the {top} most expensive:"]
    lines += [f"{v:8.2f}  {k}" for k, v in by_function.most_common(top)]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    tsv, top, args = None, 30, []
    it = iter(argv)
    for a in it:
        if a == "--tsv":
            tsv = next(it)
        elif a == "--top":
            top = int(next(it))
        else:
            args.append(a)
    rec = CpuRecorder()
    code = pytest.main(["-p", "no:cacheprovider", *args], plugins=[rec])
    total = cpu()
    print()
    print(report(rec.rows, total, top))
    if tsv:
        with open(tsv, "w", encoding="utf-8") as f:
            f.write("test\tphase\town_cpu_s\tchildren_cpu_s\n")
            f.writelines(f"{n}\t{p}\t{o:.3f}\t{c:.3f}\n" for n, p, o, c in rec.rows)
    return int(code)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
