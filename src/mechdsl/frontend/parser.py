"""Phase 1, ``parse``: .mech text -> :class:`ast.File` (or a MechError with coded diagnostics).

The grammar is grammar/mech.lark (shipped inside the wheel as mechdsl/_grammar/mech.lark).
Syntax errors are turned into labelled diagnostics (E1xx); nothing from lark reaches users.
"""
from __future__ import annotations

import os
import re
from functools import lru_cache
from pathlib import Path

from lark import Lark, Token, v_args
from lark.visitors import Transformer_NonRecursive
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken, VisitError

from . import ast
from . import limits
from ..diagnostics import Diagnostic, InternalError, MechError, Span


KEYWORDS = {
    "model", "end", "equation", "extends", "parameter", "coordinate", "output", "input", "constant",
    "each", "kinetic", "potential", "dissipation", "force", "connect", "for", "in", "loop", "scene",
    "if", "then", "elseif", "else", "or", "and", "not", "true", "false",
}

_STATEMENT_START = {"end", "equation", "parameter", "coordinate", "output", "input", "constant", "extends",
                    "connect", "for", "kinetic", "potential", "dissipation", "force", "model", "scene"}

TOKEN_TEXT = {
    "SEMICOLON": "';'", "COMMA": "','", "LPAR": "'('", "RPAR": "')'", "LSQB": "'['", "RSQB": "']'",
    "LBRACE": "'{'", "RBRACE": "'}'", "EQUAL": "'='", "COLON": "':'", "DOT": "'.'", "CIRCUMFLEX": "'^'",
    "NAME": "a name", "NUMBER": "a number", "STRING": "a string", "ADD_OP": "'+' or '-'",
    "MUL_OP": "'*' or '/'", "REL_OP": "a comparison", "$END": "end of file", "EQUATION": "'equation'",
}


def grammar_path() -> Path:
    here = Path(__file__).resolve().parents[1]         # the mechdsl package
    for cand in (here / "_grammar" / "mech.lark", here.parents[1] / "grammar" / "mech.lark"):
        if cand.is_file():
            return cand
    raise InternalError("grammar file mech.lark not found (broken installation)")


@lru_cache(maxsize=1)
def _lark() -> Lark:
    # cache=True keeps the analysed LALR tables in the temp folder (keyed by the grammar's hash):
    # a cold start builds them in ~0.4 s, loading them takes ~0.03 s
    text = grammar_path().read_text(encoding="utf-8")
    try:
        return Lark(text, parser="lalr", lexer="basic", propagate_positions=True, maybe_placeholders=True,
                    cache=True)
    except OSError:  # an unwritable temp folder: build without the cache
        return Lark(text, parser="lalr", lexer="basic", propagate_positions=True, maybe_placeholders=True)


# ----------------------------------------------------------------------------- reading files

from .source import _file_kind, _too_large, decode_source, read_source  # noqa: E402,F401  (one reader)


# ----------------------------------------------------------------------------- parsing


def parse_file(path: str | os.PathLike) -> ast.File:
    name, text = read_source(path)
    return parse(text, name)


def parse(text: str, filename: str = "<input>") -> ast.File:
    tree, diagnostics = parse_partial(text, filename)
    if diagnostics:
        raise MechError(diagnostics)
    return tree


# The last texts parsed in this process, with their results: the AST and the diagnostics are
# immutable records (tuples inside), so a second parse of the same text (check, then compile,
# then equations of one file; an editor's unchanged buffer) returns the same objects instead
# of lexing and building again (about 10 ms for a shipped model).  Keyed by the limits in
# force, which the checks of nesting and depth read; texts over _MEMO_CHARS are not kept.
_MEMO: dict = {}
_MEMO_SIZE = 64
_MEMO_CHARS = 200_000


def parse_partial(text: str, filename: str = "<input>") -> tuple[ast.File | None, list[Diagnostic]]:
    """``parse`` for an editor's half-typed file: the diagnostics ``parse`` raises (the same list)
    and, when there are syntax errors, the AST of the text with the broken statements blanked as
    the error recovery blanks them (spans unchanged), or None when nothing could be recovered (a
    model not closed yet, an unterminated string, ...)."""
    from ..diagnostics import remember_source

    remember_source(filename, text)
    key = (text, filename, tuple(sorted(limits.current().items()))) if len(text) <= _MEMO_CHARS else None
    hit = _MEMO.pop(key, None) if key is not None else None
    if hit is None:
        tree, diagnostics = _parse_partial(text, filename)
        hit = (tree, tuple(diagnostics))
    if key is not None:
        _MEMO[key] = hit                          # most recent last
        if len(_MEMO) > _MEMO_SIZE:
            del _MEMO[next(iter(_MEMO))]
    return hit[0], list(hit[1])


