"""A benchmark's table: printed, as CSV (one row per run) and as a JSON sidecar."""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

from ..output.fileio import check_writable, output_folder, write_atomic
from . import measure
from .reference import fmt_accuracy, is_floor

FIXED = ["method", "formulation", "integrator", "tolerance", "dt", "status", "cpu_s", "cpu_runs_s", "cpu_warmup_s",
         "err_final", "err_l2"]
TAIL = ["steps", "rhs_evals", "t_reached", "message"]


def invariant_names(res) -> list[str]:
    names: list[str] = []
    for r in res.rows:
        for k in r.invariants:
            if k not in names:
                names.append(k)
    return names


def to_csv_text(res) -> str:
    inv = invariant_names(res)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(FIXED + [f"drift:{k}" for k in inv] + TAIL)
    for r in res.rows:
        w.writerow([r.label, r.formulation or "", r.method, _num(r.tolerance), _num(r.dt), r.status, _num(r.cpu),
                    " ".join(_num(x) for x in r.cpu_runs), _num(r.cpu_warmup), _num(r.err_final), _num(r.err_l2)]
                   + [_num(r.invariants.get(k)) for k in inv]
                   + [_num(r.steps), _num(r.rhs_evals), _num(r.t_reached), r.message])
    return buf.getvalue()


def _num(v) -> str:
    if v is None:
        return ""
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


def summary(res, table_name: str = "bench.csv") -> dict:
    s = res.setup
    ref = res.reference
    return {
        "generator": "mechdsl bench",
        "table": table_name,
        "model": s.name or s.eom.name, "scene": s.scene, "source": s.source,
        "kind": res.kind,
        "t_start": s.t_start, "t_end": s.t_end, "points": len(ref.t) if ref.source.startswith("file") else s.points,
        "compared": list(res.columns),
        "error": "relative per component (scaled by max |reference| over time); final = max at the last time, "
                 "l2 = root mean square over the reference times and components",
        "tolerances": list(res.tolerances), "rtol_equals_atol": True,
        "timer": res.timer, "repeats": res.repeats, "timing": "minimum over repeats after one warm-up run; the repeats interleaved across the variants at each tolerance",
        "reference": {"source": ref.source, "methods": list(ref.methods), "tolerance": ref.tolerance,
                      "accuracy": ref.accuracy, "cpu_s": ref.cpu, "times": len(ref.t), "notes": list(ref.notes)},
        "plan": list(s.notes),
        "machine": res.machine,
        "rows": [_row_dict(r) for r in res.rows],
    }


def _row_dict(r) -> dict:
    d = {k: getattr(r, k) for k in ("label", "method", "formulation", "tolerance", "dt", "status", "message", "cpu",
                                    "cpu_warmup", "err_final", "err_l2", "steps", "rhs_evals", "t_reached")}
    d["cpu_runs"] = list(r.cpu_runs)
    d["invariants"] = dict(r.invariants)
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def to_json_text(res, table_name="bench.csv") -> str:
    return json.dumps(summary(res, table_name), indent=2, sort_keys=False, default=_default) + "\n"


def _default(o):
    try:
        return float(o)
    except (TypeError, ValueError):
        return str(o)


def write_tables(res, out_dir, overwrite=False) -> list[Path]:
    d = output_folder(out_dir)
    csv_p, json_p = d / "bench.csv", d / "bench.json"
    for p in (csv_p, json_p):          # both checked before either is written
        check_writable(p, overwrite)
    # the sidecar first: it marks the CSV as mechdsl's output (fileio.is_own_output)
    write_atomic(json_p, to_json_text(res, csv_p.name), overwrite=overwrite)
    write_atomic(csv_p, to_csv_text(res), overwrite=overwrite)
    return [csv_p, json_p]


# --------------------------------------------------------------------------- printed table


def header_lines(res) -> list[str]:
    s = res.setup
    ref = res.reference
    where = f" (scene {s.scene})" if s.scene else ""
    lines = [f"{s.name or s.eom.name}{where}: {res.kind} model, t = {s.t_start:g} .. {s.t_end:g} s, "
             f"compared: {', '.join(res.columns)} (relative error per component)"]
    cpu = "".join(f"; {k} {v:.3g} s" for k, v in ref.cpu.items()) if ref.cpu else ""
    lines.append(f"reference: {ref.source}{cpu}")
    lines.append(f"  {fmt_accuracy(ref)}")
    lines += [f"  {n}" for n in ref.notes]
    lines += [f"plan: {n}" for n in s.notes]
    load = res.machine.get("load_average")
    lines.append(f"CPU time: {res.timer}, minimum of {res.repeats} run(s) after a warm-up; rtol = atol = tolerance"
                 + (f"; load average {load[0]:g} on {res.machine.get('cpus')} cores" if load else ""))
    return lines


