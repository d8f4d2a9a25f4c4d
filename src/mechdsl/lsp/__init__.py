"""The language server for .mech files (``mech lsp``): diagnostics as you type, hover, go to
definition, completion, document symbols and formatting.  Needs the ``lsp`` extra (pygls);
nothing here is imported unless ``mech lsp`` runs.  See docs/editors.md and
docs/internals/lsp.md."""