def _parse_partial(text: str, filename: str) -> tuple[ast.File | None, list[Diagnostic]]:
    if not text.strip() or _only_comments(text):
        return None, [Diagnostic("E004", "file contains no model", Span(filename, 1, 1, 1, 1),
                                 "a file holds one or more `model Name ... end Name;` (and scenes)")]
    try:
        _check_nesting(text, filename)
    except MechError as e:
        return None, e.diagnostics
    tree, diagnostics = _parse_recovering(text, filename)
    if diagnostics:                      # the recovered rest, for an editor (never raised)
        try:
            result, _ = _build(tree, filename) if tree is not None else (None, [])
            if result is not None:
                _check_depth(result)
        except (MechError, InternalError):
            result = None
        return result, diagnostics
    result, problems = _build(tree, filename)
    if problems:
        return result, problems
    try:
        _check_depth(result)
    except MechError as e:
        return None, e.diagnostics
    return result, []


def _build(tree, filename: str) -> tuple[ast.File, list[Diagnostic]]:
    builder = _Builder(filename)
    try:
        result = builder.transform(tree)
    except VisitError as e:
        if isinstance(e.orig_exc, MechError):
            raise e.orig_exc from None
        raise InternalError(f"AST construction failed: {e.orig_exc!r}") from e.orig_exc
    return result, builder.problems


# ----------------------------------------------------------------------------- error recovery
MAX_SYNTAX_ERRORS = 20
_STRUCTURE = re.compile(r"\b(model|scene|end|equation|loop)\b")
_HEADER = re.compile(r"\b(?:(?:model|scene)\s+[A-Za-z_]\w*|equation|loop)\b")  # on code, docs blanked


def _parse_recovering(text: str, filename: str) -> tuple[object | None, list[Diagnostic]]:
    """Parse; on a syntax error blank the broken statement and parse again to find more errors.
    Returns the lark tree of the text with every broken statement blanked (None when the search
    stopped before the rest parsed) and the syntax diagnostics (none: the tree is the text's).

    Recovery is deliberately conservative so that no follow-on error is ever invented: the blanked
    region runs from the end of the previous statement (a ';' or a header such as `model A`,
    `equation`, `... loop`) to the next ';', and it may not contain a structural keyword (model,
    scene, end, equation, loop). An error on the first token after the blanked region is taken
    for a consequence of the blanking and not reported. Lexical errors that swallow the rest of
    the file (unterminated string or comment) and the end of the file stop the search.
    """
    diagnostics: list[Diagnostic] = []
    masked = text
    code = None   # `masked` without strings and comments, computed at the first error
    skip_to = -1  # an error exactly here is a consequence of the previous blanking
    while True:
        try:
            tree = _lark().parse(masked)
        except UnexpectedInput as e:
            pos = _error_offset(e)
            if diagnostics and pos == skip_to:
                break
            d = _syntax_diagnostic(e, masked, filename)
            diagnostics.append(d)
            if pos is None or d.code in ("E103", "E108", "E109") or len(diagnostics) >= MAX_SYNTAX_ERRORS:
                break
            code = _code_only(masked) if code is None else code
            region = _recovery_region(code, pos)
            if region is None:
                break
            a, b = region
            masked, code = (_blank(x, a, b) for x in (masked, code))   # blanking keeps code in step
            m = re.compile(r"\S").search(code, b)
            skip_to = m.start() if m else -1
            continue
        return tree, diagnostics
    return None, diagnostics


def _error_offset(e: UnexpectedInput) -> int | None:
    if isinstance(e, UnexpectedCharacters):
        return e.pos_in_stream
    tok = getattr(e, "token", None)
    if tok is None or tok.type == "$END" or tok.start_pos is None:
        return None
    return tok.start_pos


def _blank(text: str, a: int, b: int) -> str:
    """`text` with [a, b) replaced by spaces, line breaks kept (so every offset stays true)."""
    return text[:a] + re.sub(r"[^\r\n]", " ", text[a:b]) + text[b:]


def _code_only(text: str) -> str:
    """`text` with strings and comments replaced by spaces (offsets and newlines kept)."""
    return re.sub(r'"(?:[^"\\\n]|\\.)*"|//[^\n]*|/\*.*?\*/', lambda m: _blank(m.group(0), 0, len(m.group(0))),
                  text, flags=re.S)


