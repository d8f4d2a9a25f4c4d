"""The scene of the interactive 3-D view as data: what is drawn (from :mod:`mechdsl.animate.geometry`)
and where it is at every frame, packed compactly for the page.

    bodies   every body with a solid or a hoop: its pose at every frame (origin and unit
             quaternion, float32) and its solids/hoops in body axes
    points   the world positions of the few points the other drawables need (dots, frame links,
             springs, dampers, arms, pins, rails, spherical contact surfaces, traces), float32
    planes   contact planes (static)

Arrays travel as base64 of little-endian float32 (times as float64); everything else is JSON.
A model without bodies (the equation layer) is shown as bars of its coordinates.
"""
from __future__ import annotations

import base64

import numpy as np

from ..animate.camera import screen_axes, up_label
from ..animate.stage import body_colours

COLUMN_KINDS = ("point", "sphere", "link", "spring", "damper", "arm", "pin", "rail", "ring", "trace")
FORMAT = 1


def b64(a, dtype="<f4") -> str:
    return base64.b64encode(np.ascontiguousarray(np.asarray(a, dtype)).tobytes()).decode("ascii")


def quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3), Shepperd's method
    (the largest of w, x, y, z first, so no division by a small number)."""
    R = np.asarray(R, float)
    shape = R.shape[:-2]
    m = R.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    case = np.argmax(np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1), axis=1)
    q = np.empty((len(m), 4))
    for c in range(4):
        k = case == c
        if not k.any():
            continue
        a = m[k]
        d = [a[:, 0, 0], a[:, 1, 1], a[:, 2, 2]]
        if c == 0:
            s = 2.0 * np.sqrt(1.0 + d[0] + d[1] + d[2])
            q[k] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) / s, (a[:, 0, 2] - a[:, 2, 0]) / s,
                             (a[:, 1, 0] - a[:, 0, 1]) / s, s / 4], axis=1)
        elif c == 1:
            s = 2.0 * np.sqrt(1.0 + d[0] - d[1] - d[2])
            q[k] = np.stack([s / 4, (a[:, 0, 1] + a[:, 1, 0]) / s, (a[:, 0, 2] + a[:, 2, 0]) / s,
                             (a[:, 2, 1] - a[:, 1, 2]) / s], axis=1)
        elif c == 2:
            s = 2.0 * np.sqrt(1.0 + d[1] - d[0] - d[2])
            q[k] = np.stack([(a[:, 0, 1] + a[:, 1, 0]) / s, s / 4, (a[:, 1, 2] + a[:, 2, 1]) / s,
                             (a[:, 0, 2] - a[:, 2, 0]) / s], axis=1)
        else:
            s = 2.0 * np.sqrt(1.0 + d[2] - d[0] - d[1])
            q[k] = np.stack([(a[:, 0, 2] + a[:, 2, 0]) / s, (a[:, 1, 2] + a[:, 2, 1]) / s, s / 4,
                             (a[:, 1, 0] - a[:, 0, 1]) / s], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(shape + (4,))


def continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions (N, B, 4) with signs chosen so consecutive frames are on the same side
    (q and -q are the same rotation): interpolation between frames takes the short way."""
    if len(q) < 2:
        return q
    dots = np.einsum("nbi,nbi->nb", q[1:], q[:-1])
    sign = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    out = q.copy()
    out[1:] *= sign[:, :, None]
    return out


def _local(solid) -> dict:
    out = {"kind": solid.kind, "size": [float(v) for v in solid.size], "center": [float(v) for v in solid.center],
           "quat": [float(v) for v in quaternions(solid.rot)]}
    return out | ({"name": solid.name} if solid.name else {})


