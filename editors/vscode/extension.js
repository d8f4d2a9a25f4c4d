// The VS Code client of the mechdsl language server: starts `mech lsp` (settings mech.server.path
// and mech.server.args) for .mech files and hands it the editor's documents.
"use strict";

const vscode = require("vscode");
const { LanguageClient } = require("vscode-languageclient/node");

let client;

function activate(context) {
  const config = vscode.workspace.getConfiguration("mech");
  const serverOptions = {
    command: config.get("server.path", "mech"),
    args: config.get("server.args", ["lsp"]),
  };
  const clientOptions = {
    documentSelector: [
      { scheme: "file", language: "mech" },
      { scheme: "untitled", language: "mech" },
    ],
    initializationOptions: {
      debounceMs: config.get("diagnostics.debounceMs", 300),
      startChecks: config.get("diagnostics.startChecks", true),
    },
  };
  client = new LanguageClient("mech", "mechdsl language server", serverOptions, clientOptions);
  client.start().catch((err) => {
    vscode.window.showErrorMessage(
      `mechdsl: cannot start "${serverOptions.command} ${serverOptions.args.join(" ")}" (${err.message || err}). ` +
        "Install the server with pip install 'mechdsl[lsp]', or set mech.server.path to its mech command."
    );
  });
  context.subscriptions.push({ dispose: () => (client ? client.stop() : undefined) });
}

function deactivate() {
  return client ? client.stop() : undefined;
}

module.exports = { activate, deactivate };
