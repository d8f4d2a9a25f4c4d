"""Editor support: the Pygments lexer (entry point `mech`) and the TextMate grammar in editors/,
against every shipped model, and their word lists against the grammar and the semantic tables."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import MODELS, CHECKOUT, model_files

sys.path.insert(0, str(CHECKOUT / "editors"))
import make_textmate  # noqa: E402

from mechdsl.frontend import lexer as L  # noqa: E402


def test_word_lists_match_the_language():
    from mechdsl.semantic.components import CLASSES
    from mechdsl.semantic.evaluate import ALL_FUNCS, BUILTIN_NAMES

    lark = (CHECKOUT / "grammar" / "mech.lark").read_text()
    keywords = set(re.findall(r'"([a-z_]+)"', lark))
    ours = set(L.KEYWORDS) | set(L.DECLARATIONS) | set(L.ENERGY_WORDS) | set(L.CONSTANTS)
    assert ours == keywords, (sorted(ours - keywords), sorted(keywords - ours))
    assert set(L.COMPONENTS) == set(CLASSES)
    assert set(L.FUNCTIONS) == set(ALL_FUNCS)
    assert set(L.BUILTIN_NAMES) == set(BUILTIN_NAMES)


def test_pygments_finds_the_lexer_by_name_and_file_name():
    from pygments.lexers import get_lexer_by_name, get_lexer_for_filename

    assert isinstance(get_lexer_by_name("mech"), L.MechLexer)
    assert isinstance(get_lexer_for_filename("pendulum.mech"), L.MechLexer)


@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_pygments_lexes_every_model_without_errors(path):
    from pygments.token import Error, Keyword, Name

    text = path.read_text()
    tokens = list(L.MechLexer().get_tokens(text))
    assert not [v for t, v in tokens if t in Error], path.name
    assert "".join(v for _, v in tokens) == text.replace("\r\n", "\n") + ("" if text.endswith("\n") else "\n")
    kinds = {t for t, _ in tokens}
    assert Keyword in kinds and (Name.Builtin in kinds or Keyword.Pseudo in kinds)


def test_textmate_grammar_is_generated_from_the_lexer():
    assert (CHECKOUT / "editors" / "mech.tmLanguage.json").read_text() == make_textmate.text(), \
        "stale: run python editors/make_textmate.py"


def _textmate_scopes(grammar: dict, text: str) -> list[str | None]:
    """A small TextMate engine (enough for this grammar: match rules, begin/end rules with nested
    match patterns, includes): the scope of every character, None where no rule matched."""
    repo = grammar["repository"]

    def flat(patterns):
        for p in patterns:
            if "include" in p:
                yield from flat(repo[p["include"][1:]]["patterns"])
            else:
                yield p

    top = list(flat(grammar["patterns"]))
    scopes: list[str | None] = [None] * len(text)
    pos, stack = 0, []                      # stack: the open begin/end rule
    while pos < len(text):
        rules = stack[-1].get("patterns", []) if stack else top
        best = None
        # in the order of the patterns (a tie in position goes to the earlier rule, as in TextMate)
        candidates = [(re.compile(r["match"] if "match" in r else r["begin"], re.M), r,
                       "match" if "match" in r else "begin") for r in rules]
        if stack:
            candidates.append((re.compile(stack[-1]["end"], re.M), stack[-1], "end"))
        for rx, rule, kind in candidates:
            m = rx.search(text, pos)
            if m and m.end() > m.start() and (best is None or m.start() < best[0].start()):
                best = (m, rule, kind)
        if best is None:
            break
        m, rule, kind = best
        inside = stack[-1]["name"] if stack else None
        for i in range(pos, m.start()):
            scopes[i] = inside
        if kind == "match":
            name = rule.get("name") or inside
            for i in range(m.start(), m.end()):
                scopes[i] = name
            for g, cap in rule.get("captures", {}).items():
                for i in range(m.start(int(g)), m.end(int(g))):
                    scopes[i] = cap["name"]
        elif kind == "begin":
            for i in range(m.start(), m.end()):
                scopes[i] = rule["name"]
            stack.append(rule)
        else:
            for i in range(m.start(), m.end()):
                scopes[i] = rule["name"]
            stack.pop()
        pos = m.end()
    return scopes


@pytest.mark.slow_cases('andrews.mech', 'arm7.mech')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_textmate_grammar_covers_every_model(path):
    grammar = json.loads((CHECKOUT / "editors" / "mech.tmLanguage.json").read_text())
    text = path.read_text()
    scopes = _textmate_scopes(grammar, text)
    bare = [(i, c) for i, (c, s) in enumerate(zip(text, scopes)) if s is None and not c.isspace()]
    assert not bare, f"{path.name}: characters without a scope: {bare[:5]}"
    used = set(scopes)
    assert "keyword.control.mech" in used and "comment.line.double-slash.mech" in used


def test_textmate_engine_sees_comments_and_strings():
    """The engine above is itself checked on a hand-made line."""
    grammar = json.loads((CHECKOUT / "editors" / "mech.tmLanguage.json").read_text())
    text = 'model A "doc // not a comment" /* c\nc */ Revolute j; // end\n'
    s = _textmate_scopes(grammar, text)
    assert s[text.index("doc")] == "string.quoted.double.mech"
    assert s[text.index("not a comment")] == "string.quoted.double.mech"
    assert s[text.index("c\nc")] == "comment.block.mech"
    assert s[text.index("Revolute")] == "support.class.component.mech"
    assert s[text.index("// end")] == "comment.line.double-slash.mech"


# ----------------------------------------------------------------------------- the VS Code extension

VSCODE = CHECKOUT / "editors" / "vscode"


def test_vscode_extension_contributes_files_that_exist():
    pkg = json.loads((VSCODE / "package.json").read_text())
    contrib = pkg["contributes"]
    (lang,) = contrib["languages"]
    assert lang["id"] == "mech" and lang["extensions"] == [".mech"]
    conf = json.loads((VSCODE / lang["configuration"]).read_text())
    assert conf["comments"] == {"lineComment": "//", "blockComment": ["/*", "*/"]}
    assert ["(", ")"] in conf["brackets"] and ["{", "}"] in conf["brackets"]
    for pattern in conf["indentationRules"].values():
        re.compile(pattern)
    (gram,) = contrib["grammars"]
    assert gram["language"] == "mech"
    grammar = json.loads((VSCODE / gram["path"]).read_text())
    assert grammar["scopeName"] == gram["scopeName"] == "source.mech"
    assert (VSCODE / pkg["main"]).is_file()
    assert "vscode-languageclient" in pkg["dependencies"]
    assert set(contrib["configuration"]["properties"]) >= {"mech.server.path", "mech.server.args",
                                                            "mech.diagnostics.debounceMs"}


def test_vscode_extension_ships_the_committed_grammar():
    assert (VSCODE / "syntaxes" / "mech.tmLanguage.json").read_bytes() == \
        (CHECKOUT / "editors" / "mech.tmLanguage.json").read_bytes(), "stale copy: run python editors/make_textmate.py"
    assert [p.relative_to(CHECKOUT / "editors") for p in make_textmate.TARGETS] == \
        [Path("mech.tmLanguage.json"), Path("vscode/syntaxes/mech.tmLanguage.json")]


def test_vscode_client_starts_mech_lsp_with_the_settings():
    js = (VSCODE / "extension.js").read_text()
    assert 'require("vscode-languageclient/node")' in js
    assert 'config.get("server.path", "mech")' in js and 'config.get("server.args", ["lsp"])' in js
    assert "debounceMs" in js and 'language: "mech"' in js


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed: the client's syntax is not checked")
def test_vscode_client_is_valid_javascript():
    p = subprocess.run(["node", "--check", str(VSCODE / "extension.js")], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
