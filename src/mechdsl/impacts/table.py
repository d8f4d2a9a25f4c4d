"""A short text summary of a result's events (what ``mech simulate`` prints)."""
from __future__ import annotations

import sys


def _num(x, fmt="{:.6g}") -> str:
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(fmt.format(v) for v in x) + "]"
    return fmt.format(x)


def _jumps(e: dict, most: int = 3) -> str:
    """The speeds an event changed, `der(c) v- -> v+` (at most `most`; the full states are in
    the event's state_before / state_after)."""
    a, b = e.get("state_before") or {}, e.get("state_after") or {}
    keys = [k for k in a if k.startswith("der(") and abs(b.get(k, a[k]) - a[k]) > 1e-12 * max(1.0, abs(a[k]))]
    text = ", ".join(f"{k} {a[k]:.6g} -> {b[k]:.6g}" for k in keys[:most])
    return text + (f", ... ({len(keys) - most} more)" if len(keys) > most else "")


def events_table(events: list[dict], max_rows: int = 20) -> str:
    """The events as a table: counts per kind and contact, total energy change, and the first
    and last rows (``max_rows`` in all)."""
    if not events:
        return "events: none\n"
    counts: dict[tuple[str, str], int] = {}
    for e in events:
        key = (e["kind"], e.get("contact", ""))
        counts[key] = counts.get(key, 0) + 1
    dE = sum(float(e.get("energy_change", 0.0)) for e in events)
    lines = [f"events: {len(events)} (" + ", ".join(f"{n} {k} {c}" for (k, c), n in counts.items())
             + f"); total energy change {dE:.6g} J"]
    head = ["time [s]", "event", "contact", "impulse [N.s]", "energy change [J]", "normal speed -/+ [m/s]",
            "speeds changed (before -> after)"]
    rows = []
    half = max_rows // 2
    shown = events if len(events) <= max_rows else events[:half] + [None] + events[-(max_rows - half):]
    for e in shown:
        if e is None:
            rows.append(["...", f"({len(events) - max_rows} more)", "", "", "", "", ""])
            continue
        rows.append([f"{e['time']:.9g}", e["kind"], e.get("contact", ""), _num(e.get("impulse", 0.0)),
                     _num(e.get("energy_change", 0.0)),
                     _num(e.get("speed_before", 0.0)) + " / " + _num(e.get("speed_after", 0.0)), _jumps(e)])
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    fmt = "  ".join("{:<%d}" % w for w in widths)
    lines.append("  " + fmt.format(*head).rstrip())
    lines += ["  " + fmt.format(*r).rstrip() for r in rows]
    return "\n".join(lines) + "\n"


def print_events(result, file=None, max_rows: int = 20) -> None:
    """Print the events table of a result (nothing when it has no events)."""
    if getattr(result, "events", None):
        (file or sys.stdout).write(events_table(result.events, max_rows))
