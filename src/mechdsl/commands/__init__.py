"""CLI subcommands: one module per command, each with ``add_parser(sub)`` and ``run(args)``.

``COMMANDS`` lists the module names in the order ``mech --help`` shows them.  A module
that fails to import (an optional part missing) is left out of the CLI with a note.
"""
COMMANDS = ["check", "compile", "simulate", "sweep", "equations", "equilibrium", "linearize", "fit", "animate", "view",
            "export", "bench", "import", "lsp", "examples", "completion"]

# a command whose name is not a module name (``import`` is a Python keyword)
MODULES = {"import": "import_urdf"}


def module_of(command: str) -> str:
    return MODULES.get(command, command)
