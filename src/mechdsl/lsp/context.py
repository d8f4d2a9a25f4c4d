"""Where the cursor is, read from the text before it (which need not parse: completion is asked
for in the middle of typing): inside a comment or string, after ``a.b.``, at a modifier's name
inside ``Type name(...``, at the start of a statement, after a declaration prefix, or in an
expression; and in which model or scene, in which section.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

_LEX = re.compile(r'"(?:[^"\\\n]|\\.)*"?|//[^\n]*|/\*.*?(?:\*/|\Z)', re.S)
_WORD = re.compile(r"[A-Za-z_]\w*$")
_CHAIN = re.compile(r"((?:[A-Za-z_]\w*\s*(?:\[[^\[\]]*\]\s*)?\.\s*)+)([A-Za-z_]\w*)?$")
_UNIT = re.compile(r"\b(model|scene)\s+([A-Za-z_]\w*)|\bend\s+([A-Za-z_]\w*)\s*;|\bequation\b")
_BOUNDARY = re.compile(r";|\bequation\b|\bloop\b|\b(?:model|scene)\s+[A-Za-z_]\w*")
PREFIXES = ("parameter", "coordinate", "output", "input", "constant")


@dataclass
class Context:
    kind: str                      # none | member | modifier | statement | type | model-name | expression | naming
    word: str = ""                 # the part of a name typed so far
    chain: list[str] = field(default_factory=list)     # member: the names before the last dot
    owner: list[str] = field(default_factory=list)     # modifier: the words naming what is modified
    unit: str | None = None        # the model or scene the cursor is in
    unit_kind: str | None = None   # model | scene | None (between units)
    equations: bool = False        # in a model's equation section
    scene_model: str | None = None  # a scene's model


def code_only(text: str) -> tuple[str, bool]:
    """text with strings and comments blanked (offsets kept), and whether text ends inside a
    comment or an unterminated string."""
    out, inside, p = [], False, 0
    for m in _LEX.finditer(text):
        out.append(text[p:m.start()])
        tok = m.group()
        out.append(re.sub(r"[^\n]", " ", tok))
        p = m.end()
        if m.end() == len(text):
            inside = tok.startswith("//") or (tok.startswith("/*") and not (len(tok) >= 4 and tok.endswith("*/"))) \
                or (tok.startswith('"') and (len(tok) == 1 or not tok.endswith('"') or tok.endswith('\\"')))
    out.append(text[p:])
    return "".join(out), inside


def context_at(prefix: str) -> Context:
    """The context of a cursor after ``prefix`` (the whole text before it)."""
    code, inside = code_only(prefix)
    if inside:
        return Context("none")
    ctx = Context("expression")
    _unit(code, ctx)
    m = _WORD.search(code)
    ctx.word = m.group() if m else ""
    before = code[:len(code) - len(ctx.word)]
    if before.endswith(".") and before[-2:-1].isdigit() and not re.search(r"[A-Za-z_]\w*\s*\.$", before):
        return Context("none")             # 1. is a number
    chain = _CHAIN.search(code)
    if chain and chain.group(1).rstrip().endswith("."):
        names = [re.sub(r"\[.*", "", p).strip() for p in chain.group(1).split(".")[:-1]]
        start = chain.start()
        if start and code[start - 1].isdigit():
            return Context("none")
        ctx.kind, ctx.chain = "member", names
        return ctx
    paren = _open_paren(before)
    if paren is not None:
        owner = _modified(code, paren)
        if owner is not None:
            piece = before[paren + 1:]
            arg = re.split(r",", _top_level(piece))[-1]
            if "=" not in arg:
                ctx.kind, ctx.owner = "modifier", owner
                return ctx
        return ctx                          # a call's arguments, an array: an expression
    stmt = before[_boundary(before):].strip()
    if ctx.unit_kind is None:
        ctx.kind = "top" if not stmt else "none"
        return ctx
    if not stmt:
        ctx.kind = "statement"
        return ctx
    words = stmt.split()
    if words[0] in PREFIXES and len(words) == 1:
        ctx.kind = "type"
    elif words[0] == "extends" and len(words) == 1:
        ctx.kind = "model-name"
    elif words[0] == "model" and len(words) == 1 and ctx.unit_kind == "scene":
        ctx.kind = "model-name"
    elif re.fullmatch(r"(?:(?:parameter|coordinate|output|input|constant)\s+)?[A-Za-z_]\w*", stmt) \
            and not ctx.equations and ctx.unit_kind == "model":
        ctx.kind = "naming"                 # `Rod |`: the new name is the user's
    return ctx


def _unit(code: str, ctx: Context) -> None:
    stack: list[tuple[str, str]] = []
    eq = False
    for m in _UNIT.finditer(code):
        if m.group(1):
            if stack and stack[-1][0] == "scene" and m.group(1) == "model":
                ctx.scene_model = m.group(2)
                continue
            stack.append((m.group(1), m.group(2)))
            eq = False
        elif m.group(3):
            if stack and stack[-1][1] == m.group(3):
                stack.pop()
                ctx.scene_model = None
                eq = False
        else:
            eq = True
    if stack:
        ctx.unit_kind, ctx.unit = stack[-1]
        ctx.equations = eq and ctx.unit_kind == "model"
    else:
        ctx.scene_model = None


def _boundary(code: str) -> int:
    end = 0
    for m in _BOUNDARY.finditer(code):
        end = m.end()
    return end


def _top_level(s: str) -> str:
    """s with the insides of nested brackets removed."""
    out, depth = [], 0
    for ch in s:
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth = max(0, depth - 1)
        elif depth == 0:
            out.append(ch)
    return "".join(out)


def _open_paren(code: str, end: int | None = None) -> int | None:
    """The offset of the innermost bracket still open at ``end`` if it is a '(' (None for none
    or a '[' / '{'), within the current statement."""
    depth = 0
    i = len(code) if end is None else end
    while i > 0:
        i -= 1
        ch = code[i]
        if ch == ";":
            return None
        if ch in ")]}":
            depth += 1
        elif ch in "([{":
            if depth == 0:
                return i if ch == "(" else None
            depth -= 1
    return None


_HEAD = re.compile(r"(?:\b(parameter|coordinate|output|input|constant)\s+)?\b([A-Za-z_]\w*)\s+([A-Za-z_]\w*)\s*"
                   r"(?:\[[^\[\]]*\]\s*)?$")


def _modified(code: str, paren: int, depth: int = 0) -> list[str] | None:
    """What the modification opened at ``paren`` modifies, as words from the outside in:
    ["decl", prefix, Type, name] | ["extends", Base] | ["model", M] (a scene's), with the names of
    enclosing modifiers after them (``phi`` in ``Revolute j(phi(``); None for a call."""
    head = code[:paren]
    m = re.search(r"\b(extends|model)\s+([A-Za-z_]\w*)\s*$", head)
    if m:
        return [m.group(1), m.group(2)]
    m = _HEAD.search(head)
    if m and m.group(2) not in ("end", "equation", "connect", "force", "for") and m.group(3) not in ("loop",):
        return ["decl", m.group(1) or "", m.group(2), m.group(3)]
    m = re.search(r"(?:\beach\s+)?([A-Za-z_][\w.]*(?:\[\d+\])?)\s*$", head)
    if m and depth < 8:
        outer = _open_paren(code, m.start())
        if outer is not None:
            piece = code[outer + 1:m.start()]
            arg = _top_level(piece).split(",")[-1]
            if "=" not in arg:
                base = _modified(code, outer, depth + 1)
                if base is not None:
                    return base + [re.sub(r"\[\d+\]", "", m.group(1))]
    return None


__all__ = ["Context", "context_at", "code_only"]