def _recovery_region(code: str, pos: int) -> tuple[int, int] | None:
    """The statement around offset `pos` of `code` (see _parse_recovering), or None."""
    start = code.rfind(";", 0, pos) + 1
    for m in _HEADER.finditer(code, start, pos):
        start = m.end()
    end = code.find(";", pos)
    if end < 0 or _STRUCTURE.search(code, start, end + 1):
        return None
    return start, end + 1


def _check_depth(root: ast.Node) -> None:
    """Reject syntax trees deeper than the `depth` limit (e.g. sums of thousands of terms) with E104."""
    max_depth = limits.get("depth")
    stack = [(root, 1)]
    while stack:
        node, d = stack.pop()
        if d > max_depth:
            raise MechError(Diagnostic("E104", f"expression is too deeply nested (more than {max_depth} levels)",
                                       node.span, "split it with intermediate `Real` variables, or use sum() "
                                                  "over an array; " + limits.hint("depth")))
        stack.extend((c, d + 1) for c in node.child_nodes())


def _only_comments(text: str) -> bool:
    import re

    stripped = re.sub(r"//[^\n]*|/\*.*?\*/", "", text, flags=re.S)
    return not stripped.strip()


_WORD = re.compile(r"\w+")


def _check_nesting(text: str, filename: str) -> None:
    """Reject absurd bracket nesting (E104) and over-long names (E314) before the parser sees them.

    One linear scan that skips strings and comments."""
    max_nesting, max_name = limits.get("nesting"), limits.get("name_length")
    depth, line, col = 0, 1, 0
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        col += 1
        if ch == "\n":
            line, col = line + 1, 0
        elif ch == '"':  # a string ends at its closing quote or (unterminated: E108 later) at the line end
            j = i + 1
            while j < n and text[j] not in '"\n':
                j += 2 if text[j] == "\\" and j + 1 < n and text[j + 1] != "\n" else 1
            col += j - i
            i = j if j < n and text[j] == '"' else j - 1
        elif ch == "/" and text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j - 1
        elif ch == "/" and text.startswith("/*", i):
            j = text.find("*/", i + 2)
            if j < 0:
                raise MechError(Diagnostic("E109", "unterminated comment", Span(filename, line, col, line, col + 2),
                                           "close the comment with */"))
            j += 1
            line += text.count("\n", i, j)
            i = j
        elif ch in "([{":
            depth += 1
            if depth > max_nesting:
                raise MechError(Diagnostic(
                    "E104", f"brackets nested more than {max_nesting} deep",
                    Span(filename, line, col, line, col + 1),
                    "split the expression with intermediate `Real` variables; " + limits.hint("nesting")))
        elif ch in ")]}":
            depth = max(0, depth - 1)
        elif ch.isalnum() or ch == "_":  # a name or a number: one run of word characters
            m = _WORD.match(text, i)
            j = m.end() if m else i + 1
            if j - i > max_name and not ch.isdigit():
                raise MechError(Diagnostic(
                    "E314", f"name is too long ({j - i:,} characters, more than {max_name})",
                    Span(filename, line, col, line, col + 1),
                    "use a shorter name; " + limits.hint("name_length")))
            col += j - i - 1
            i = j - 1
        i += 1


def _describe(tok: Token) -> str:
    if tok.type == "$END":
        return "end of file"
    return f"'{tok.value}'" if tok.value else TOKEN_TEXT.get(tok.type, tok.type)


def _expected_text(expected) -> str:
    names = sorted({TOKEN_TEXT.get(t, f"'{t.lower()}'" if t.isupper() and t.isalpha() else t) for t in expected})
    if len(names) > 8:
        names = names[:8] + ["..."]
    return ", ".join(names)


