"""Plain-text tables for the analysis commands (mech equilibrium, mech linearize)."""
from __future__ import annotations

import numpy as np


def num(v: float, width: int = 0) -> str:
    if isinstance(v, complex) or np.iscomplexobj(v):
        v = complex(v)
        if abs(v.imag) <= 1e-12 * max(1.0, abs(v)):
            return num(v.real, width)
        s = f"{v.real:.6g}{v.imag:+.6g}i"
    else:
        v = float(v)
        s = "0" if v == 0 else f"{v:.6g}"
    return s.rjust(width) if width else s


def table(headers: list[str], rows: list[list[str]], indent: str = "  ") -> str:
    w = [len(h) for h in headers]
    for r in rows:
        for i, c in enumerate(r):
            w[i] = max(w[i], len(c))
    lines = [indent + "  ".join(h.ljust(w[i]) for i, h in enumerate(headers)).rstrip()]
    for r in rows:
        lines.append(indent + "  ".join(c.ljust(w[i]) for i, c in enumerate(r)).rstrip())
    return "\n".join(lines)


def matrix(name: str, A: np.ndarray, rows, cols, indent: str = "  ") -> str:
    A = np.asarray(A)
    if A.size == 0:
        return f"{indent}{name} = [] (empty)"
    body = [[str(r)] + [num(v) for v in A[i]] for i, r in enumerate(rows)]
    return f"{indent}{name}:\n" + table([""] + [str(c) for c in cols], body, indent + "  ")
