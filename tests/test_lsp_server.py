"""`mech lsp` driven over stdio as an editor drives it: a real subprocess (`python -m mechdsl lsp`),
JSON-RPC with Content-Length framing (tests/lsp_client.py): initialize, didOpen a shipped model,
publishDiagnostics, hover, definition, completion, documentSymbol, formatting, didChange to broken
texts, shutdown and exit."""
from __future__ import annotations

import time

import pytest

from conftest import MODELS
from lsp_client import LspClient, pos
from mechdsl.frontend.format import format_source

PATH = MODELS / "double_pendulum.mech"
TEXT = PATH.read_text()
URI = PATH.as_uri()


@pytest.fixture(scope="module")
def server():
    c = LspClient({"debounceMs": 20})
    yield c
    assert c.internal_errors() == []
    assert c.close() == 0
    assert c.raw_out == []                   # nothing but protocol messages on stdout


def _doc(uri=URI):
    return {"textDocument": {"uri": uri}}


def test_initialize_announces_the_features(server):
    caps = server.init_result["result"]["capabilities"]
    assert caps["hoverProvider"] and caps["definitionProvider"] and caps["documentSymbolProvider"]
    assert caps["documentFormattingProvider"]
    assert caps["completionProvider"]["triggerCharacters"] == ["."]
    assert caps["textDocumentSync"]["change"] == 1            # whole documents
    assert server.init_result["result"]["serverInfo"]["name"] == "mechdsl"


def test_a_shipped_model_opens_without_diagnostics_and_answers(server):
    server.open(URI, TEXT, 1)
    assert server.diagnostics(URI, 1)["diagnostics"] == []

    h = server.result("textDocument/hover", {**_doc(), "position": pos(TEXT, "-g, 0}", delta=1)})
    assert h["contents"]["kind"] == "markdown"
    assert "g = 9.81 m/s2" in h["contents"]["value"] and "unit m/s2" in h["contents"]["value"]
    assert h["range"] == {"start": pos(TEXT, "-g, 0}", delta=1), "end": pos(TEXT, "-g, 0}", delta=2)}

    d = server.result("textDocument/definition", {**_doc(), "position": pos(TEXT, "L = l", delta=4)})
    assert d["uri"] == URI
    assert d["range"]["start"] == pos(TEXT, "l(unit") and d["range"]["end"] == pos(TEXT, "l(unit", delta=1)
    d = server.result("textDocument/definition", {**_doc(), "position": pos(TEXT, "model DoublePendulum;", delta=8)})
    assert d["range"]["start"] == pos(TEXT, "DoublePendulum \"Two")            # the scene's model

    c = server.result("textDocument/completion", {**_doc(), "position": pos(TEXT, "rod2.b.x", delta=5)})
    labels = {i["label"] for i in c["items"]}
    assert {"a", "b", "com", "m", "L", "w_body"} <= labels

    syms = server.result("textDocument/documentSymbol", _doc())
    assert [(s["name"], s["kind"]) for s in syms] == [("DoublePendulum", 5), ("Chaos", 24)]
    children = {c["name"]: c["detail"] for c in syms[0]["children"]}
    assert children["m"] == "parameter Real" and children["rod1"] == "component Rod"
    assert children["j1"] == "component Revolute" and children["x2"] == "output Real"

    assert server.result("textDocument/formatting", {**_doc(), "options": {"tabSize": 2, "insertSpaces": True}}) == []


def test_broken_texts_give_the_right_code_and_range(server):
    bad = TEXT.replace("child = rod2.a", "child = rod3.a")
    server.change(URI, bad, 2)
    ds = server.diagnostics(URI, 2)["diagnostics"]
    assert [d["code"] for d in ds] == ["E201"]
    assert ds[0]["range"] == {"start": pos(bad, "rod3.a"), "end": pos(bad, "rod3.a", delta=4)}
    assert ds[0]["severity"] == 1 and ds[0]["source"] == "mech"
    assert "undefined name 'rod3'" in ds[0]["message"] and "help: did you mean 'rod2'?" in ds[0]["message"]

    half = TEXT.replace("  output Real y2", "  output Real s = rod1.\n  output Real y2")
    server.change(URI, half, 3)
    ds = server.diagnostics(URI, 3)["diagnostics"]
    assert ds and ds[0]["code"] in ("E102", "E105")
    # completion and hover keep working in the rest of a half-typed file
    c = server.result("textDocument/completion", {**_doc(), "position": pos(half, "rod1.\n", delta=5)})
    assert {"a", "b", "w_body"} <= {i["label"] for i in c["items"]}
    h = server.result("textDocument/hover", {**_doc(), "position": pos(half, "Rod rod2", delta=5)})
    assert "component of model DoublePendulum" in h["contents"]["value"]
    # a file with syntax errors is not formatted: no edits, a message
    assert server.result("textDocument/formatting", {**_doc(), "options": {"tabSize": 2, "insertSpaces": True}}) is None
    msg = server.wait_for(lambda m: m.get("method") == "window/showMessage")
    assert "not formatted" in msg["params"]["message"] and msg["params"]["type"] == 2

    cut = TEXT[:TEXT.index("end DoublePendulum")]
    server.change(URI, cut, 4)
    ds = server.diagnostics(URI, 4)["diagnostics"]
    assert [d["code"] for d in ds] == ["E103"]


