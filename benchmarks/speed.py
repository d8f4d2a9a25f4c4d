"""Speed without cliffs (issue 24): every figure of docs/performance.md's section of that name
from one run of this script.

    PYTHONPATH=src python benchmarks/speed.py [--docs DIR] [--quick] [--items 1,2,... [--update]]

Runs the benchmark of each item of the issue one after the other, each as a fresh process
(``python benchmarks/NAME.py ...``), prints what each prints, and writes the section into
docs/performance.md between the markers ``<!-- speed.py: begin -->`` and ``<!-- speed.py:
end -->`` (the rest of the page is left as it is; benchmarks/make_performance.py keeps the
section when it regenerates the page).  Every script measures CPU time (the minimum of
repeats) and puts the ratios it states side by side in its own run; each item's block says
when, where and at what load its script ran.  --quick, and --items without --update, are smoke
tests: they print and write nothing into the docs; ``--items 1,7 --update`` reruns those items
and replaces only their blocks (between ``<!-- speed.py item N -->`` markers).
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- speed.py: begin -->", "<!-- speed.py: end -->"

# (item, title, goal, script, arguments, quick arguments)
ITEMS = [
    ("1", "`auto` against every method, tolerance by tolerance",
     "cost monotone in the tolerance, at most 1.2x the best method at equal accuracy, the same method "
     "whatever the cache holds",
     "auto_wp.py", ["--repeats", "3"], ["--quick", "--models", "dp"]),
    ("2", "Small models: the default run against scipy DOP853 + Pinocchio's ABA",
     "N = 2 and 5 at most 0.1 of scipy + pin.aba; a warm 2-coordinate run at most 3x its right-hand-side work",
     "nlink_run.py", ["--sizes", "2,5,10,30,100,200", "--repeats", "30"], ["--sizes", "2,5", "--repeats", "1"]),
    ("3", "Generated C and its compile against the model's size",
     "C size and compile time linear in the number of links; a 7-joint arm in under 10 s of CPU and 500 MB",
     "codegen_scaling.py", [], ["--quick"]),
    ("3, 8", "Whole `mech simulate` processes on empty, new-model and warm caches (and a third run)",
     "the 200-link chain's first run at most 3 s CPU and 200 MB (item 3); the 12-link chain warm 0.15 s, "
     "from an empty cache 0.5 s (item 8)",
     "first_run.py", ["--sizes", "12,50,200", "--runs", "3"], ["--sizes", "12", "--runs", "1"]),
    ("4", "Contact scenes across tolerances",
     "cost and events monotone in the tolerance; the events' losses within the energy available",
     "contacts_tolerance.py", ["--repeats", "8"], ["--quick"]),
    ("5", "Ensembles: the default sweep against a hand-written map and mujoco.rollout",
     "per run at most 0.5x a hand `Function.map` and at least 4x better than `mujoco.rollout` at matched "
     "accuracy",
     "ensemble.py", ["--runs", "400", "--repeat", "3"], ["--runs", "16", "--repeat", "1", "--t-end", "2"]),
    ("6", "One call of a 7-joint arm's dynamics from Python",
     "`Model.fast_function` at most 2x Pinocchio's `pin.aba` from Python",
     "python_call.py", [], ["--calls", "2000"]),
    ("7", "Optimal control: the cart-pole swing-up",
     "the documented default `m.casadi()[\"ode\"]` at most 1.1x a hand-written CasADi model (same iterations)",
     "control_swingup.py", ["--N", "30,60,120", "--repeat", "3"], ["--N", "30", "--repeat", "1"]),
]


def run_item(script: str, args: list[str]) -> tuple[str, float, float]:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    t0 = time.perf_counter()
    r0 = os.times()
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], capture_output=True, text=True,
                       env=env, cwd=ROOT)
    r1 = os.times()
    cpu = (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)
    out = p.stdout.rstrip()
    if p.returncode != 0:
        out += f"\n(exit code {p.returncode})\n" + "\n".join(p.stderr.rstrip().splitlines()[-15:])
    return out, time.perf_counter() - t0, cpu


HEAD = ("Every block below is the output of its item's script, run as a fresh process by `python "
        "benchmarks/speed.py`; the line above each block says when, on what machine and at what load it "
        "ran (the machine is shared: absolute times are inflated and noisy; each script states CPU times, "
        "the minimum of repeats, and its ratios from runs side by side in that script's run).")


def item_marker(item: str) -> str:
    return f"<!-- speed.py item {item} -->"


def block(it, res, where: str) -> str:
    item, title, goal, script, args, _ = it
    out, wall, cpu = res
    cmd = " ".join(["python", f"benchmarks/{script}", *args])
    return "\n".join([item_marker(item), f"### Item {item}: {title}", "",
                      f"Goal: {goal}.  `{cmd}` ({wall:.0f} s wall, {cpu:.0f} s CPU; {where}):",
                      "", "```", out, "```", ""])


def section(blocks: list[str]) -> str:
    return "\n".join([BEGIN, "", "## Speed without cliffs (issue 24)", "", HEAD, "", *blocks, END])


def blocks_of(text: str) -> dict[str, str]:
    """item -> its block, from the section as it stands in the docs."""
    body = text[text.index(BEGIN):text.index(END)]
    out = {}
    for it in ITEMS:
        m = item_marker(it[0])
        if m in body:
            start = body.index(m)
            nxt = [body.index(item_marker(o[0]), start + 1) for o in ITEMS if item_marker(o[0]) in body[start + 1:]]
            out[it[0]] = body[start:min(nxt) if nxt else len(body)].rstrip() + "\n"
    return out


def write(docs: Path, text: str) -> None:
    page = docs / "performance.md"
    old = page.read_text()
    if BEGIN in old and END in old:
        new = old[:old.index(BEGIN)] + text + old[old.index(END) + len(END):]
    else:
        new = old.rstrip() + "\n\n" + text + "\n"
    tmp = page.with_suffix(".md.tmp")
    tmp.write_text(new)
    os.replace(tmp, page)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--docs", default=str(ROOT / "docs"))
    ap.add_argument("--quick", action="store_true", help="short runs, docs untouched (a smoke test)")
    ap.add_argument("--items", default=None, help="only these items (comma separated), docs untouched")
    ap.add_argument("--update", action="store_true", help="with --items: replace those items' blocks in the docs")
    a = ap.parse_args(argv)
    wanted = None if a.items is None else set(a.items.split(","))
    from mechdsl.output.result import versions

    v = ", ".join(f"{k} {val}" for k, val in versions().items())
    done = {}
    for it in ITEMS:
        if wanted is not None and not wanted & set(it[0].replace(" ", "").split(",")):
            continue
        args = it[5] if a.quick else it[4]
        print(f"== item {it[0]}: benchmarks/{it[3]} {' '.join(args)}", flush=True)
        load0 = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        res = run_item(it[3], args)
        load1 = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        print(res[0], flush=True)
        where = (f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.platform(terse=True)}, "
                 f"{os.cpu_count()} cores, load average {load0} at the start and {load1} at the end; {v}")
        done[it[0]] = block((*it[:4], args, it[5]), res, where)
    if a.quick or (wanted is not None and not a.update):
        return 0
    page = Path(a.docs) / "performance.md"
    old = page.read_text()
    kept = blocks_of(old) if BEGIN in old and END in old else {}
    missing = [it[0] for it in ITEMS if it[0] not in done and it[0] not in kept]
    if missing:
        print(f"speed.py: items {', '.join(missing)} have no block yet: run them too", file=sys.stderr)
        return 1
    write(Path(a.docs), section([done.get(it[0]) or kept[it[0]] for it in ITEMS]))
    print(f"wrote {page}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "src"))
    sys.exit(main())
