"""Shared by the URDF tests: where example-robot-data keeps its robots, and a state of an imported
model carried over to Pinocchio (joint by joint, through the importer's name map)."""
from __future__ import annotations

import importlib.metadata
from pathlib import Path

import casadi as ca
import numpy as np


def robots_dir() -> Path:
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def all_urdfs() -> list[Path]:
    return sorted(robots_dir().rglob("*.urdf"))


class Pair:
    """An imported robot beside Pinocchio's model of the same URDF (fixed base)."""

    def __init__(self, rel: str, mimic: bool = False):
        import pinocchio as pin

        import mechdsl
        from mechdsl.urdf import convert

        self.path = robots_dir() / rel
        self.imp = convert(self.path)
        self.model = mechdsl.loads(self.imp.text)
        self.eom = e = self.model.eom
        self.pin = pin.buildModelFromUrdf(str(self.path), mimic) if mimic else pin.buildModelFromUrdf(str(self.path))
        self.data = self.pin.createData()
        self.mimic = mimic
        coords = list(e.coords)
        self.rows = []                       # (pinocchio joint, index in mechdsl's q)
        for jid in range(1, self.pin.njoints):
            jm, name = self.pin.joints[jid], self.pin.names[jid]
            if jm.nv == 0 or name in self.imp.mimics:
                continue
            self.rows.append((jm, coords.index(self.imp.coordinates[name][0])))
        assert len(self.rows) == len(coords), "every coordinate is one of Pinocchio's joints"
        self.P = np.zeros((len(coords), self.pin.nv))
        for jm, k in self.rows:
            self.P[k, jm.idx_v] = 1.0
        self.f = ca.Function("f", [e.q, e.qd, e.t, e.p], [e.M, e.bias, e.qdd if e.qdd is not None else ca.SX(0, 1)])

    def state(self, rng):
        n = len(self.rows)
        q, v = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2.0, 2.0, n)
        return q, v, self.to_pin(q, v)

    def to_pin(self, q, v):
        import pinocchio as pin

        qp, vp = pin.neutral(self.pin), np.zeros(self.pin.nv)
        for jm, k in self.rows:
            if jm.nq == 2:                  # a continuous joint: (cos, sin)
                qp[jm.idx_q:jm.idx_q + 2] = [np.cos(q[k]), np.sin(q[k])]
            else:
                qp[jm.idx_q] = q[k]
            vp[jm.idx_v] = v[k]
        return qp, vp

    def mechdsl(self, q, v):
        M, b, a = self.f(q, v, 0.0, self.eom.param_values)
        M, b = np.array(M), np.array(b).ravel()
        a = np.array(a).ravel() if self.eom.qdd is not None else np.linalg.solve(M, b)
        return M, b, a

    def pinocchio(self, qp, vp):
        import pinocchio as pin

        M = pin.crba(self.pin, self.data, qp)
        M = np.triu(M) + np.triu(M, 1).T
        b = -pin.rnea(self.pin, self.data, qp, vp, np.zeros(self.pin.nv))
        a = np.linalg.solve(M, b) if self.mimic else pin.aba(self.pin, self.data, qp, vp, np.zeros(self.pin.nv))
        P = self.P
        return P @ M @ P.T, P @ b, P @ a


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300))
