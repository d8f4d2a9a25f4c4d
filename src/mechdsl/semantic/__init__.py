"""Phase 2, ``analyze``: AST -> resolved models (:mod:`mechdsl.model.ir`) and scenes.

``analyze(file)`` checks the file as a whole and returns a :class:`Program`; models and
scenes are flattened on request (``program.model(name)``, ``program.scene(name)``), so a
scene compiles only the model it needs.
"""
from __future__ import annotations

import math

from ..frontend import ast
from ..model import ir
from ..frontend import limits
from ..diagnostics import Diagnostic, DiagnosticBag, MechError, Span, did_you_mean
from ..frontend.printer import expr as print_expr
from . import mods as Mods
from .cycles import containment_cycles
from .flatten import Flattener
from .run_settings import check_run_settings

# scene settings: name -> kind; later phases may register more (extend, never rename)
SCENE_SETTINGS: dict[str, str] = {
    "stop_time": "number", "start_time": "number", "tolerance": "number", "rtol": "number", "atol": "number",
    "method": "string", "points": "integer", "outputs": "names", "formulation": "string", "dt": "number",
    "reactions": "bool", "compiled": "bool",
    "rest_speed": "number", "impact_order": "string", "output_events": "bool",  # contacts (docs/contacts.md)
}
ENERGY_SIGNALS = ("kinetic_energy", "potential_energy", "energy")


