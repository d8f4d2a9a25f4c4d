"""Where a URDF's mesh files are, and their bounding boxes (the imported bodies are drawn with
the box, issue 26).

File names: ``package://NAME/rest`` is looked up in the folders given for NAME (``--package-dir
NAME=DIR``), then in the folders above the URDF (one named NAME, or one whose package.xml names
it), then in ``ROS_PACKAGE_PATH``; ``file://`` and plain paths are relative to the URDF.
Formats: STL (binary and ASCII), Wavefront OBJ and COLLADA (.dae: the vertex sources of the
geometries, placed by the scene's node transforms (matrix, translate, rotate, scale) and scaled
by the asset's unit; up_axis is ignored, as ROS tools do).  A file that cannot be found or read
gives None and the reason.
"""
from __future__ import annotations

import math
import os
import struct
from pathlib import Path

import numpy as np

from . import xmltree

MAX_MESH_BYTES = 200_000_000


def resolve(filename: str, urdf_dir: Path, package_dirs: dict[str, str]) -> tuple[Path | None, str]:
    """(path, "") or (None, why)."""
    if filename.startswith("package://"):
        rest = filename[len("package://"):].lstrip("/")     # (package:///name/... is seen in the wild)
        pkg, _, rel = rest.partition("/")
        for base in _package_candidates(pkg, urdf_dir, package_dirs):
            p = base / rel
            if p.is_file():
                return p, ""
        return None, f"package '{pkg}' not found (give its folder with --package-dir {pkg}=DIR)"
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    p = Path(filename)
    if not p.is_absolute():
        p = urdf_dir / p
    return (p, "") if p.is_file() else (None, f"no file {p}")


def _package_candidates(pkg: str, urdf_dir: Path, package_dirs: dict[str, str]):
    if pkg in package_dirs:
        yield Path(package_dirs[pkg])
    d = urdf_dir.resolve()
    for folder in [d, *d.parents]:
        if folder.name == pkg:
            yield folder
        xml = folder / "package.xml"
        if xml.is_file() and f"<name>{pkg}</name>" in xml.read_text(errors="replace")[:20000]:
            yield folder
    for base in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if base:
            yield Path(base) / pkg


def bounding_box(path: Path) -> tuple[np.ndarray | None, str]:
    """((2, 3) array of the min and max corner, in the mesh's units before scale) or (None, why)."""
    try:
        size = path.stat().st_size
        if size > MAX_MESH_BYTES:
            return None, f"{path} is larger than {MAX_MESH_BYTES:,} bytes"
        suffix = path.suffix.lower()
        if suffix == ".stl":
            pts = _stl(path.read_bytes())
        elif suffix == ".obj":
            pts = _obj(path.read_text(errors="replace"))
        elif suffix == ".dae":
            pts = _dae(path.read_bytes(), str(path))
        else:
            return None, f"the mesh format {suffix or '(none)'} is not read (STL, OBJ and COLLADA are)"
    except (OSError, ValueError, struct.error) as e:
        return None, f"cannot read {path}: {e}"
    except Exception as e:  # noqa: BLE001 - a damaged mesh file never stops an import (a drawing is lost)
        return None, f"cannot read {path}: {type(e).__name__}"
    if pts is None or len(pts) == 0 or not np.all(np.isfinite(pts)):
        return None, f"no vertices in {path}"
    return np.array([pts.min(axis=0), pts.max(axis=0)]), ""


def _stl(data: bytes) -> np.ndarray | None:
    if len(data) >= 84:
        n = struct.unpack_from("<I", data, 80)[0]
        if 84 + 50 * n == len(data):
            rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
            tri = np.frombuffer(data, rec, n, 84)
            return tri["v"].reshape(-1, 3).astype(float)
    text = data.decode("ascii", errors="replace")
    vals = [line.split()[1:4] for line in text.splitlines() if line.lstrip().startswith("vertex")]
    return np.array(vals, float) if vals else None


def _obj(text: str) -> np.ndarray | None:
    vals = [line.split()[1:4] for line in text.splitlines() if line.startswith("v ")]
    return np.array(vals, float) if vals else None


def _dae(data: bytes, name: str) -> np.ndarray | None:
    from ..diagnostics import MechError

    try:
        root = xmltree.parse(data, name)
    except MechError as e:
        raise ValueError(e.diagnostics[0].message) from None
    tag = lambda el: el.tag.rsplit("}", 1)[-1] if "}" in el.tag else el.tag.split(":")[-1]  # noqa: E731
    by_id = {}
    for el in _walk(root):
        if "id" in el.attrib:
            by_id[el.attrib["id"]] = el
    unit = 1.0
    for el in _walk(root):
        if tag(el) == "unit" and el.get("meter"):
            unit = float(el.get("meter"))
            break
    geoms = {}
    for el in _walk(root):
        if tag(el) == "geometry":
            pts = _geometry_points(el, by_id, tag)
            if pts is not None:
                geoms[el.get("id", "")] = pts
    if not geoms:
        return None
    scene_nodes = [el for el in _walk(root) if tag(el) == "visual_scene"]
    placed = []
    for scene in scene_nodes[:1]:
        for node in scene.children:
            if tag(node) == "node":
                _place(node, np.eye(4), geoms, by_id, tag, placed, 0)
    pts = np.vstack(placed) if placed else np.vstack(list(geoms.values()))
    return pts * unit


def _walk(el):
    stack = [el]
    while stack:
        e = stack.pop()
        yield e
        stack.extend(reversed(e.children))


def _geometry_points(geom, by_id, tag) -> np.ndarray | None:
    out = []
    for mesh in geom.children:
        if tag(mesh) != "mesh":
            continue
        for v in mesh.children:
            if tag(v) != "vertices":
                continue
            for inp in v.children:
                if tag(inp) == "input" and inp.get("semantic") == "POSITION":
                    src = by_id.get((inp.get("source") or "").lstrip("#"))
                    arr = next((c for c in (src.children if src else []) if tag(c) == "float_array"), None)
                    if arr is not None:
                        vals = np.array(arr.text.split(), float)
                        out.append(vals[: len(vals) // 3 * 3].reshape(-1, 3))
    return np.vstack(out) if out else None


def _place(node, T, geoms, by_id, tag, out, depth) -> None:
    if depth > 64:
        return
    for c in node.children:
        k = tag(c)
        if k == "matrix":
            T = T @ np.array(c.text.split(), float).reshape(4, 4)
        elif k == "translate":
            M = np.eye(4)
            M[:3, 3] = np.array(c.text.split(), float)[:3]
            T = T @ M
        elif k == "scale":
            T = T @ np.diag(list(np.array(c.text.split(), float)[:3]) + [1.0])
        elif k == "rotate":
            x, y, z, deg = np.array(c.text.split(), float)[:4]
            M = np.eye(4)
            M[:3, :3] = _axis_angle(np.array([x, y, z]), math.radians(deg))
            T = T @ M
    for c in node.children:
        k = tag(c)
        if k == "instance_geometry":
            pts = geoms.get((c.get("url") or "").lstrip("#"))
            if pts is not None:
                out.append(pts @ T[:3, :3].T + T[:3, 3])
        elif k == "node":
            _place(c, T, geoms, by_id, tag, out, depth + 1)
        elif k == "instance_node":
            target = by_id.get((c.get("url") or "").lstrip("#"))
            if target is not None:
                _place(target, T, geoms, by_id, tag, out, depth + 1)


def _axis_angle(a: np.ndarray, angle: float) -> np.ndarray:
    n = float(np.linalg.norm(a))
    if n == 0:
        return np.eye(3)
    a = a / n
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
