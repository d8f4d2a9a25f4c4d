"""What `mech check` and a run's metadata say about regularized friction (issue 17)."""
from __future__ import annotations

from . import exprs as X


def friction_notes(model, values: dict[str, float]) -> list[str]:
    """One line per Friction of ``model`` (an ir.Model): its law and the regularization speed
    v_eps at the parameter values ``values`` ({name: value})."""
    out = []
    for f in getattr(model, "forces", ()) if model is not None else ():
        if not getattr(f, "note", ""):
            continue
        line = f"{f.name}: {f.note}"
        if f.regularization is not None:
            try:
                line += f", v_eps = {X.evaluate(f.regularization, values):.6g}"
            except (KeyError, ValueError):
                line += f", v_eps = {X.to_text(f.regularization)}"
        out.append(line)
    return out
