"""Library code says nothing by itself (issue 27): no print() and no writes to sys.stdout or
sys.stderr outside the command line (mechdsl/cli.py, mechdsl/commands/); its messages go to the
"mechdsl" logger, which shows nothing unless the application configures logging.  The modules
are read from the installed package (mechdsl.__file__), so this holds for the wheel too."""
from __future__ import annotations

import ast
import logging
from pathlib import Path

import mechdsl

PACKAGE = Path(mechdsl.__file__).resolve().parent
CLI = {"cli.py", "__main__.py"}
# functions whose purpose is printing, on request, to the file they are given
ON_REQUEST = {("impacts/table.py", "print_events")}


def _candidates():
    """(path relative to the package, text) of every library module (the CLI's left out)."""
    for p in sorted(PACKAGE.rglob("*.py")):
        rel = p.relative_to(PACKAGE).as_posix()
        if not (rel in CLI or rel.startswith("commands/")):
            yield rel, p.read_text(encoding="utf-8")


def _library_modules():
    for rel, text in _candidates():
        # _speaking_calls finds only the name print and the attributes sys.stdout / sys.stderr:
        # a module whose text has none of these words cannot have one (and is not parsed)
        if any(word in text for word in ("print", "stdout", "stderr")):
            yield rel, ast.parse(text)


def _is_std_stream(node) -> bool:
    return (isinstance(node, ast.Attribute) and node.attr in ("stdout", "stderr")
            and isinstance(node.value, ast.Name) and node.value.id == "sys")


def _speaking_calls(tree):
    """(enclosing function, line) of every print() call and write to sys.stdout/sys.stderr."""
    found = []

    class Scan(ast.NodeVisitor):
        stack = ["<module>"]

        def visit_FunctionDef(self, node):
            self.stack.append(node.name)
            self.generic_visit(node)
            self.stack.pop()

        visit_AsyncFunctionDef = visit_FunctionDef

        def visit_Call(self, node):
            f = node.func
            if (isinstance(f, ast.Name) and f.id == "print") or (
                    isinstance(f, ast.Attribute) and f.attr in ("write", "writelines") and (
                        _is_std_stream(f.value) or (isinstance(f.value, ast.BoolOp)
                                                    and any(_is_std_stream(v) for v in f.value.values)))):
                found.append((self.stack[-1], node.lineno))
            self.generic_visit(node)

    Scan().visit(tree)
    return found


def test_the_scan_finds_a_print():
    tree = ast.parse("def f():\n    print('x')\n    sys.stderr.write('y')\n    (out or sys.stdout).write('z')\n")
    assert sorted(line for _, line in _speaking_calls(tree)) == [2, 3, 4]


def test_the_scan_reads_every_package():
    """Every subpackage of the installed package is scanned, the recently added ones by name."""
    scanned = {rel.split("/")[0] for rel, _ in _candidates() if "/" in rel}
    packages = {p.parent.relative_to(PACKAGE).parts[0] for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE}
    assert scanned == packages - {"commands"}
    assert {"urdf", "export", "view", "lsp", "sweep", "simulation", "animate"} <= scanned


def test_no_prints_in_library_code():
    found = []
    for rel, tree in _library_modules():
        for fn, line in _speaking_calls(tree):
            if (rel, fn) not in ON_REQUEST:
                found.append(f"{rel}:{line} in {fn}")
    assert not found, "library code prints (use logging, or return the text): " + ", ".join(sorted(set(found)))


def test_the_library_logger_is_silent_by_default():
    logger = logging.getLogger("mechdsl")
    assert any(isinstance(h, logging.NullHandler) for h in logger.handlers)
