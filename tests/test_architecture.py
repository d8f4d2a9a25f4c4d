"""The package's layering, read from its own import statements (issue 22).

Every ``import`` and ``from ... import`` of a mechdsl module is an edge of the import graph,
those written inside functions included.  The graph has no circle; the libraries of mechanics
(``dae``, ``impacts``) never import the simulation layer (only their package faces re-export
the layer's keyword entries, lazily); inside ``simulation``, ``dae``, ``impacts`` and
``analysis`` imports are written at module level (deferral only in the package faces, which
keep the cold start light: tests/test_coldstart.py); at most 12 modules at the top of the
package.  A test written to fail: each rule is also checked against a graph that breaks it.
"""
from __future__ import annotations

import ast
from pathlib import Path

import mechdsl

SRC = Path(mechdsl.__path__[0]).resolve().parent       # the folder holding the installed package
PACKAGE = "mechdsl"
LIBRARIES = ("mechdsl.dae", "mechdsl.impacts")        # mechanics the simulation layer uses
MODULE_LEVEL = ("mechdsl.simulation", "mechdsl.dae", "mechdsl.impacts", "mechdsl.analysis")
# the package faces' lazy re-exports of the public run entries (mechdsl.dae.simulate_dae,
# mechdsl.impacts.simulate_with_contacts): the one place a library names the layer
FACE_ENTRIES = {("mechdsl.dae", "mechdsl.simulation.shims"), ("mechdsl.impacts", "mechdsl.simulation.shims"),
                ("mechdsl.dae", "mechdsl.output.result")}


def modules(root: Path = SRC) -> dict[str, Path]:
    out = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        out[name[: -len(".__init__")] if name.endswith(".__init__") else name] = path
    return out


def _targets(module: str, node, is_package: bool, known) -> list[str]:
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        if node.level:
            parts = module.split(".")
            if not is_package:
                parts = parts[:-1]
            parts = parts[:len(parts) - (node.level - 1)]
            base = ".".join(parts + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
    out = []
    for name in names:
        while name and name not in known:          # a name inside a module: the module
            name = name.rpartition(".")[0]
        if name.split(".")[0] == PACKAGE and name:
            out.append(name)
    return out


def import_graph(mods: dict[str, Path]) -> dict[str, dict[str, bool]]:
    """module -> {imported module: True when the import is written inside a function}."""
    graph: dict[str, dict[str, bool]] = {m: {} for m in mods}
    for m, path in mods.items():
        is_package = path.name == "__init__.py"

        def visit(node, local):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    visit(child, True)
                elif isinstance(child, (ast.Import, ast.ImportFrom)):
                    for t in _targets(m, child, is_package, mods):
                        if t != m:
                            graph[m][t] = graph[m].get(t, True) and local
                elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                    continue
                else:
                    visit(child, local)

        visit(ast.parse(path.read_text()), False)
    return graph


def circles(graph: dict[str, dict[str, bool]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative); the edge
    from a module to its own parent package is left out (importing a submodule runs its
    package's __init__ anyway: that is not a dependency the module chose)."""
    edges = {a: [b for b in bs if not a.startswith(b + ".")] for a, bs in graph.items()}
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(edges[root]))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in edges:
                    continue
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(edges[w])))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def inside(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def library_imports_of_the_layer(graph) -> list[tuple[str, str]]:
    return [(a, b) for a, bs in graph.items() for b in bs
            if inside(a, LIBRARIES) and inside(b, ("mechdsl.simulation",)) and (a, b) not in FACE_ENTRIES]


def deferred_imports(graph, mods) -> list[tuple[str, str]]:
    """Imports of mechdsl modules written only inside functions, in the packages that import at
    module level, outside their package faces."""
    return [(a, b) for a, bs in graph.items() for b, local in bs.items()
            if local and inside(a, MODULE_LEVEL) and mods[a].name != "__init__.py"]


GRAPH = import_graph(modules())


def test_no_import_circle_counting_imports_inside_functions():
    assert circles(GRAPH) == []


def test_the_libraries_of_mechanics_never_import_the_simulation_layer():
    assert library_imports_of_the_layer(GRAPH) == []


def test_imports_at_module_level_inside_the_layer_and_its_libraries():
    assert deferred_imports(GRAPH, modules()) == []


def test_at_most_twelve_modules_at_the_top_of_the_package():
    top = [p.name for p in (SRC / PACKAGE).glob("*.py")]
    assert len(top) <= 12, sorted(top)


def test_the_rules_fail_on_a_graph_that_breaks_them():
    """The checks above are not vacuous: a circle, a library importing the layer and a deferred
    import are each found in a graph built to have one."""
    broken = {m: dict(bs) for m, bs in GRAPH.items()}
    broken["mechdsl.model.ir"]["mechdsl.simulation.template"] = True         # ir -> layer -> ... -> ir
    assert any("mechdsl.model.ir" in c for c in circles(broken))
    broken["mechdsl.dae.constrained_system"]["mechdsl.simulation.record"] = False
    assert ("mechdsl.dae.constrained_system", "mechdsl.simulation.record") in library_imports_of_the_layer(broken)
    assert ("mechdsl.model.ir", "mechdsl.simulation.template") not in deferred_imports(broken, modules())
    broken["mechdsl.analysis.core"]["mechdsl.eom"] = True
    assert ("mechdsl.analysis.core", "mechdsl.eom") in deferred_imports(broken, modules())
    # and the graph reads real imports: the template imports the back ends' face at module level
    assert GRAPH["mechdsl.simulation.template"]["mechdsl.simulation.backends"] is False
