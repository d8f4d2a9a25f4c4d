"""The drawn shape of an imported body, from the <visual> elements of its links.

A body is drawn with one shape (``ir.Body.shape``, ``shape_size``, ``axis``), centred at its
centre of mass (docs/animate.md): one primitive visual is kept as it is (a cylinder with its
axis; a box turned by a multiple of 90 degrees with its edges permuted; a sphere); anything
else (a mesh, a box turned otherwise, several visuals) becomes the box that bounds it, in body
axes.  A mesh file that cannot be found or read is the located warning W021 and is not drawn.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..diagnostics import DiagnosticBag
from . import meshes
from .robot import Visual
from .tree import Group
from .xmltree import span


@dataclass
class Shape:
    kind: str                     # box | cylinder | sphere
    size: tuple[float, ...]
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)


def body_shape(g: Group, file: str, package_dirs: dict[str, str], diags: DiagnosticBag,
               bbox_cache: dict) -> Shape | None:
    placed = []
    for mb in g.members:
        for v in mb.link.visuals:
            R = mb.R @ v.origin.R
            p = mb.p + mb.R @ v.origin.p
            placed.append((v, R, p))
    if not placed:
        return None
    if len(placed) == 1:
        v, R, p = placed[0]
        if v.kind == "sphere":
            return Shape("sphere", v.size)
        if v.kind == "cylinder":
            return Shape("cylinder", v.size, tuple(float(x) for x in R[:, 2]))
        if v.kind == "box":
            perm = np.abs(np.round(R))
            if np.allclose(np.abs(R), perm, atol=1e-9) and np.allclose(perm.sum(axis=0), 1):
                return Shape("box", tuple(float(x) for x in perm @ np.array(v.size)))
    boxes = [b for b in (_bounds(v, R, p, file, package_dirs, diags, bbox_cache) for v, R, p in placed)
             if b is not None]
    if not boxes:
        return None
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    size = hi - lo
    if not np.any(size > 0):
        return None
    return Shape("box", tuple(float(x) for x in size))


def _bounds(v: Visual, R, p, file, package_dirs, diags, cache) -> np.ndarray | None:
    """The (min, max) corners of a visual in body axes."""
    if v.kind == "box":
        h = np.array(v.size) / 2
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    elif v.kind == "sphere":
        r = v.size[0]
        local = np.array([[-r, -r, -r], [r, r, r]])
    elif v.kind == "cylinder":
        r, L = v.size
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        rim = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
        local = np.vstack([np.hstack([rim, np.full((16, 1), z)]) for z in (-L / 2, L / 2)])
    else:
        key = (v.filename, str(Path(file).parent))
        if key not in cache:
            path, why = meshes.resolve(v.filename, Path(file).parent, package_dirs)
            cache[key] = meshes.bounding_box(path) if path is not None else (None, why)
        box, why = cache[key]
        if box is None:
            diags.warning("W021", f"mesh '{v.filename}' is not drawn: {why}", span(file, v.el),
                          "the dynamics do not need it; give the package folder with --package-dir NAME=DIR "
                          "to draw the body with the mesh's bounding box")
            return None
        lo, hi = box * v.scale[None, :]
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        local = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pts = local @ R.T + p
    return np.array([pts.min(axis=0), pts.max(axis=0)])
