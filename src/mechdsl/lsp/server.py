"""``mech lsp``: the language server (pygls), over stdin/stdout.

Documents are synchronised whole (TextDocumentSyncKind.Full: the files are small, and an
incremental edit would be applied by pygls at lines split as Python splits them, where a form
feed or U+2028 is a line break that the client does not count).

Diagnostics: an edit (re)starts a timer (``debounceMs``, default 300 ms, an initialization
option); when it fires, analysis.analyse runs in a worker thread and its diagnostics are
published; then analysis.start_problems (the equations of motion and the start-state checks) runs
in a second worker and, if the text is still the same, publishes them with the first stage's
(unless the initialization option ``startChecks`` is false).
Each worker runs only the newest job of a document (an older one not started yet is dropped),
so a slow derivation never delays the next edit's syntax and name errors.  Both are daemon
threads: nothing keeps the process alive after ``exit``.

Requests (hover, definition, completion, document symbols, formatting) are answered on the
server's thread from the newest analysis; when the text changed since, it is parsed again at once
(parse_partial + SymbolIndex, milliseconds) so that positions are the text's own.

No request, notification or worker job lets an exception escape: an internal error is logged to
the client (window/logMessage, "mechdsl internal error ...") and the answer is empty.
"""
from __future__ import annotations

import asyncio
import threading
import traceback
from dataclasses import dataclass, field
from urllib.parse import unquote, urlparse

from lsprotocol import types as T
from pygls.lsp.server import LanguageServer

from .. import __version__
from ..diagnostics import Diagnostic, MechError
from ..frontend import limits
from .analysis import Analysis, analyse, start_problems, unique
from .positions import Lines

DEBOUNCE = 0.3          # seconds of quiet after an edit before the analysis runs
SEVERITY = {"error": T.DiagnosticSeverity.Error, "warning": T.DiagnosticSeverity.Warning,
            "note": T.DiagnosticSeverity.Information}


class LatestWorker:
    """A daemon thread running submitted jobs one at a time; a job replaces a waiting job of the
    same key (the same document), so only the newest text is analysed."""

    def __init__(self, name: str, on_error):
        self._cv = threading.Condition()
        self._jobs: dict[str, object] = {}
        self._on_error = on_error
        threading.Thread(target=self._loop, name=f"mechdsl-lsp-{name}", daemon=True).start()

    def submit(self, key: str, job) -> None:
        with self._cv:
            self._jobs.pop(key, None)
            self._jobs[key] = job
            self._cv.notify()

    def _loop(self) -> None:
        while True:
            with self._cv:
                while not self._jobs:
                    self._cv.wait()
                key = next(iter(self._jobs))
                job = self._jobs.pop(key)
            try:
                job()
            except BaseException as e:     # noqa: BLE001 - reported to the client, the worker lives on
                self._on_error("analysis", e)


@dataclass
class Document:
    uri: str
    filename: str
    version: int = 0
    text: str = ""
    analysis: Analysis | None = None     # the newest finished analysis (perhaps of an older text)
    quick: Analysis | None = None        # the current text parsed for a request (no semantics)
    timer: object = None
    published: list = field(default_factory=list)


def filename_of(uri: str) -> str:
    """A file: URI's path (what diagnostics spans are named by), else the URI itself."""
    u = urlparse(uri)
    return unquote(u.path) if u.scheme == "file" else uri


