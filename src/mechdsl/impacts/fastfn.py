"""Low-overhead numeric calls of CasADi Functions (``Function.buffer``) for the event loop.

The buffer wrapper itself is :class:`mechdsl.eom.codegen.FastFunction`; the event loop indexes
the outputs of every call, so here a single output comes back as a one-element tuple too.  The
arguments the event loop passes are numbers and vectors, copied straight into the input
buffers (numpy's ``np.ndim``/``np.ravel`` per argument cost as much as a small model's
evaluation); anything else (matrices, lists) goes the general way, column-major.
"""
from __future__ import annotations

import numpy as np

from ..eom.codegen import FastFunction as _FastFunction

_PLAIN = (float, int, np.float64)


class FastFunction(_FastFunction):
    def __call__(self, *args):
        for dst, a in zip(self._args, args):
            ta = type(a)
            if ta in _PLAIN or (ta is np.ndarray and a.ndim <= 1):
                dst[:] = a
            else:
                dst[:] = np.ravel(a, order="F") if np.ndim(a) > 1 else a    # matrices column-major
        self._eval()
        views = self._views
        if self._single:
            return (views[0].copy() if self.copy else views[0],)
        return tuple(v.copy() for v in views) if self.copy else tuple(views)
