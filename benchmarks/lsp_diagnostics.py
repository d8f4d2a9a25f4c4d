"""How long the language server (`mech lsp`) takes to produce a file's diagnostics.

    python benchmarks/lsp_diagnostics.py [--repeats K] [--server] [MODEL.mech ...]

In-process, with the imports already done (the server is a long-lived process), for every shipped
model (default) from the largest file down: the CPU time (time.process_time, minimum of K
repeats, default 5) of

- stage 1, ``mechdsl.lsp.analysis.analyse``: read, parse, symbol index, analyse, load every
  target `mech check` checks and every model alone (its diagnostics are published at once);
- stage 2, ``start_problems``: the equations of motion and the start-state checks, twice: with
  the derived equations of the same model structure remembered (an edit that changes a value or
  a name's spelling back) and derived anew (an edit that changes the structure; the in-process
  cache of derived equations cleared before each repeat).

``--server`` also measures the whole round trip over stdio: a real ``python -m mechdsl lsp``
with debounceMs 0, the wall time from sending didChange (the text with one parameter value
changed, so that every repeat is a new text) to receiving its publishDiagnostics; minimum of K.
(Wall time on a shared machine is noise upward; the minimum is the honest figure.)
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cpu_min(fn, repeats: int, before=None) -> float:
    best = float("inf")
    for _ in range(repeats):
        if before is not None:
            before()
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def in_process(paths: list[Path], repeats: int) -> list[tuple]:
    from mechdsl import api
    from mechdsl.lsp.analysis import analyse, start_problems

    rows = []
    for path in paths:
        text = path.read_text()
        a = analyse(text, str(path))
        start_problems(a)                                           # warm: imports, LALR tables
        s1 = cpu_min(lambda: analyse(text, str(path)), repeats)
        s2_cached = cpu_min(lambda: start_problems(analyse(text, str(path))), repeats) - s1
        fresh = analyse(text, str(path))
        s2_fresh = cpu_min(lambda: start_problems(fresh), repeats,
                           before=lambda: (api._EOM_CACHE.clear(), [setattr(m, "_eom", None) for m in fresh.loaded]))
        coords = sum(len(m.model.coordinates) for m in a.loaded)
        rows.append((path.name, len(text), coords, s1, max(0.0, s2_cached), s2_fresh))
    return rows


def over_stdio(paths: list[Path], repeats: int) -> list[tuple]:
    sys.path.insert(0, str(ROOT / "tests"))
    from lsp_client import LspClient

    rows = []
    c = LspClient({"debounceMs": 0})
    try:
        version = 0
        for path in paths:
            text = path.read_text()
            uri = path.as_uri()
            version += 1
            c.open(uri, text, version)
            c.diagnostics(uri, version)
            best = float("inf")
            for k in range(repeats):
                version += 1
                changed = text + f"\n// edit {k}\n"       # a new text: analysed anew, same model
                t = time.perf_counter()
                c.change(uri, changed, version)
                c.diagnostics(uri, version)
                best = min(best, time.perf_counter() - t)
            rows.append((path.name, best))
    finally:
        c.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="*", type=Path)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--server", action="store_true", help="also the round trip over stdio")
    args = ap.parse_args()
    paths = [p.resolve() for p in args.models] or sorted((ROOT / "models").glob("*.mech"), key=lambda p: -p.stat().st_size)
    print(f"CPU seconds, minimum of {args.repeats}; stage 1 = parse + analyse + load (published at once), "
          "stage 2 = equations of motion + start-state checks")
    print(f"{'model':28s} {'bytes':>6s} {'coords':>6s} {'stage 1':>8s} {'stage 2':>8s} {'stage 2':>8s} {'total':>8s}")
    print(f"{'':28s} {'':>6s} {'':>6s} {'':>8s} {'(cached)':>8s} {'(anew)':>8s} {'(anew)':>8s}")
    for name, size, coords, s1, s2c, s2f in in_process(paths, args.repeats):
        print(f"{name:28s} {size:6d} {coords:6d} {s1:8.3f} {s2c:8.3f} {s2f:8.3f} {s1 + s2f:8.3f}")
    if args.server:
        print(f"\nround trip over stdio (didChange -> publishDiagnostics, wall seconds, minimum of {args.repeats})")
        for name, wall in over_stdio(paths, args.repeats):
            print(f"{name:28s} {wall:8.3f}")


if __name__ == "__main__":
    main()
