"""Speed against accuracy: work-precision benchmarks of a model (``mech bench``).

    import mechdsl
    from mechdsl.bench import Setup, parse_variants, parse_tolerances, run_bench, format_table
    setup = Setup.from_model(mechdsl.load("models/double_pendulum.mech", scene="Chaos"))
    res = run_bench(setup, variants=parse_variants("erk,cvodes-bdf,scipy-dop853"),
                    tolerances=parse_tolerances("1e-3..1e-9"))
    print(format_table(res)); write_tables(res, "out/"); write_chart(res, "out/")

Modules: spec (method specifications, tolerance sweeps), plan (the default plan of mech
bench, proportionate to the model), reference (file or computed
reference with its estimated accuracy), measure (error norms, invariant drift), timing (CPU
time, min over repeats after a warm-up), runner (the sweep), report (table, CSV, JSON),
chart (the work-precision chart).  Design: docs/internals/bench.md; use: docs/performance.md.
"""
from .chart import draw, write_chart
from .reference import Reference, read_csv
from .report import format_table, to_csv_text, write_tables
from .runner import BenchResult, Row, Setup, run_bench
from .spec import Variant, parse_tolerances, parse_variant, parse_variants

__all__ = ["Setup", "run_bench", "BenchResult", "Row", "Variant", "parse_variants", "parse_variant",
           "parse_tolerances", "Reference", "read_csv", "format_table", "to_csv_text", "write_tables", "draw",
           "write_chart"]