def _syntax_diagnostic(e: UnexpectedInput, text: str, filename: str) -> Diagnostic:
    lines = text.split("\n")  # as the lexer counts lines
    if len(lines) > 1 and lines[-1] == "":
        lines.pop()
    line = getattr(e, "line", None) or 1
    col = getattr(e, "column", None) or 1
    if line == -1 or col == -1:  # EOF without position
        line = len(lines)
        col = len(lines[-1]) + 1
    if isinstance(e, UnexpectedCharacters):
        ch = text[e.pos_in_stream] if e.pos_in_stream < len(text) else ""
        span = Span(filename, line, col, line, col + 1)
        if ch == '"':
            return Diagnostic("E108", "unterminated string", span, 'close the string with " on the same line')
        if ch == "/" and text.startswith("/*", e.pos_in_stream):
            return Diagnostic("E109", "unterminated comment", span, "close the comment with */")
        if ch == "'":
            return Diagnostic("E101", "unexpected character \"'\"", span, 'strings use double quotes: "text"')
        if ch == ".":
            return Diagnostic("E106", "malformed number or stray '.'", span,
                              "numbers look like 1, 0.5, 2e-3; names are joined by single dots")
        shown = repr(ch) if ch.isprintable() else f"U+{ord(ch):04X}"
        return Diagnostic("E101", f"unexpected character {shown}", span,
                          "remove it; names use letters, digits and _")
    if isinstance(e, (UnexpectedToken, UnexpectedEOF)):
        tok = getattr(e, "token", None)
        expected = set(getattr(e, "expected", None) or getattr(e, "accepts", None) or ())
        if tok is None or tok.type == "$END":
            return Diagnostic("E103", "unexpected end of file", Span(filename, line, col, line, col + 1),
                              _eof_hint(text) or f"expected {_expected_text(expected)}")
        width = max(1, len(str(tok.value)))
        span = Span(filename, tok.line, tok.column, tok.end_line or tok.line,
                    tok.end_column or tok.column + width)
        before = text[tok.start_pos - 1] if tok.start_pos > 0 else ""
        if tok.type in ("NUMBER", "NAME") and (before.isdigit() or before == ".") and _after_number(text, tok.start_pos):
            bad = _number_text(text, tok)
            span = Span(filename, tok.line, tok.column - (len(bad) - width), span.end_line, span.end_col)
            return Diagnostic("E106", f"malformed number: '{bad}'", span,
                              "numbers look like 1, 0.5, 2e-3" + ("; multiply with '*': 2*L" if tok.type == "NAME"
                                                                  else ""))
        if tok.type == "DOT":
            return Diagnostic("E106", "stray '.'", span,
                              "numbers look like 1, 0.5, 2e-3; names are joined by single dots: rod.a.x")
        prev = _previous_token_end(text, tok)
        if "SEMICOLON" in expected and prev is not None and (prev[0] < tok.line or str(tok.value) in _STATEMENT_START):
            pl, pc = prev
            return Diagnostic("E107", "missing ';'", Span(filename, pl, pc, pl, pc + 1),
                              f"end the statement on line {pl} with ';'")
        if tok.type != "NAME" and str(tok.value) in KEYWORDS and "NAME" in expected:
            return Diagnostic("E105", f"'{tok.value}' is a reserved word and cannot be used as a name", span,
                              f"rename it, e.g. '{tok.value}_'")
        if tok.type == "EQUAL" and "REL_OP" in expected | {"REL_OP"} and _in_condition(text, tok):
            return Diagnostic("E102", "unexpected '=' in a condition", span, "compare with '=='")
        return Diagnostic("E102", f"unexpected {_describe(tok)}", span, f"expected {_expected_text(expected)}")
    return Diagnostic("E102", "syntax error", Span(filename, line, col, line, col + 1),
                      "see docs/language.md for the syntax")


def _after_number(text: str, pos: int) -> bool:
    """True when the token at pos directly follows a number (``1.2.3``, ``2L``, ``1e``)."""
    i = pos
    while i > 0 and (text[i - 1].isalnum() or text[i - 1] in "._"):
        i -= 1
    return text[i:pos][:1].isdigit() or (text[i:pos][:1] == "." and text[i + 1:pos][:1].isdigit())


def _number_text(text: str, tok: Token) -> str:
    i = tok.start_pos
    while i > 0 and (text[i - 1].isalnum() or text[i - 1] in "._"):
        i -= 1
    return text[i:tok.end_pos if tok.end_pos is not None else tok.start_pos + len(str(tok.value))]


def _in_condition(text: str, tok: Token) -> bool:
    start = text.rfind("\n", 0, tok.start_pos) + 1
    head = text[start:tok.start_pos]
    return " if " in f" {head}" or "elseif" in head


def _previous_token_end(text: str, tok: Token) -> tuple[int, int] | None:
    """Line and column just after the last non-blank, non-comment character before tok."""
    i = tok.start_pos - 1
    while i >= 0:
        # skip whitespace and line comments going backwards (approximate: strip // comments per line)
        line_start = text.rfind("\n", 0, i + 1) + 1
        line_text = text[line_start:i + 1]
        cut = line_text.find("//")
        if cut >= 0:
            line_text = line_text[:cut]
        stripped = line_text.rstrip()
        if stripped:
            line = text.count("\n", 0, line_start) + 1
            return line, len(stripped) + 1
        i = line_start - 2
    return None


