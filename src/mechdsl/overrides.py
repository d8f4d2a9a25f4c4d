"""What ``Model.with_params`` changes (mechdsl.api): values in the declared units, the
override trees of structural values (Integer and Boolean parameters, start values) as the
front end reads scene modifiers, and the dependent parameters re-evaluated."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .diagnostics import Diagnostic, MechError, UsageError
from .model import ir
from .numbers import Quantity, finite, in_declared_unit, quantity


def with_values(model: ir.Model, values: dict[str, float]) -> ir.Model:
    """``model`` with the Real parameters in ``values`` set (their bindings dropped) and the
    dependent parameters re-evaluated, in the order they depend on each other."""
    from .model.exprs import evaluate

    params = [dataclasses.replace(p, value=values[p.name], binding=None) if p.name in values else p
              for p in model.parameters]
    dependent = [k for k, p in enumerate(params) if p.binding is not None and not p.integer]
    env = {p.name: p.value for k, p in enumerate(params) if k not in dependent}
    while dependent:              # in the order they depend on each other (a value may refer ahead)
        left = []
        for k in dependent:
            try:
                params[k] = dataclasses.replace(params[k], value=dependent_value(params[k], env, evaluate))
                env[params[k].name] = params[k].value
            except KeyError:      # refers to a dependent parameter not yet evaluated
                left.append(k)
        if len(left) == len(dependent):
            raise UsageError(f"parameter {params[left[0]].name} depends on parameters that cannot be evaluated")
        dependent = left
    return dataclasses.replace(model, parameters=tuple(params))


def dependents_of(eom, fixed: set[int]) -> set[int]:
    """Entries of p computed (by bindings) only from the free parameters among ``fixed``."""
    from .eom.codegen import casadi_functions, free_parameters

    free = free_parameters(eom)
    f = casadi_functions(eom, names=("parameters",))["parameters"]
    sp = f.jac_sparsity(0, 0)           # rows: entries of p, columns: free parameters
    fixed_free = {j for j, n in enumerate(free) if eom.params.index(n) in fixed}
    out = set()
    for i in range(len(eom.params)):
        cols = {j for j in range(len(free)) if sp.has_nz(i, j)}
        if eom.params[i] not in free and cols and cols <= fixed_free:
            out.add(i)
    return out


def dependent_value(p: ir.Parameter, env: dict[str, float], evaluate) -> float:
    """A dependent parameter re-evaluated with new values: a value it cannot have (1/0,
    sqrt(-1), overflow) is E303 at the parameter, as when the file itself is analyzed."""
    problem = None
    try:
        with np.errstate(all="ignore"):
            value = float(evaluate(p.binding, env))
        if not math.isfinite(value):
            problem = f"evaluates to {value}"
    except (ValueError, ZeroDivisionError, OverflowError) as ex:
        problem = f"cannot be evaluated: {ex}"
    except TypeError:  # a complex number: a negative base to a fractional power
        problem = "has no real value"
    if problem is None:
        return value
    raise MechError(Diagnostic("E303", f"parameter '{p.name}' {problem} with the values given", p.span,
                               "it depends on the parameters changed (--set / with_params): check their "
                               "values against its formula (division by zero, a function's domain)"))


def in_declared_unit_of(model: ir.Model, key: str, v):
    """A start value or speed given with a unit (``deg(30)``, ``"30 deg"``) -> a bare number in the
    coordinate's declared unit, which the front end reads as it reads a scene modifier (issue 23)."""
    if isinstance(v, bool) or not isinstance(v, (str, Quantity)):
        return v
    if isinstance(v, str):
        try:
            v = quantity(v, key)
        except UsageError:
            return v                       # not a number: literal says so, naming the parameter
    name, _, attr = key.rpartition(".")
    if attr not in ("start", "speed"):
        name, attr = key, "start"
    try:
        unit = model.coordinate(name).unit
    except KeyError:
        unit = None
    return in_declared_unit(v, unit, key, speed=attr == "speed")


def number(name: str, v) -> float:
    return finite(v, f"value of '{name}'")


def literal(v, name: str = "value"):
    from .frontend import ast

    if isinstance(v, bool):
        return ast.Bool(value=v)
    x = number(name, v)
    if float(x).is_integer() and isinstance(v, int):
        return ast.Number(value=int(v)) if x >= 0 else ast.UnaryOp(op="-", operand=ast.Number(value=-int(v)))
    return ast.Number(value=abs(x)) if x >= 0 else ast.UnaryOp(op="-", operand=ast.Number(value=-x))


def add_override(tree: dict, key: str, value, by_name, coords) -> None:
    from .semantic.mods import Mod

    parts = key.split(".")
    if parts[-1] not in ("start", "speed", "fixed") and key not in by_name:
        if key in coords:
            parts = parts + ["start"]
        else:
            raise UsageError(f"'{key}' is not a parameter or a start value (use NAME.start or NAME.speed)")
    node_dict = tree
    for i, part in enumerate(parts):
        node = node_dict.setdefault(part, Mod())
        if i == len(parts) - 1:
            node.value = literal(value, key)
        node_dict = node.sub


def key_value(v):
    """A structural value as the cache key sees it: N=4 and N=4.0 are one model."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return v
    return float(v)


def overrides_of(items, model: ir.Model) -> dict:
    """The override tree of structural ``with_params`` items (a cached Model keeps only these)."""
    by_name = {p.name: p for p in model.parameters}
    coords = set(model.coordinate_names)
    tree: dict = {}
    for k, v in items:
        add_override(tree, k, v, by_name, coords)
    return tree


def merge_overrides(a: dict, b: dict) -> dict:
    from .semantic.mods import merge_dicts

    return merge_dicts(a, b)