def format_table(res) -> str:
    inv_label = None
    for r in res.rows:
        mi = measure.main_invariant(r.invariants)
        if mi:
            inv_label = mi[0]
            break
    inv_head = {"energy": "energy drift", "residual": "max |g|"}.get(inv_label or "", inv_label or "drift")
    head = ["method", "tol", "dt", "CPU [ms]", "err final", "err L2", inv_head, "steps", "status"]
    body = []
    for r in res.rows:
        mi = measure.main_invariant(r.invariants)
        floor = "*" if is_floor(r.err_final, res.reference, "final") else ""
        floor2 = "*" if is_floor(r.err_l2, res.reference, "l2") else ""
        body.append([r.label, "-" if r.tolerance is None else f"{r.tolerance:.0e}", "-" if r.dt is None else f"{r.dt:.3g}",
                     "-" if r.cpu is None else f"{r.cpu * 1e3:.4g}",
                     "-" if r.err_final is None else f"{r.err_final:.2e}{floor}",
                     "-" if r.err_l2 is None else f"{r.err_l2:.2e}{floor2}",
                     "-" if mi is None else f"{mi[1]:.2e}", "-" if r.steps is None else str(r.steps),
                     r.status if r.ok else f"{r.status}: {_short(r.message)}"])
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    out = header_lines(res) + [""]
    out.append("  ".join(h.ljust(w) if i in (0, 8) else h.rjust(w)
                         for i, (h, w) in enumerate(zip(head, widths))).rstrip())
    for b in body:
        out.append("  ".join(c.ljust(w) if i in (0, 8) else c.rjust(w)
                             for i, (c, w) in enumerate(zip(b, widths))).rstrip())
    if any("*" in (b[4] + b[5]) for b in body):
        out.append("* within 3x of the reference's estimated accuracy: not resolved")
    return "\n".join(out).rstrip()


def _short(msg: str, n: int = 90) -> str:
    msg = " ".join(msg.split())
    return msg if len(msg) <= n else msg[: n - 3] + "..."


# --------------------------------------------------------------------------- who is fastest


def fastest(res, label: str, target: float, norm: str = "err_final"):
    """The cheapest successful run of ``label`` whose error (``norm``: err_final or err_l2)
    is at most ``target``: the Row, or None when no run of the sweep reached it."""
    ok = [r for r in res.rows_of(label) if r.ok and getattr(r, norm) is not None and getattr(r, norm) <= target]
    return min(ok, key=lambda r: r.cpu) if ok else None


def fastest_lines(res, targets=(1e-3, 1e-6, 1e-9), norm: str = "err_final") -> list[str]:
    """Per method: the CPU time of its cheapest run meeting each error target (the IFToMM
    way of judging a method: the fastest run that is accurate enough), and that time
    relative to the best method's."""
    best = {}
    for tgt in targets:
        cands = [fastest(res, lab, tgt, norm) for lab in res.variants()]
        cpus = [r.cpu for r in cands if r is not None]
        best[tgt] = min(cpus) if cpus else None
    what = "final-time" if norm == "err_final" else "L2"
    head = ["method"] + [f"{what} error <= {t:.0e}" for t in targets]
    body = []
    for lab in res.variants():
        cells = [lab]
        for tgt in targets:
            r = fastest(res, lab, tgt, norm)
            if r is None:
                cells.append("not reached")
            else:
                rel = f" (x{r.cpu / best[tgt]:.1f})" if best[tgt] else ""
                tol = "-" if r.tolerance is None else f"{r.tolerance:.0e}"
                cells.append(f"{r.cpu * 1e3:.3g} ms at {tol}{rel}")
        body.append(cells)
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    out = ["fastest run meeting each error target (CPU time; x = relative to the fastest method):"]
    out.append("  ".join(h.ljust(w) for h, w in zip(head, widths)).rstrip())
    out += ["  ".join(c.ljust(w) for c, w in zip(b, widths)).rstrip() for b in body]
    return out


def markdown_table(head: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in body]
    return "\n".join(lines)
