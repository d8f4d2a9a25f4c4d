"""URDF in (issue 26): ``import_urdf(path) -> str``, the .mech text of a robot description.

    import mechdsl
    text = mechdsl.import_urdf("ur5.urdf")          # or: mech import ur5.urdf -o ur5.mech
    m = mechdsl.loads(text)

Phases (each its own module): read the XML with positions (xmltree), the URDF's elements as
data (robot), the kinematic tree with fixed links merged (tree), drawn shapes from the visuals
and meshes (shapes, meshes), the text (writer, names), and a check of the text by mechdsl's own
front end, whose findings about the inertia data are located back in the URDF (this module).
Every problem names the URDF element, ``file:line:col``; see docs/import.md.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..diagnostics import Diagnostic, DiagnosticBag, MechError, remember_source
from . import robot as R
from . import tree as T
from .shapes import body_shapes, report_missing
from .writer import write
from .xmltree import read_bytes, span


@dataclass
class Imported:
    """What an import gives: the text and how the URDF's names map to the model's."""

    text: str
    model: str                                   # the model's name in the text
    bodies: dict[str, str]                       # URDF link (that has a body of its own) -> body
    joints: dict[str, str]                       # URDF movable joint -> joint
    coordinates: dict[str, tuple[str, ...]]      # URDF joint -> its coordinates ("" : the floating root)
    diagnostics: list[Diagnostic] = field(default_factory=list)   # warnings, located in the URDF
    left_out: list[str] = field(default_factory=list)             # joints left out (loops)
    mimics: dict[str, tuple[str, float, float]] = field(default_factory=dict)  # URDF joint -> (joint it
                                                                  # follows, multiplier, offset)
    root: str = ""
    measured: list[str] = field(default_factory=list)             # links whose inertia is taken as measured
    kinds: dict[str, str] = field(default_factory=dict)           # URDF movable joint -> its URDF type
    shapes: dict[str, tuple[str, int]] = field(default_factory=dict)  # Shape -> (URDF link, index of its <visual>)


def import_urdf(path: str | os.PathLike, *, floating: bool = False, measured_inertia: bool = False,
                package_dirs: dict[str, str] | None = None, skip_missing_meshes: bool = False) -> str:
    """The .mech text of the robot in the URDF file ``path`` (see :func:`convert`)."""
    return convert(path, floating=floating, measured_inertia=measured_inertia, package_dirs=package_dirs,
                   skip_missing_meshes=skip_missing_meshes).text


def convert(path: str | os.PathLike, *, floating: bool = False, measured_inertia: bool = False,
            package_dirs: dict[str, str] | None = None, mech_name: str | None = None,
            skip_missing_meshes: bool = False) -> Imported:
    """Import a URDF file.  ``floating``: the root link gets a Free joint (quaternion) instead of
    being fixed to the world; ``measured_inertia``: inertias that break the triangle inequality
    beyond rounding are accepted as measured data (``measured_inertia = true`` on those bodies);
    ``package_dirs``: folders of ROS packages named in ``package://`` mesh paths;
    ``skip_missing_meshes``: a mesh file that is absent is the warning W021 and is not drawn,
    instead of the error E028.  Problems are MechErrors located in the URDF (codes E020-E028,
    E508, E509); warnings are in ``Imported.diagnostics``."""
    from .. import __version__

    name = str(path)
    data = read_bytes(name)
    remember_source(name, data.decode("utf-8", errors="replace"))
    robot = R.read_robot(data, name)
    diags = DiagnosticBag()
    diags.extend(robot.warnings)
    st = T.build(robot, diags)
    diags.raise_if_errors()
    assert st is not None
    if not st.movable and not floating:
        raise MechError(Diagnostic("E027", f"robot '{robot.name}' has no movable joint: nothing in it moves",
                                   span(name, robot.el), "import it with --floating (mech import) or floating=True "
                                                         "to give its root link a Free joint"))
    cache: dict = {}
    missing: list = []
    shapes = {g.link.name: body_shapes(g, name, dict(package_dirs or {}), diags, cache, missing) for g in st.groups}
    report_missing(missing, name, diags, skip_missing_meshes)
    diags.raise_if_errors()
    mech_name = mech_name or str(Path(name).with_suffix(".mech").name)
    measured: dict[str, str] = {}
    for attempt in range(2):
        w = write(robot, st, shapes, floating=floating, measured=measured, version=__version__)
        problems = _check(w.text, w.model, mech_name, w, robot, st, measured_inertia)
        retry = {link: why for link, why in problems.get("measured", {}).items()}
        if retry and measured_inertia and attempt == 0:
            measured = retry
            continue
        diags.extend(problems["diagnostics"])
        break
    diags.raise_if_errors()
    mimics = {j.name: j.mimic for j in st.movable if j.mimic is not None}
    return Imported(w.text, w.model, w.bodies, w.joints, w.coordinates, diags.warnings,
                    [j.name for j in st.left_out], mimics, st.root.name, sorted(measured),
                    {j.name: j.type for j in st.movable}, w.shapes)


def _check(text: str, model: str, mech_name: str, w, robot: R.Robot, st: T.Structure,
           measured_ok: bool) -> dict:
    """Analyze the text with mechdsl's front end; its findings about bodies and joints are
    located at the URDF elements they came from."""
    from ..frontend.parser import parse
    from ..semantic import analyze

    out: dict = {"diagnostics": [], "measured": {}}
    try:
        program = analyze(parse(text, mech_name))
        program.model(model)
        found = list(getattr(program, "last_warnings", []))
    except MechError as e:
        found = e.diagnostics
    for d in found:
        where = _origin(w, d)
        if where is None:                       # not about a link or joint: the text itself (a bug)
            remember_source(mech_name, text)
            out["diagnostics"].append(d)
            continue
        kind, urdf_name = where
        if kind == "link":
            link = robot.links[urdf_name]
            el = link.inertial.el if link.inertial is not None else link.el
            group = next(g for g in st.groups if g.link.name == urdf_name)
            merged = [mb.link.name for mb in group.members[1:] if mb.link.inertial is not None]
            what = f"link '{urdf_name}'" + (f" (with {', '.join(repr(n) for n in merged)} merged into it)" if merged else "")
        else:
            j = next(k for k in robot.joints if k.name == urdf_name)
            el, what = j.el, f"joint '{urdf_name}'"
        help = d.help
        if d.code == "E509" and "triangle inequality" in d.message:
            out["measured"][urdf_name] = _excess_note(d.message)
            help = ("each principal moment is at most the sum of the other two for any mass distribution; "
                    "rounding is accepted up to 1e-6 of I3. For measured data you stand by, import with "
                    "--measured-inertia (mech import) or measured_inertia=True (import_urdf)")
        out["diagnostics"].append(dataclasses.replace(d, message=f"{what}: {d.message}", span=span(robot.file, el),
                                                      help=help))
    if measured_ok and out["measured"]:
        out["diagnostics"] = [d for d in out["diagnostics"] if d.severity != "error" or d.code != "E509"
                              or "triangle inequality" not in d.message]
    return out


def _origin(w, d: Diagnostic) -> tuple[str, str] | None:
    line = d.span.line
    best = None
    for ln, where in sorted(w.lines.items()):
        if ln <= line:
            best = where
        else:
            break
    return best if line > 0 else None


def _excess_note(message: str) -> str:
    i = message.find("I3 - (I1 + I2)")
    return message[i:].rstrip(")") if i >= 0 else "the triangle inequality is broken"


__all__ = ["import_urdf", "convert", "Imported"]
