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


def share_dir() -> Path:
    """The folder holding example-robot-data's ``package://`` roots (its share/ folder)."""
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share"))


def all_urdfs() -> list[Path]:
    return sorted(robots_dir().rglob("*.urdf"))


class Pair:
    """An imported robot beside Pinocchio's model of the same URDF (fixed base).

    Pinocchio (before 3.4 at least) reads a mimic joint as a joint of its own; mechdsl binds it
    to the joint it follows (q_m = k q_j + c).  So Pinocchio's joint space is mapped onto
    mechdsl's by the constant matrix P^T (v_pin = P^T v): M = P M_pin P^T and bias = P bias_pin,
    exact (a constant map has no velocity-product term), and the accelerations are compared as
    the solution of those projected equations."""

    def __init__(self, rel: str):
        import pinocchio as pin

        import mechdsl
        from mechdsl.urdf import convert

        self.path = robots_dir() / rel
        self.imp = convert(self.path)
        self.model = mechdsl.loads(self.imp.text)
        self.eom = e = self.model.eom
        self.pin = pin.buildModelFromUrdf(str(self.path))
        self.data = self.pin.createData()
        self.mimic = bool(self.imp.mimics)
        coords = list(e.coords)
        self.rows = []                       # (pinocchio joint, index in mechdsl's q, multiplier, offset)
        joint_of = {self.pin.names[j]: self.pin.joints[j] for j in range(1, self.pin.njoints)}
        for name, jm in joint_of.items():
            if jm.nv == 0:
                continue
            target, mult, off = self.imp.mimics.get(name, (name, 1.0, 0.0))
            self.rows.append((jm, coords.index(self.imp.coordinates[target][0]), mult, off))
        assert {k for _, k, _, _ in self.rows} == set(range(len(coords))), "every coordinate drives a joint"
        self.P = np.zeros((len(coords), self.pin.nv))
        for jm, k, mult, _ in self.rows:
            self.P[k, jm.idx_v] = mult
        self.f = ca.Function("f", [e.q, e.qd, e.t, e.p], [e.M, e.bias, e.qdd if e.qdd is not None else ca.SX(0, 1)])

    def state(self, rng):
        n = len(self.eom.coords)
        q, v = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2.0, 2.0, n)
        return q, v, self.to_pin(q, v)

    def to_pin(self, q, v):
        import pinocchio as pin

        qp, vp = pin.neutral(self.pin), np.zeros(self.pin.nv)
        for jm, k, mult, off in self.rows:
            x = mult * q[k] + off
            if jm.nq == 2:                  # a continuous joint: (cos, sin)
                qp[jm.idx_q:jm.idx_q + 2] = [np.cos(x), np.sin(x)]
            else:
                qp[jm.idx_q] = x
            vp[jm.idx_v] = mult * v[k]
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
        P = self.P
        Mq, bq = P @ M @ P.T, P @ b
        if self.mimic:
            return Mq, bq, np.linalg.solve(Mq, bq)
        return Mq, bq, P @ pin.aba(self.pin, self.data, qp, vp, np.zeros(self.pin.nv))


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300))
