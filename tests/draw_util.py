"""Shared by the tests of drawn shapes: the page's body poses and a quaternion as a matrix,
written out here (independent of mechdsl.view.scene.quaternions), and the order of a box's
corners in mechdsl.animate.shapes.outline_samples."""
from __future__ import annotations

import base64

import numpy as np

SIGNS = [np.array([sx, sy, sz]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]


def quat_matrix(x, y, z, w) -> np.ndarray:
    """The rotation of the unit quaternion (x, y, z, w) (three.js's order)."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def page_solids(data: dict, frame: int = 0):
    """(body name, origin, rotation, solid dict) of every solid in a page's data at a frame."""
    B = len(data["bodies"])
    poses = np.frombuffer(base64.b64decode(data["poses"]), "<f4").reshape(-1, B, 7)[frame].astype(float)
    for body, pose in zip(data["bodies"], poses):
        for s in body["solids"]:
            yield body["name"], pose[:3], quat_matrix(*pose[3:]), s
