"""The drawn shapes of an imported body, from the <visual> elements of its links.

Every visual becomes one ``Shape`` component on its body (docs/language.md), placed where the
URDF puts it: the visual's ``<origin xyz rpy>`` in its link's frame, composed with the link's
placement in the body when the link is merged into another by a fixed joint.  Boxes, cylinders
(axis along the visual's z, as in URDF) and spheres are kept as they are; a mesh becomes its
bounding box in the mesh's own axes, scaled, its centre the centre of that box (so a mesh whose
origin is at one end is drawn where it is).

A mesh file that is absent (no such file, or its ROS package not found) is the located error
E028 naming the <mesh> element, said once per missing package; with ``skip_missing_meshes``
it is the warning W021 and the visual is not drawn (the dynamics do not need it).  A mesh file
that is there but cannot be read (an unknown format, a damaged file) is W021 either way.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..diagnostics import DiagnosticBag
from . import meshes
from .robot import Visual
from .tree import Group
from .xmltree import Element, span


@dataclass
class Placed:
    """One drawn shape of a body, in the body's (the group link's) frame."""

    kind: str                     # box | cylinder | sphere
    size: tuple[float, ...]       # box (lx, ly, lz), cylinder (R, L), sphere (R,)
    p: np.ndarray                 # its centre
    R: np.ndarray                 # its axes (columns) in body axes; a cylinder's axis is the third
    rpy: np.ndarray | None        # the URDF's own rpy when R is exactly the visual's (no composition)
    link: str                     # the URDF link of the visual
    index: int                    # which <visual> of that link (0, 1, ...), Pinocchio's geometry suffix
    verbatim: bool = False        # size and p are the URDF's numbers as written (not computed)


@dataclass
class Missing:
    """A mesh file that is not there."""

    el: Element
    filename: str
    why: str


def body_shapes(g: Group, file: str, package_dirs: dict[str, str], diags: DiagnosticBag, cache: dict,
                missing: list[Missing]) -> list[Placed]:
    """The shapes of group ``g``, in the order of its links and their visuals.  Meshes that are
    absent are appended to ``missing`` (reported by :func:`report_missing`); meshes that cannot
    be read are the warning W021 in ``diags``."""
    out: list[Placed] = []
    for mb in g.members:
        own = mb is g.members[0]                  # the group's own link: the URDF's placement as it is
        for k, v in enumerate(mb.link.visuals):
            R = v.origin.R if own else mb.R @ v.origin.R
            p = v.origin.p if own else mb.p + mb.R @ v.origin.p
            rpy = v.origin.rpy if own else None
            if v.kind in ("box", "cylinder", "sphere"):
                out.append(Placed(v.kind, tuple(float(x) for x in v.size), np.array(p, float), R, rpy,
                                  mb.link.name, k, own))
                continue
            box = _mesh_box(v, file, package_dirs, diags, cache, missing)
            if box is None:
                continue
            lo, hi = box
            size = hi - lo
            if not np.any(size > 0):
                continue
            out.append(Placed("box", tuple(float(x) for x in size), p + R @ ((lo + hi) / 2), R, rpy,
                              mb.link.name, k))
    return out


def _mesh_box(v: Visual, file, package_dirs, diags, cache, missing) -> tuple[np.ndarray, np.ndarray] | None:
    """The (min, max) corners of a mesh in its own axes, scaled; None when not drawn."""
    key = (v.filename, str(Path(file).parent))
    if key not in cache:
        path, why = meshes.resolve(v.filename, Path(file).parent, package_dirs)
        cache[key] = ("absent", why) if path is None else meshes.bounding_box(path)
    box, why = cache[key]
    if isinstance(box, str):
        missing.append(Missing(v.el, v.filename, why))
        return None
    if box is None:
        diags.warning("W021", f"mesh '{v.filename}' is not drawn: {why}", span(file, v.el),
                      "the dynamics do not need it; the link is drawn with its other visuals, or as the "
                      "ellipsoid of its inertia")
        return None
    lo, hi = box * v.scale[None, :]
    return np.minimum(lo, hi), np.maximum(lo, hi)


def report_missing(missing: list[Missing], file: str, diags: DiagnosticBag, skip: bool) -> None:
    """E028 (W021 when ``skip``) for the absent meshes: a package that is not found is said once,
    at its first mesh, with the number of its meshes."""
    first: dict[str, int] = {}
    groups: list[list[Missing]] = []
    for m in missing:
        key = m.why if m.why.startswith("package '") else f"{len(groups)}"
        if key in first:
            groups[first[key]].append(m)
        else:
            first[key] = len(groups)
            groups.append([m])
    for grp in groups:
        m, more = grp[0], len(grp) - 1
        also = f" and {more} more of its package" if more else ""
        if skip:
            diags.warning("W021", f"mesh '{m.filename}'{also} {'are' if more else 'is'} not drawn: {m.why}",
                          span(file, m.el), "the dynamics do not need meshes; give the package folder with "
                                            "--package-dir NAME=DIR to draw them")
        else:
            first = "" if m.why.startswith("package '") else "check the path (relative to the URDF's folder); "
            diags.error("E028", f"cannot find mesh '{m.filename}'{also}: {m.why}", span(file, m.el),
                        f"{first}to go on without drawing {'them' if more else 'it'}, import with "
                        "--skip-missing-meshes (skip_missing_meshes=True): the dynamics do not need meshes")