def test_start_state_problems_arrive_after_the_names(server):
    bad = TEXT.replace("start = pi/2", "start = 1e17")
    server.change(URI, bad, 5)
    published = server.wait_for(lambda m: m.get("method") == "textDocument/publishDiagnostics"
                                and m["params"].get("version") == 5 and m["params"]["diagnostics"])
    d = published["params"]["diagnostics"][0]
    assert d["code"] == "E748" and d["range"]["start"]["line"] == pos(bad, "Revolute j1")["line"]


def test_ranges_count_utf16_units(server):
    uri = "untitled:Untitled-1"
    text = 'model A "π 🙂"\n  parameter Real m = 1;\n  Real q = /* 🙂 */ m;\n  Real r = /* 🙂 */ mm;\nend A;\n'
    server.open(uri, text, 1)
    ds = server.diagnostics(uri, 1)["diagnostics"]
    assert [d["code"] for d in ds] == ["E201"]
    # "  Real r = /* " is 14 units, the emoji 2, " */ " 4: mm starts at 20 (19 characters)
    assert ds[0]["range"] == {"start": {"line": 3, "character": 20}, "end": {"line": 3, "character": 22}}
    h = server.result("textDocument/hover", {**_doc(uri), "position": {"line": 2, "character": 20}})
    assert "parameter of model A" in h["contents"]["value"]
    assert h["range"]["start"] == {"line": 2, "character": 20}
    server.notify("textDocument/didClose", _doc(uri))


def test_formatting_replaces_the_document_with_the_printers_text(server):
    uri = "untitled:ugly"
    text = "model  A // c\n    parameter Real m=1;\nend A;\n"
    server.open(uri, text, 1)
    edits = server.result("textDocument/formatting", {**_doc(uri), "options": {"tabSize": 2, "insertSpaces": True}})
    assert len(edits) == 1 and edits[0]["newText"] == format_source(text)
    assert edits[0]["range"] == {"start": {"line": 0, "character": 0}, "end": {"line": 3, "character": 0}}


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_rapid_edits_are_analysed_once_and_start_checks_can_be_left_out():
    c = LspClient({"debounceMs": 2000, "startChecks": False})
    try:
        c.open(URI, TEXT, 1)
        for v in (2, 3, 4):
            c.change(URI, TEXT.replace("rod2.a", f"rod{v + 5}.a"), v)
        ds = c.diagnostics(URI, 4)["diagnostics"]
        assert "rod9" in ds[0]["message"]
        versions = [m["params"]["version"] for m in c.notifications
                    if m.get("method") == "textDocument/publishDiagnostics"]
        assert set(versions) == {4}
        # without the second stage, a start-state problem (E748, see above) is not reported
        c.change(URI, TEXT.replace("start = pi/2", "start = 1e17"), 5)
        assert c.diagnostics(URI, 5)["diagnostics"] == []
        time.sleep(3)
        assert [m["params"]["diagnostics"] for m in c.notifications
                if m.get("method") == "textDocument/publishDiagnostics" and m["params"]["version"] == 5] == [[]]
        assert c.internal_errors() == []
    finally:
        assert c.close() == 0


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_mech_lsp_without_pygls_says_how_to_install_it(tmp_path):
    import subprocess
    import sys

    (tmp_path / "pygls.py").write_text("raise ImportError('no pygls here')\n")
    env = {"PYTHONPATH": str(tmp_path)}
    import os

    p = subprocess.run([sys.executable, "-m", "mechdsl", "lsp"], capture_output=True, text=True,
                       env={**os.environ, **env}, timeout=60, stdin=subprocess.DEVNULL)
    assert p.returncode == 2 and "pip install 'mechdsl[lsp]'" in p.stderr


@pytest.mark.slow  # CPU budget: the cheaper tests of this file stay in the default run
def test_pygls_is_imported_only_when_mech_lsp_runs():
    import subprocess
    import sys

    for args in (["--help"], ["check", str(PATH)]):
        r = subprocess.run([sys.executable, "-X", "importtime", "-m", "mechdsl", *args], capture_output=True,
                           text=True, timeout=120)
        names = {line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time")}
        assert "mechdsl.cli" in names
        assert not {n for n in names if n.split(".")[0] in ("pygls", "lsprotocol", "cattrs")}, args
        assert "mechdsl.lsp" not in names
