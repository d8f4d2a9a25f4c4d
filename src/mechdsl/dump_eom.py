"""``mech compile --emit eom``: the equations of motion as deterministic text."""
from __future__ import annotations

MAX_OPS = 400


def _expr_text(e) -> str:
    import casadi as ca

    n = ca.Function("e", ca.symvar(e), [e]).n_instructions()
    if n > MAX_OPS:
        return f"<expression of {n} operations>"
    return str(e)


def dump_eom(eom) -> str:
    L = [f"eom {eom.name}: route {eom.route}, {eom.n} coordinates, {eom.m} constraints"]
    L.append("coordinates q = (" + ", ".join(eom.coords) + ")")
    L.append("parameters p = (" + ", ".join(eom.params) + ")")
    L.append(f"T = {_expr_text(eom.T)}")
    L.append(f"V = {_expr_text(eom.V)}")
    L.append(f"D = {_expr_text(eom.D)}")
    for i, c in enumerate(eom.coords):
        L.append(f"Q[{c}] = {_expr_text(eom.Q[i])}")
    for i in range(eom.n):
        for j in range(i + 1):
            L.append(f"M[{eom.coords[i]},{eom.coords[j]}] = {_expr_text(eom.M[i, j])}")
    for i, c in enumerate(eom.coords):
        L.append(f"bias[{c}] = {_expr_text(eom.bias[i])}")
    if eom.g is not None:
        for i, name in enumerate(eom.constraint_names):
            L.append(f"g[{name}] = {_expr_text(eom.g[i])}")
    for k, v in eom.outputs.items():
        L.append(f"output {k} = {_expr_text(v)}")
    return "\n".join(L) + "\n"