def _eof_hint(text: str) -> str | None:
    import re

    opened = re.findall(r"^\s*(model|scene)\s+([A-Za-z_]\w*)", text, flags=re.M)
    closed = re.findall(r"\bend\s+([A-Za-z_]\w*)\s*;", text)
    for kind, name in opened:
        if name not in closed:
            return f"{kind} '{name}' is not closed: add `end {name};`"
    return None


# ----------------------------------------------------------------------------- tree -> AST


def _span(filename: str, meta) -> Span:
    if getattr(meta, "empty", True):
        return Span(filename)
    return Span(filename, meta.line, meta.column, meta.end_line, meta.end_column)


def _tok_span(filename: str, tok: Token) -> Span:
    return Span(filename, tok.line, tok.column, tok.end_line or tok.line,
                tok.end_column or tok.column + len(str(tok)))


def _unescape(raw: str) -> str:
    body = raw[1:-1]
    if "\\" not in body:
        return body
    out, i = [], 0
    table = {"n": "\n", "t": "\t", "r": "\r", '"': '"', "\\": "\\", "'": "'", "?": "?",
             "a": "\a", "b": "\b", "f": "\f", "v": "\v"}
    while i < len(body):
        c = body[i]
        if c == "\\" and i + 1 < len(body):
            out.append(table.get(body[i + 1], body[i + 1]))
            i += 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _number(text: str) -> int | float:
    if any(c in text for c in ".eE") or len(text) > 300:  # huge integers: float (inf, reported as E106)
        return float(text)
    return int(text)


