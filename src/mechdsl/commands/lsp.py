"""``mech lsp``: the language server, speaking LSP over stdin/stdout (mechdsl.lsp)."""
from __future__ import annotations

import os
import sys

from ..diagnostics import UsageError


def add_parser(sub):
    p = sub.add_parser("lsp", help="run the language server for editors (LSP over stdin/stdout)",
                       description="Run the .mech language server: diagnostics, hover, go to definition, "
                                   "completion, document symbols and formatting, for any editor with an LSP "
                                   "client (docs/editors.md). Needs the lsp extra: pip install 'mechdsl[lsp]'.")
    p.add_argument("--stdio", action="store_true", help="use stdin/stdout (the default and only transport)")
    return p


def run(args) -> int:
    if args.out.json:
        # stdout carries the protocol's messages, so it cannot also hold a JSON document; -q and -v
        # apply as everywhere (mechdsl's log messages on stderr, which editors show in their log)
        raise UsageError("mech lsp speaks the Language Server Protocol on stdout: --json does not apply "
                         "(for diagnostics as JSON use mech check --json FILE)")
    try:
        import pygls.lsp.server  # noqa: F401  (pygls 2.0 and newer)
    except ImportError:
        raise UsageError("mech lsp needs pygls 2.0 or newer: pip install 'mechdsl[lsp]'") from None
    from ..lsp.server import serve

    # the protocol owns stdout: anything else written there (a print, a C library's message)
    # would break it, so file descriptor 1 becomes stderr and the protocol gets a copy of the original
    sys.stdout.flush()
    protocol_out = os.fdopen(os.dup(1), "wb", buffering=0)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    serve(sys.stdin.buffer, protocol_out)
    return 0
