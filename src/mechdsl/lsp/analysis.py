"""The server's analysis of one document, in two stages, each the same work ``mech check`` does:

1. ``analyse``: read (size, NUL), parse, analyse the file, load every target ``mech check``
   checks (models that are not parts of others, scenes) and every model alone for the values
   hover shows.  Milliseconds for the shipped models; its diagnostics are published at once.
2. ``start_problems``: derive each loaded target's equations of motion and check its start state
   (mechdsl.eom.preflight; for a scene also the run's validation): ``mech check``'s
   ``check_start_state``.  This can take seconds for a large model, so the server runs it in a
   worker of its own and publishes its diagnostics with stage 1's when it ends (nothing when
   the text changed meanwhile).

A syntax error stops after stage 1's parse, as ``mech check`` stops; the AST of the rest of the
file (frontend.parser.parse_partial) still gives the symbol index, so hover, completion and go to
definition keep working in the other statements of a half-typed file.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..diagnostics import Diagnostic, MechError, Span
from ..frontend import ast


@dataclass
class Analysis:
    text: str
    filename: str
    tree: ast.File | None = None          # the whole text's AST, or the rest of a half-typed file's
    index: object | None = None           # semantic.symbols.SymbolIndex of tree
    complete: bool = False                # no syntax errors: tree is the text's own
    diagnostics: list[Diagnostic] = field(default_factory=list)
    loaded: list = field(default_factory=list)       # api.Model of each target that loaded
    flat: dict = field(default_factory=dict)         # model name -> ir.Model (the model alone)
    scene_models: dict = field(default_factory=dict)  # scene name -> ir.Model (with its modifications)


def analyse(text: str, filename: str) -> Analysis:
    """Stage 1 (see the module docstring)."""
    from ..frontend.parser import parse_partial
    from ..frontend.source import decode_source
    from ..semantic.symbols import SymbolIndex

    a = Analysis(text, filename)
    try:      # what the file reader checks (E002 NUL byte or a lone surrogate, E005 size)
        decode_source(text.encode("utf-8", "surrogatepass"), filename)
    except MechError as e:
        a.diagnostics = e.diagnostics
        return a
    a.tree, syntax = parse_partial(text, filename)
    a.index = SymbolIndex(a.tree) if a.tree is not None else None
    if syntax:
        a.diagnostics = syntax
        return a
    a.complete = True
    _semantic(a)
    return a


def _semantic(a: Analysis) -> None:
    from ..api import Model
    from ..commands.check import check_targets
    from ..semantic import analyze

    try:
        program = analyze(a.tree)
    except MechError as e:
        a.diagnostics = e.diagnostics
        return
    found: list[Diagnostic] = []
    for kind, name in check_targets(program):
        unit = program.model_def(name) if kind == "model" else program.scene_def(name)
        try:
            m = Model._from_program(program, name if kind == "model" else None, name if kind == "scene" else None)
        except MechError as e:
            found += locate(e.diagnostics, unit)
            continue
        a.loaded.append(m)
        found += locate(m.warnings, unit)
        if kind == "model":
            a.flat[name] = m.model
        else:
            a.scene_models[name] = m.model
    for name in program.model_names():     # the parts alone, for hover's values (their errors are not reported)
        if name not in a.flat:
            try:
                a.flat[name] = program.model(name)
            except MechError:
                pass
    a.diagnostics = unique(found)


def start_problems(a: Analysis, still_wanted=lambda: True) -> list[Diagnostic]:
    """Stage 2 (see the module docstring); ``still_wanted()`` False stops between targets."""
    from ..commands.check import check_start_state

    found: list[Diagnostic] = []
    for m in a.loaded:
        if not still_wanted():
            break
        unit = a.tree and next((u for u in a.tree.items if u.name == (m.scene or m.model).name), None)
        try:
            check_start_state(m)
        except MechError as e:
            found += locate(e.diagnostics, unit)
    return unique(found)


def locate(diags, unit) -> list[Diagnostic]:
    """A diagnostic without a position is shown at the header of the model or scene it is about
    (``mech check`` prints it without a line)."""
    out = []
    for d in diags:
        if d.span.line <= 0 and unit is not None and unit.span.line > 0:
            ns = unit.name_span
            d = dataclasses.replace(d, span=Span(d.span.file if d.span.file not in ("", "<input>") else ns.file,
                                                 unit.span.line, unit.span.col, ns.end_line, ns.end_col))
        out.append(d)
    return out


def unique(diags) -> list[Diagnostic]:
    return list(dict.fromkeys(diags))


__all__ = ["Analysis", "analyse", "start_problems", "locate"]