class Program:
    def __init__(self, file: ast.File, units: bool = True):
        self.file = file
        self.units = units
        self._models: dict[str, ast.ModelDef] = {}
        self._scenes: dict[str, ast.SceneDef] = {}
        diags = DiagnosticBag()
        if len(file.items) > limits.get("models"):
            item = file.items[limits.get("models")]
            raise MechError(Diagnostic("E317", f"the file holds more than {limits.get('models'):,} models and scenes "
                                               f"({len(file.items):,})", item.name_span,
                                       "split it into several files; " + limits.hint("models")))
        for item in file.items:
            table = self._models if isinstance(item, ast.ModelDef) else self._scenes
            other = self._scenes if isinstance(item, ast.ModelDef) else self._models
            if item.name in table or item.name in other:
                diags.error("E202", f"'{item.name}' is defined twice in this file", item.name_span,
                            "models and scenes share one namespace: rename one")
                continue
            table[item.name] = item
        diags.raise_if_errors()
        cycles = containment_cycles(self._models)
        if cycles:
            raise MechError(cycles)

    # ------------------------------------------------------------------ names
    def model_def(self, name: str) -> ast.ModelDef | None:
        return self._models.get(name)

    def model_names(self) -> list[str]:
        return list(self._models)

    def part_users(self) -> dict[str, list[str]]:
        """Models used as component types inside other models: {part: [models that contain it]}."""
        out: dict[str, list[str]] = {}
        for m in self._models.values():
            for el in m.elements:
                if isinstance(el, ast.Declaration) and el.type_name in self._models and el.type_name != m.name:
                    users = out.setdefault(el.type_name, [])
                    if m.name not in users:
                        users.append(m.name)
        return out

    def scene_def(self, name: str) -> ast.SceneDef | None:
        return self._scenes.get(name)

    def scene_names(self) -> list[str]:
        return list(self._scenes)

    def default_target(self) -> tuple[str, str]:
        """('scene', first scene) if the file has scenes, else ('model', last model)."""
        if self._scenes:
            return "scene", next(iter(self._scenes))
        return "model", list(self._models)[-1]

    # ------------------------------------------------------------------ flattening
    def model(self, name: str, modification: dict | None = None, span: Span | None = None) -> ir.Model:
        d = self._models.get(name)
        if d is None:
            raise MechError(Diagnostic("E206", f"no model named '{name}'", span or Span(self.file.filename),
                                       did_you_mean(name, self._models) or
                                       f"models in this file: {', '.join(self._models) or 'none'}"))
        from . import values

        key = _flat_key(self, name, modification)
        hit = _FLAT_MEMO.pop(key, None) if key is not None else None
        if hit is None or hit[0] is not self.file:
            token = values.UNITS.set(self.units)
            try:
                fl = Flattener(self, d, modification)
                fl.diags.raise_if_errors()
                model = fl.build()
            finally:
                values.UNITS.reset(token)
            hit = (self.file, model, tuple(fl.diags.warnings))
        if key is not None:
            _FLAT_MEMO[key] = hit                     # most recent last
            if len(_FLAT_MEMO) > _FLAT_MEMO_SIZE:
                del _FLAT_MEMO[next(iter(_FLAT_MEMO))]
        self.last_warnings = list(hit[2])
        return hit[1]

    def scene(self, name: str, extra: dict | None = None) -> ir.Scene:
        s = self._scenes.get(name)
        if s is None:
            raise MechError(Diagnostic("E602", f"no scene named '{name}'", Span(self.file.filename),
                                       did_you_mean(name, self._scenes) or
                                       f"scenes in this file: {', '.join(self._scenes) or 'none'}"))
        diags = DiagnosticBag()
        models = [it for it in s.items if isinstance(it, ast.SceneModel)]
        if not models:
            raise MechError(Diagnostic("E603", f"scene '{name}' names no model", s.name_span,
                                       "add `model ModelName;` to the scene"))
        if len(models) > 1:
            raise MechError(Diagnostic("E603", f"scene '{name}' names more than one model", models[1].span,
                                       "a scene simulates one model"))
        mm = models[0]
        mods = Mods.from_ast(mm.modification, diags)
        diags.raise_if_errors()
        if extra:
            mods = Mods.merge_dicts(mods, extra)
        model = self.model(mm.name, mods, mm.span)
        settings = self._settings(s, model)
        return ir.Scene(name, model, s.doc or "", tuple(settings), s.span)

    def _settings(self, s: ast.SceneDef, model: ir.Model) -> list[tuple[str, object]]:
        diags = DiagnosticBag()
        out: dict[str, object] = {}
        values = {p.name: p.value for p in model.parameters}
        for it in s.items:
            if not isinstance(it, ast.Setting):
                continue
            kind = SCENE_SETTINGS.get(it.name)
            if kind is None:
                diags.error("E601", f"unknown scene setting '{it.name}'", it.span,
                            did_you_mean(it.name, SCENE_SETTINGS) or "settings: " + ", ".join(SCENE_SETTINGS))
                continue
            if it.name in out:
                diags.error("E202", f"setting '{it.name}' is given twice", it.span, "keep one of them")
                continue
            try:
                out[it.name] = _setting_value(it, kind, values, model)
            except MechError as e:
                diags.extend(e.diagnostics)
        diags.raise_if_errors()
        check_run_settings(s, out, model)
        if "tolerance" in out:
            out.setdefault("rtol", out["tolerance"])
            out.setdefault("atol", out["tolerance"])
        return list(out.items())


def _setting_value(it: ast.Setting, kind: str, values: dict[str, float], model: ir.Model):
    from ..model import exprs as X

    v = it.value

    def bad(msg, help=None):
        raise MechError(Diagnostic("E604", msg, v.span, help))

    if kind == "string":
        if not isinstance(v, ast.String):
            bad(f"'{it.name}' must be a string", f'{it.name} = "..."')
        return v.value
    if kind == "bool":
        if not isinstance(v, ast.Bool):
            bad(f"'{it.name}' must be true or false", f"{it.name} = true;")
        return v.value
    if kind == "names":
        items = v.items if isinstance(v, ast.Array) else (v,)
        names = []
        for x in items:
            if isinstance(x, ast.String):
                names.append((x.value, x.span))
            elif isinstance(x, (ast.Ref, ast.Call)):
                names.append((print_expr(x), x.span))
            else:
                bad(f"'{it.name}' lists names of outputs or coordinates", "e.g. outputs = {x, y, der(theta)};")
        return tuple(_expand_names(names, model))
    # number / integer: a constant expression in literals and parameters
    try:
        num = _const_eval(v, values)
    except (ValueError, KeyError, ZeroDivisionError, OverflowError, TypeError) as ex:
        bad(f"'{it.name}' must be a number ({ex})", "use numbers, parameters of the model and + - * / ^")
    if isinstance(num, complex):
        bad(f"'{it.name}' has no real value", "a negative number raised to a fractional power is complex")
    if not math.isfinite(num):
        bad(f"'{it.name}' must be finite", "check the formula")
    if kind == "integer":
        if not float(num).is_integer() or num < 1:
            bad(f"'{it.name}' must be a positive whole number", f"e.g. {it.name} = 501;")
        return int(num)
    if it.name in ("rtol", "atol", "tolerance", "dt") and num <= 0:
        bad(f"'{it.name}' must be positive", f"e.g. {it.name} = 1e-8;")
    return float(num)


