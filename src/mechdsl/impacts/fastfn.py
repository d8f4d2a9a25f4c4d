"""Low-overhead numeric calls of CasADi Functions (``Function.buffer``) for the event loop.

The buffer wrapper itself is :class:`mechdsl.eom.codegen.FastFunction`; the event loop indexes
the outputs of every call, so here a single output comes back as a one-element tuple too.
"""
from __future__ import annotations

from ..eom.codegen import FastFunction as _FastFunction


class FastFunction(_FastFunction):
    def __call__(self, *args):
        out = super().__call__(*args)
        return (out,) if self._single else out
