"""The stability suite: scenes where common numerical methods fail, each with the checks
that say what fails and what works (docs/performance.md).  One module a case; each has
``run(size) -> Case`` (size "small" for the test suite, "full" for the charts) and
``chart(case, out_dir) -> [paths]``.  Run them all:  python benchmarks/stability/run.py
"""
