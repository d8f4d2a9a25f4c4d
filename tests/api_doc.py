"""Writes docs/api.md: the Python API reference, generated from the docstrings and signatures
of everything importable from ``mechdsl`` and the public classes its functions return, so the
page cannot drift from the code: tests/test_display.py fails when the committed page differs
from what this script generates.

    PYTHONPATH=src python tests/api_doc.py            # rewrite docs/api.md
    PYTHONPATH=src python tests/api_doc.py --check    # exit 1 if it is stale
"""
from __future__ import annotations

import inspect
import os
import sys
from pathlib import Path

# the page lives in the source checkout (MECHDSL_CHECKOUT when the tests run from a copy elsewhere)
ROOT = Path(os.environ.get("MECHDSL_CHECKOUT") or Path(__file__).resolve().parents[1])
DOCS = ROOT / "docs" / "api.md"

# (import path, what it is) of the classes the top-level functions hand out
CLASSES = [
    ("mechdsl.api.Model", "what `mechdsl.load` / `mechdsl.loads` return"),
    ("mechdsl.output.result.Result", "what `Model.simulate` returns"),
    ("mechdsl.output.result.Failure", "`Result.failure` of a run that stopped early"),
    ("mechdsl.animate.Animation", "what `Result.animate` returns"),
    ("mechdsl.view.View", "what `Result.view` and `Model.view` return"),
    ("mechdsl.output.display.Equations", "what `Model.equations` returns"),
    ("mechdsl.analysis.equilibrium.Equilibrium", "what `Model.equilibria` returns (a list of them)"),
    ("mechdsl.analysis.linear_model.Linearization", "what `Model.linearize` returns"),
    ("mechdsl.analysis.modes.Modes", "what `Linearization.modes()` returns"),
    ("mechdsl.urdf.Imported", "what `mechdsl.urdf.convert` returns (`mechdsl.import_urdf` returns its text)"),
    ("mechdsl.export.ExportInfo", "what `Model.export_fmu` returns"),
]


def _obj(path: str):
    import importlib

    mod, _, name = path.rpartition(".")
    return getattr(importlib.import_module(mod), name)


def _doc(obj) -> str:
    d = (inspect.getdoc(obj) or "") if obj is not None else ""
    return d.strip()


def _sig(name: str, fn) -> str:
    try:
        s = str(inspect.signature(fn))
    except (TypeError, ValueError):
        s = "(...)"
    s = s.replace("(self, ", "(").replace("(self)", "()")
    return f"{name}{s}"


def _members(cls):
    """Public methods and properties defined by the class itself (declaration order)."""
    out = []
    for name, value in cls.__dict__.items():
        if name.startswith("_"):
            continue
        if isinstance(value, property):
            out.append((name, "property", value.fget))
        elif isinstance(value, (staticmethod, classmethod)):
            out.append((name, "method", value.__func__))
        elif inspect.isfunction(value):
            out.append((name, "method", value))
    return out


def _fields(cls) -> list[str]:
    import dataclasses

    if not dataclasses.is_dataclass(cls):
        return []
    return [f.name for f in dataclasses.fields(cls) if not f.name.startswith("_")]


def generate() -> str:
    import mechdsl

    lines = ["# Python API reference", "",
             "Generated from the docstrings by `tests/api_doc.py` (`PYTHONPATH=src python tests/api_doc.py`);",
             "a test fails when this page is stale.  Guides: [tutorial.md](tutorial.md),",
             "[simulate.md](simulate.md), [analysis.md](analysis.md), [animate.md](animate.md), and the",
             "notebook [notebooks/tour.ipynb](notebooks/tour.ipynb).", "",
             "## `mechdsl`", "", _doc(mechdsl), ""]
    for name in mechdsl.__all__:
        obj = getattr(mechdsl, name)
        if name == "__version__":
            lines += [f"### `mechdsl.__version__`", "", "The version string.", ""]
        elif inspect.isclass(obj):
            lines += [f"### class `mechdsl.{name}`", "", _doc(obj) or "(no docstring)", ""]
        else:       # the lazy wrappers in mechdsl/__init__.py carry mechdsl.api's docstrings
            import mechdsl.api

            doc = _doc(obj) or _doc(getattr(mechdsl.api, name, None)) or "(no docstring)"
            lines += [f"### `mechdsl.{_sig(name, obj)}`", "", doc, ""]
    import mechdsl.examples

    lines += ["## `mechdsl.examples`", "", _doc(mechdsl.examples), ""]
    for name in mechdsl.examples.__all__:
        lines += [f"### `mechdsl.examples.{_sig(name, getattr(mechdsl.examples, name))}`", "",
                  _doc(getattr(mechdsl.examples, name)) or "(no docstring)", ""]
    lines += ["## Classes returned by the API", ""]
    for path, what in CLASSES:
        cls = _obj(path)
        lines += [f"### class `{path}`", "", f"*{what}.*", "", _doc(cls) or "(no docstring)", ""]
        fields = _fields(cls)
        if fields:
            lines += ["Fields: " + ", ".join(f"`{f}`" for f in fields) + ".", ""]
        for name, kind, fn in _members(cls):
            head = f"`{name}`" if kind == "property" else f"`{_sig(name, fn)}`"
            doc = _doc(fn)
            lines.append(f"- {head}" + (" (property)" if kind == "property" else "")
                         + (": " + doc.replace("\n", " ") if doc else ""))
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str]) -> int:
    text = generate()
    if "--check" in argv:
        if not DOCS.is_file() or DOCS.read_text(encoding="utf-8") != text:
            print(f"{DOCS} is stale: run PYTHONPATH=src python tests/api_doc.py", file=sys.stderr)
            return 1
        return 0
    DOCS.write_text(text, encoding="utf-8")
    print(f"wrote {DOCS}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
