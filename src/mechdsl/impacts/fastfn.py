"""Low-overhead numeric calls of CasADi Functions from Python (``Function.buffer``).

A plain ``f(numpy arrays)`` converts every argument to a DM and costs 50-200 us; the
buffer interface evaluates in place on preallocated numpy arrays in about 1 us, which
matters when a one-step integrator calls the right-hand side from Python.
"""
from __future__ import annotations

import numpy as np


class FastFunction:
    def __init__(self, f):
        import casadi as ca

        # dense outputs so that the buffers can be reshaped without a sparsity pattern
        if any(not f.sparsity_out(i).is_dense() for i in range(f.n_out())):
            ins = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
            outs = [ca.densify(o) for o in f.call(ins)]
            f = ca.Function(f.name(), ins, outs, f.name_in(), f.name_out())
        self.f = f
        self.buf, self._eval = f.buffer()
        self.ins = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self.outs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        self.shapes = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(self.ins):
            self.buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.outs):
            self.buf.set_res(i, memoryview(r))

    def __call__(self, *args) -> list[np.ndarray]:
        for a, v in zip(self.ins, args):
            a[:] = np.ravel(v, order="F") if np.ndim(v) > 1 else v
        self._eval()
        return [r.reshape(s, order="F").copy() if s[1] > 1 else r.copy() for r, s in zip(self.outs, self.shapes)]