@v_args(meta=True)
class _Builder(Transformer_NonRecursive):
    def __init__(self, filename: str):
        super().__init__(visit_tokens=False)
        self.f = filename
        self.problems: list[Diagnostic] = []

    def S(self, meta) -> Span:
        return _span(self.f, meta)

    # -- units
    def start(self, meta, items):
        return ast.File(items=tuple(items), filename=self.f, span=self.S(meta))

    def _check_end(self, kind, name_tok, end_tok):
        if str(name_tok) != str(end_tok):
            self.problems.append(Diagnostic(
                "E110", f"'end {end_tok}' does not match {kind} '{name_tok}'", _tok_span(self.f, end_tok),
                f"write `end {name_tok};`"))

    def model(self, meta, items):
        name, doc, *rest = items
        end = rest.pop()
        elements = tuple(x for x in rest if not isinstance(x, list))
        equations = tuple(e for x in rest if isinstance(x, list) for e in x)
        self._check_end("model", name, end)
        return ast.ModelDef(name=str(name), doc=doc, elements=elements, equations=equations,
                            name_span=_tok_span(self.f, name), span=self.S(meta))

    def equation_section(self, meta, items):
        return list(items[1:])

    def scene(self, meta, items):
        name, doc, *rest = items
        end = rest.pop()
        self._check_end("scene", name, end)
        return ast.SceneDef(name=str(name), doc=doc, items=tuple(rest), name_span=_tok_span(self.f, name),
                            span=self.S(meta))

    def scene_model(self, meta, items):
        name, mod = items
        return ast.SceneModel(name=str(name), modification=mod, name_span=_tok_span(self.f, name), span=self.S(meta))

    def setting(self, meta, items):
        name, value = items
        return ast.Setting(name=str(name), value=value, name_span=_tok_span(self.f, name), span=self.S(meta))

    # -- declarations
    def doc(self, meta, items):
        return _unescape(str(items[0])) if items and items[0] is not None else None

    def prefix(self, meta, items):
        return str(items[0])

    def declaration(self, meta, items):
        prefix, type_tok, name_tok, dims, mod, value, doc = items
        return ast.Declaration(prefix=prefix, type_name=str(type_tok), name=str(name_tok),
                               dims=tuple(dims or ()), modification=mod, value=value, doc=doc,
                               name_span=_tok_span(self.f, name_tok), type_span=_tok_span(self.f, type_tok),
                               span=self.S(meta))

    def extends_clause(self, meta, items):
        name, mod = items
        return ast.Extends(name=str(name), modification=mod, name_span=_tok_span(self.f, name), span=self.S(meta))

    def dims(self, meta, items):
        return tuple(items)

    def binding(self, meta, items):
        return items[0]

    def modification(self, meta, items):
        return tuple(x for x in items if x is not None)

    def dotted_name(self, meta, items):   # (name, span): the span goes to Modifier.name_span
        return ".".join(items), self.S(meta)

    def name_part(self, meta, items):
        name, index = items
        if index is None:
            return str(name)
        text = str(index)
        if not text.isdigit():
            self.problems.append(Diagnostic("E102", f"the element index in '{name}[{text}]' must be a positive integer",
                                            _tok_span(self.f, index), f"write {name}[2](...)"))
            return f"{name}[{text}]"
        return f"{name}[{int(text)}]"

    def coordinate_field(self, meta, items):
        return "coordinate", self.S(meta)

    def argument(self, meta, items):
        each, (name, name_span), mod, value = items
        return ast.Modifier(name=name, each=each is not None, modification=mod, value=value, name_span=name_span,
                            span=self.S(meta))

    # -- equations
    def simple_equation(self, meta, items):
        lhs, rhs, doc = items
        return ast.SimpleEquation(lhs=lhs, rhs=rhs, doc=doc, span=self.S(meta))

    def energy_kind(self, meta, items):
        return str(items[0])

    def energy_equation(self, meta, items):
        kind, expr, doc = items
        return ast.EnergyEquation(kind=kind, expr=expr, doc=doc, span=self.S(meta))

    def force_equation(self, meta, items):
        ref, expr, doc = items
        return ast.ForceEquation(coordinate=ref, expr=expr, doc=doc, span=self.S(meta))

    def connect_equation(self, meta, items):
        a, el, b, doc = items
        return ast.Connect(a=a, element=el, b=b, doc=doc, span=self.S(meta))

    def for_equation(self, meta, items):
        var, rng, *body = items
        return ast.ForEquation(var=str(var), range=rng, body=tuple(body), var_span=_tok_span(self.f, var),
                               span=self.S(meta))

    def range(self, meta, items):
        a, b, c = items
        if c is None:
            return ast.Range(start=a, stop=b, span=self.S(meta))
        return ast.Range(start=a, step=b, stop=c, span=self.S(meta))

    # -- expressions
    def if_expr(self, meta, items):
        cond, then, *rest = items
        otherwise = rest.pop()
        branches = [(cond, then)] + [tuple(b) for b in rest]
        return ast.IfExpr(branches=tuple(branches), otherwise=otherwise, span=self.S(meta))

    def elseif(self, meta, items):
        return (items[0], items[1])

    def or_op(self, meta, items):
        return ast.BinOp(op="or", left=items[0], right=items[1], span=self.S(meta))

    def and_op(self, meta, items):
        return ast.BinOp(op="and", left=items[0], right=items[1], span=self.S(meta))

    def not_op(self, meta, items):
        return ast.UnaryOp(op="not", operand=items[0], span=self.S(meta))

    def rel_op(self, meta, items):
        return ast.BinOp(op=str(items[1]), left=items[0], right=items[2], span=self.S(meta))

    def bin_op(self, meta, items):
        return ast.BinOp(op=str(items[1]), left=items[0], right=items[2], span=self.S(meta))

    def unary_op(self, meta, items):
        return ast.UnaryOp(op=str(items[0]), operand=items[1], span=self.S(meta))

    def pow_op(self, meta, items):
        return ast.BinOp(op="^", left=items[0], right=items[1], span=self.S(meta))

    def number(self, meta, items):
        return ast.Number(value=_number(str(items[0])), span=self.S(meta))

    def string(self, meta, items):
        return ast.String(value=_unescape(str(items[0])), span=self.S(meta))

    def true_lit(self, meta, items):
        return ast.Bool(value=True, span=self.S(meta))

    def false_lit(self, meta, items):
        return ast.Bool(value=False, span=self.S(meta))

    def call(self, meta, items):
        func, *args = items
        return ast.Call(func=func, args=tuple(a for a in args if a is not None), span=self.S(meta))

    def array(self, meta, items):
        return ast.Array(items=tuple(a for a in items if a is not None), span=self.S(meta))

    def comprehension(self, meta, items):
        expr, var, rng = items
        return ast.Comprehension(expr=expr, var=str(var), range=rng, var_span=_tok_span(self.f, var), span=self.S(meta))

    def component_ref(self, meta, items):
        return ast.Ref(parts=tuple(items), span=self.S(meta))

    def ref_part(self, meta, items):
        name, subs = items
        return ast.RefPart(name=str(name), subscripts=tuple(subs or ()), span=self.S(meta))

    def subscripts(self, meta, items):
        return tuple(items)

