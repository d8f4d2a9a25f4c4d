"""The language server never crashes on a half-typed file: truncations of the shipped models (every
prefix at a stride) and the broken-input corpus go through didChange, each followed by every
request (hover, definition, completion, documentSymbol, formatting) at several positions; every
answer must be a result (no JSON-RPC error), every version must be analysed (its diagnostics
published), no internal error may be logged, and the process must stay alive.  A fast subset runs
by default, the full sweep is marked slow."""
from __future__ import annotations

import pytest

from conftest import MODELS, model_files
from lsp_client import LspClient, lsp_position
from test_corpus import CORPUS

URI = "file:///fuzz/half_typed.mech"
OPTIONS = {"tabSize": 2, "insertSpaces": True}


def truncations(path, stride: int) -> list[str]:
    text = path.read_text()
    return [text[:n] for n in range(0, len(text) + 1, stride)] + [text]


def corpus_texts(every: int = 1) -> list[str]:
    files = sorted(CORPUS.glob("*.mech"))[::every]
    return [p.read_bytes().decode("utf-8", "replace") for p in files]


def sweep(texts: list[str]) -> int:
    c = LspClient({"debounceMs": 0})
    try:
        c.open(URI, "", 1)
        c.diagnostics(URI, 1)
        for k, text in enumerate(texts):
            v = k + 2
            c.change(URI, text, v)
            doc = {"textDocument": {"uri": URI}}
            for i in sorted({len(text), len(text) // 2, len(text) // 3, max(0, len(text) - 7)}):
                at = {**doc, "position": lsp_position(text, i)}
                for method in ("textDocument/hover", "textDocument/definition", "textDocument/completion"):
                    answer = c.request(method, at)
                    assert "error" not in answer, (method, text[-200:], answer)
            for method, params in (("textDocument/documentSymbol", doc),
                                   ("textDocument/formatting", {**doc, "options": OPTIONS})):
                answer = c.request(method, params)
                assert "error" not in answer, (method, text[-200:], answer)
            c.diagnostics(URI, v)
            assert c.internal_errors() == [], text[-300:]
        assert c.alive()
        return len(texts)
    finally:
        assert c.close() == 0


def test_truncations_and_corpus_fast_subset():
    # about 24 texts (a prefix every 503 characters of three models, every 40th corpus file):
    # every text costs the server 17 requests; the full sweeps are the slow tests below
    texts = []
    for name in ("pendulum.mech", "coupled_pendulums.mech", "nfourbar.mech"):
        texts += truncations(MODELS / name, 503)
    texts += corpus_texts(every=40)
    assert sweep(texts) > 20


@pytest.mark.slow
@pytest.mark.parametrize("path", model_files(), ids=lambda p: p.name)
def test_every_truncation_of_every_model(path):
    assert sweep(truncations(path, 11)) > 10


@pytest.mark.slow
def test_the_whole_corpus():
    assert sweep(corpus_texts()) == len(list(CORPUS.glob("*.mech")))