def build_scene(geo, times, Q, *, up=None, title="", speed=1.0, events=()) -> dict:
    """The page's data for frames at ``times`` with coordinates Q (N, n)."""
    times = np.asarray(times, float)
    up = np.asarray(geo.up if up is None else up, float)
    X = geo.positions(times, Q)                                   # (N, 3, K)
    origins, rotations = geo.poses(times, Q)                      # (N, B, 3), (N, B, 3, 3)
    palette = body_colours(geo)
    bodies = [{"name": name, "solids": [], "hoops": [], "colour": palette.get(name, "#888888")} for name in geo.posed]
    index = {name: i for i, name in enumerate(geo.posed)}
    used: dict[int, int] = {}                                     # column of X -> column of the page's points

    def cols(it) -> list[int]:
        return [used.setdefault(c, len(used)) for c in range(it.cols.start, it.cols.stop)]

    items, planes = [], []
    radii = []
    for it in geo.items:
        solid = it.extra.get("solid")
        if solid is not None:
            bodies[index[it.body]]["solids"].append(_local(solid) | {"translucent": solid.kind == "ellipsoid"})
        elif it.kind == "hoop":
            bodies[index[it.body]]["hoops"].append({"center": [float(v) for v in it.extra["center"]],
                                                    "normal": [float(v) for v in it.extra["normal"]],
                                                    "radius": float(it.radius)})
        elif it.kind == "plane":
            planes.append({k: [float(v) for v in it.extra[k]] for k in ("base", "normal", "u", "v")})
        elif it.kind in COLUMN_KINDS and not it.extra.get("hidden"):
            items.append({"kind": it.kind, "name": it.name, "cols": cols(it), "radius": float(it.radius),
                          "colour": palette.get(it.body, "#222222"), "ground": bool(it.extra.get("ground"))})
            if it.radius:
                radii.append(float(it.radius))
    lo, hi = _bounds(X, geo, origins)
    pad = max(radii, default=0.0)
    lo, hi = lo - pad, hi + pad
    scale = float(max(np.max(hi - lo), 1e-3))
    quats = continuous(quaternions(rotations)) if len(geo.posed) else np.zeros((len(times), 0, 4))
    poses = np.concatenate([origins, quats], axis=2) if len(geo.posed) else np.zeros((len(times), 0, 7))
    axes = screen_axes("3d", up)
    return {
        "format": FORMAT, "mode": "3d", "title": title, "times": b64(times, "<f8"), "n_frames": int(len(times)),
        "speed": float(speed), "up": [float(v) for v in up], "up_label": up_label(up),
        "toward_viewer": [float(v) for v in axes[2]],
        "center": [float(v) for v in (lo + hi) / 2], "extent": [float(v) for v in hi - lo], "scale": scale,
        "bodies": bodies, "poses": b64(poses), "items": items, "planes": planes,
        "points": b64(X[:, :, list(used)].transpose(0, 2, 1)) if used else "", "n_points": len(used),
        "impacts": sorted(float(e["time"]) for e in events if e.get("kind") == "impact"),
    }


def _bounds(X, geo, origins) -> tuple[np.ndarray, np.ndarray]:
    """Box holding every drawn point at every frame (spheres by their radius)."""
    pts = [X.transpose(0, 2, 1).reshape(-1, 3)] if X.size else []
    for it in geo.items:
        if it.kind == "sphere" and X.size:
            c = X[:, :, it.cols.start]
            pts += [c + it.radius, c - it.radius]
    if origins.size:
        pts.append(origins.reshape(-1, 3))
    if not pts:
        return np.full(3, -1.0), np.full(3, 1.0)
    P = np.concatenate(pts)
    P = P[np.all(np.isfinite(P), axis=1)]
    if not len(P):
        return np.full(3, -1.0), np.full(3, 1.0)
    return P.min(axis=0), P.max(axis=0)


def bars_scene(names, units, times, Q, *, title="", speed=1.0) -> dict:
    """A model without bodies: its coordinates as bars (the same controls)."""
    Q = np.asarray(Q, float).reshape(len(times), -1)
    return {"format": FORMAT, "mode": "bars", "title": title, "times": b64(times, "<f8"), "n_frames": int(len(times)),
            "speed": float(speed), "names": list(names), "units": list(units), "q": b64(Q),
            "range": [float(min(0.0, Q.min())) if Q.size else -1.0, float(max(0.0, Q.max())) if Q.size else 1.0]}