class MechLanguageServer:
    def __init__(self, debounce: float = DEBOUNCE):
        self.ls = LanguageServer("mechdsl", __version__, text_document_sync_kind=T.TextDocumentSyncKind.Full)
        self.debounce = debounce
        self.start_checks = True                # stage 2 (initialization option startChecks)
        self.docs: dict[str, Document] = {}
        self.limits = limits.current()          # `mech lsp --limit ...` holds in the workers too
        self.loop: asyncio.AbstractEventLoop | None = None
        self.analysis_worker = LatestWorker("analysis", self.internal_error)
        self.start_worker = LatestWorker("start", self.internal_error)
        self._register()

    # ------------------------------------------------------------------ plumbing
    def internal_error(self, where: str, e: BaseException) -> None:
        text = "".join(traceback.format_exception(type(e), e, e.__traceback__))
        msg = T.LogMessageParams(type=T.MessageType.Error, message=f"mechdsl internal error in {where}: {text}")
        try:
            if self.loop is not None and threading.current_thread() is not threading.main_thread():
                self.loop.call_soon_threadsafe(self.ls.window_log_message, msg)
            else:
                self.ls.window_log_message(msg)
        except Exception:                          # noqa: BLE001 - the connection is gone
            pass

    def guarded(self, where: str, fn, default=None):
        """fn() with every exception reported as an internal error (the answer: default)."""
        try:
            return fn()
        except Exception as e:                     # noqa: BLE001
            self.internal_error(where, e)
            return default

    def lines(self, text: str) -> Lines:
        try:
            enc = self.ls.workspace.position_encoding
        except RuntimeError:                        # not initialized yet
            enc = "utf-16"
        return Lines(text, str(getattr(enc, "value", enc) or "utf-16"))

    # ------------------------------------------------------------------ documents
    def opened(self, uri: str, version: int | None) -> None:
        doc = self.docs.get(uri) or Document(uri, filename_of(uri))
        self.docs[uri] = doc
        doc.text = self.ls.workspace.get_text_document(uri).source
        doc.version = version if version is not None else doc.version + 1
        doc.quick = None
        self.schedule(doc)

    def schedule(self, doc: Document) -> None:
        loop = self.loop = self.loop or asyncio.get_running_loop()
        if doc.timer is not None:
            doc.timer.cancel()
        doc.timer = loop.call_later(self.debounce, self.submit, doc.uri, doc.version)

    def submit(self, uri: str, version: int) -> None:
        doc = self.docs.get(uri)
        if doc is None or doc.version != version:
            return
        text, filename, lim = doc.text, doc.filename, self.limits

        def stage1():
            with limits.override(lim):
                a = analyse(text, filename)
            self.loop.call_soon_threadsafe(self.guarded, "analysis", lambda: self.analysed(uri, version, a))

        self.analysis_worker.submit(uri, stage1)

    def analysed(self, uri: str, version: int, a: Analysis) -> None:
        doc = self.docs.get(uri)
        if doc is None or doc.version != version:
            return
        doc.analysis = a
        self.publish(doc, a.diagnostics)
        if not a.loaded or not self.start_checks:
            return
        lim = self.limits

        def stage2():
            with limits.override(lim):
                extra = start_problems(a, still_wanted=lambda: doc.version == version and uri in self.docs)
            if extra:
                self.loop.call_soon_threadsafe(self.guarded, "start checks",
                                               lambda: self.checked(uri, version, a, extra))

        self.start_worker.submit(uri, stage2)

    def checked(self, uri: str, version: int, a: Analysis, extra: list[Diagnostic]) -> None:
        doc = self.docs.get(uri)
        if doc is not None and doc.version == version:
            self.publish(doc, unique(a.diagnostics + extra))

    def publish(self, doc: Document, diags: list[Diagnostic]) -> None:
        lines = self.lines(doc.text)
        items = []
        for d in diags:
            (l0, c0), (l1, c1) = lines.range(d.span)
            items.append(T.Diagnostic(
                range=T.Range(start=T.Position(line=l0, character=c0), end=T.Position(line=l1, character=c1)),
                message=d.message + (f"\nhelp: {d.help}" if d.help else ""),
                severity=SEVERITY.get(d.severity, T.DiagnosticSeverity.Error), code=d.code, source="mech"))
        doc.published = items
        self.ls.text_document_publish_diagnostics(
            T.PublishDiagnosticsParams(uri=doc.uri, diagnostics=items, version=doc.version))

    def current(self, uri: str) -> tuple[Document, Analysis] | None:
        """The document and an analysis whose index belongs to the current text (a quick parse
        when the newest analysis is of an older text; its values are the older analysis's)."""
        doc = self.docs.get(uri)
        if doc is None:
            return None
        a = doc.analysis
        if a is not None and a.text == doc.text:
            return doc, a
        if doc.quick is None or doc.quick.text != doc.text:
            from ..frontend.parser import parse_partial
            from ..semantic.symbols import SymbolIndex

            with limits.override(self.limits):
                try:
                    tree, _ = parse_partial(doc.text, doc.filename)
                except MechError:
                    tree = None
            q = Analysis(doc.text, doc.filename, tree, SymbolIndex(tree) if tree is not None else None)
            if a is not None:
                q.flat, q.scene_models = a.flat, a.scene_models
            doc.quick = q
        return doc, doc.quick

    # ------------------------------------------------------------------ features
    def _register(self) -> None:
        ls = self.ls

        @ls.feature(T.INITIALIZE)
        def initialize(params: T.InitializeParams):
            self.loop = asyncio.get_running_loop()
            opts = params.initialization_options
            if isinstance(opts, dict) and isinstance(opts.get("debounceMs"), (int, float)):
                self.debounce = max(0.0, float(opts["debounceMs"]) / 1000.0)
            if isinstance(opts, dict) and isinstance(opts.get("startChecks"), bool):
                self.start_checks = opts["startChecks"]

        @ls.feature(T.TEXT_DOCUMENT_DID_OPEN)
        def did_open(params: T.DidOpenTextDocumentParams):
            self.guarded("didOpen", lambda: self.opened(params.text_document.uri, params.text_document.version))

        @ls.feature(T.TEXT_DOCUMENT_DID_CHANGE)
        def did_change(params: T.DidChangeTextDocumentParams):
            self.guarded("didChange", lambda: self.opened(params.text_document.uri, params.text_document.version))

        @ls.feature(T.TEXT_DOCUMENT_DID_CLOSE)
        def did_close(params: T.DidCloseTextDocumentParams):
            doc = self.docs.pop(params.text_document.uri, None)
            if doc is not None and doc.timer is not None:
                doc.timer.cancel()
            ls.text_document_publish_diagnostics(T.PublishDiagnosticsParams(uri=params.text_document.uri,
                                                                            diagnostics=[]))

        @ls.feature(T.TEXT_DOCUMENT_HOVER)
        def hover(params: T.HoverParams):
            return self.guarded("hover", lambda: self.hover(params))

        @ls.feature(T.TEXT_DOCUMENT_DEFINITION)
        def definition(params: T.DefinitionParams):
            return self.guarded("definition", lambda: self.definition(params))

        @ls.feature(T.TEXT_DOCUMENT_COMPLETION, T.CompletionOptions(trigger_characters=["."]))
        def completion(params: T.CompletionParams):
            return self.guarded("completion", lambda: self.completion(params))

        @ls.feature(T.TEXT_DOCUMENT_DOCUMENT_SYMBOL)
        def document_symbol(params: T.DocumentSymbolParams):
            return self.guarded("documentSymbol", lambda: self.document_symbols(params), [])

        @ls.feature(T.TEXT_DOCUMENT_FORMATTING)
        def formatting(params: T.DocumentFormattingParams):
            return self.guarded("formatting", lambda: self.formatting(params))

    def _at(self, params):
        got = self.current(params.text_document.uri)
        if got is None:
            return None
        doc, a = got
        lines = self.lines(doc.text)
        line, col = lines.from_lsp(params.position.line, params.position.character)
        return doc, a, lines, line, col

    def hover(self, params: T.HoverParams) -> T.Hover | None:
        from .hover import hover_text
        from .navigate import lsp_range

        got = self._at(params)
        if got is None or got[1].index is None:
            return None
        doc, a, lines, line, col = got
        occ = a.index.at(line, col)
        text = hover_text(a, occ) if occ is not None else None
        if not text:
            return None
        return T.Hover(contents=T.MarkupContent(kind=T.MarkupKind.Markdown, value=text),
                       range=lsp_range(lines, occ.span))

    def definition(self, params: T.DefinitionParams) -> T.Location | None:
        from .navigate import definition

        got = self._at(params)
        if got is None or got[1].index is None:
            return None
        doc, a, lines, line, col = got
        return definition(a.index, lines, doc.uri, line, col)

    def completion(self, params: T.CompletionParams) -> T.CompletionList | None:
        from .complete import completions
        from .context import context_at

        got = self._at(params)
        if got is None:
            return None
        doc, a, lines, line, col = got
        index = a.index or (doc.analysis.index if doc.analysis is not None else None)
        prefix = "\n".join(lines.lines[:line - 1] + [lines.lines[line - 1][:col - 1]]) if lines.lines else ""
        return T.CompletionList(is_incomplete=False, items=completions(index, context_at(prefix)))

    def document_symbols(self, params: T.DocumentSymbolParams) -> list[T.DocumentSymbol]:
        from .navigate import document_symbols

        got = self.current(params.text_document.uri)
        if got is None or got[1].index is None:
            return []
        doc, a = got
        return document_symbols(a.index, self.lines(doc.text))

    def formatting(self, params: T.DocumentFormattingParams) -> list[T.TextEdit] | None:
        from ..frontend.format import FormatError, format_source

        doc = self.docs.get(params.text_document.uri)
        if doc is None:
            return None
        try:
            with limits.override(self.limits):
                new = format_source(doc.text, doc.filename)
        except MechError as e:
            d = e.diagnostics[0]
            where = f" (line {d.span.line}: {d.code} {d.message})" if d.span.line > 0 else f" ({d.code} {d.message})"
            self.ls.window_show_message(T.ShowMessageParams(
                type=T.MessageType.Warning, message=f"mech: not formatted: the file has errors{where}"))
            return None
        except FormatError as e:
            self.internal_error("formatting", e)
            return None
        if new == doc.text:
            return []
        lines = self.lines(doc.text)
        end = lines.to_lsp(len(lines.lines), len(lines.lines[-1]) + 1)
        return [T.TextEdit(range=T.Range(start=T.Position(line=0, character=0),
                                         end=T.Position(line=end[0], character=end[1])), new_text=new)]


def serve(stdin=None, stdout=None) -> None:
    """Run the server on binary streams (default: this process's stdin and stdout)."""
    server = MechLanguageServer()
    server.ls.start_io(stdin, stdout)


__all__ = ["MechLanguageServer", "serve", "filename_of", "LatestWorker"]