def _const_eval(e: ast.Expr, values: dict[str, float]) -> float:
    if isinstance(e, ast.Number):
        return float(e.value)
    if isinstance(e, ast.Ref) and e.simple is not None:
        if e.simple == "pi":
            return math.pi
        if e.simple in values:
            return values[e.simple]
        raise ValueError(f"'{e.simple}' is not a parameter")
    if isinstance(e, ast.UnaryOp) and e.op in "+-":
        x = _const_eval(e.operand, values)
        return -x if e.op == "-" else x
    if isinstance(e, ast.BinOp) and e.op in "+-*/^":
        a, b = _const_eval(e.left, values), _const_eval(e.right, values)
        return {"+": a + b, "-": a - b, "*": a * b, "/": a / b, "^": a ** b}[e.op]
    if isinstance(e, ast.Call) and e.func.simple in ("sqrt", "sin", "cos", "exp", "log"):
        return getattr(math, e.func.simple)(*[_const_eval(a, values) for a in e.args])
    raise ValueError("use numbers and parameters")


def _expand_names(names: list[tuple[str, Span]], model: ir.Model) -> list[str]:
    known = {o.name for o in model.outputs} | set(model.coordinate_names) | {
        f"der({c})" for c in model.coordinate_names} | set(ENERGY_SIGNALS)
    out: list[str] = []
    diags = DiagnosticBag()
    for n, span in names:
        if n in known:
            out.append(n)
            continue
        prefixed = [k for k in sorted(known) if k.startswith(n + "[")]
        if prefixed:
            out += [o.name for o in model.outputs if o.name.startswith(n + "[")] or prefixed
            continue
        diags.error("E201", f"'{n}' is not an output or coordinate of model '{model.name}'", span,
                    did_you_mean(n, known) or "declare it in the model as `output Real name = ...;`")
    diags.raise_if_errors()
    return out


# The last models flattened in this process, like the parse memo (frontend/parser.py): the parser
# returns the same (immutable) AST for the same text, so a model flattened again from the same
# file object with the same modification, units switch and limits is the same (immutable)
# ir.Model with the same warnings (check, then simulate, then equations of one file; an editor's
# unchanged buffer; a scene's model).  The entry holds its AST, so the id in the key is never
# reused while it is kept; models that failed are not kept (flattened again, the same errors).
_FLAT_MEMO: dict = {}
_FLAT_MEMO_SIZE = 64


def _frozen(v):
    """``v`` hashable, each value with its type (2, 2.0 and True are equal keys otherwise, and an
    Integer parameter given 2.0 is an error where 2 is not)."""
    if isinstance(v, dict):
        return tuple(sorted((k, _frozen(x)) for k, x in v.items()))
    if isinstance(v, (list, tuple)):
        return (type(v).__name__, tuple(_frozen(x) for x in v))
    return type(v).__name__, v


def _flat_key(program: Program, name: str, modification: dict | None):
    """The memo's key, None when the modification holds something unhashable."""
    try:
        key = (id(program.file), bool(program.units), name, _frozen(modification or {}),
               tuple(sorted(limits.current().items())))
        hash(key)
    except TypeError:
        return None
    return key


def analyze(file: ast.File, units: bool = True) -> Program:
    """Check the file as a whole; ``units=False`` switches dimensional analysis off."""
    return Program(file, units)


__all__ = ["analyze", "Program", "SCENE_SETTINGS"]
