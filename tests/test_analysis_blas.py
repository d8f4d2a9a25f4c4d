"""The symmetry search's SVDs on one BLAS thread (analysis.core.one_blas_thread; issue 24 item 8:
OpenBLAS's threads cost a first run ~0.1 s of CPU on a few hundred rows): the search finds the
same first integrals, to the bit of their expressions, and the thread count is restored."""
import contextlib

import numpy as np

import mechdsl
from mechdsl.analysis import core, integrals

from conftest import MODELS


def test_one_blas_thread_restores_the_thread_count_and_nests():
    blas = core._openblas()
    before = blas[1]() if blas is not None else None
    with core.one_blas_thread():
        if blas is not None:
            assert blas[1]() == 1
        with core.one_blas_thread():
            pass
    assert (blas[1]() if blas is not None else None) == before


def test_the_first_integrals_are_those_found_with_blas_threads(monkeypatch):
    def found():
        out = []
        for name in ("kepler.mech", "double_pendulum.mech"):
            eom = mechdsl.load(MODELS / name).eom
            out.append([(f.name, f.kind, str(f.sx), f.direction, f.rotation) for f in integrals.first_integrals(eom)])
        return out
    one = found()
    assert any(f[1] in ("momentum", "angular_momentum") for fs in one for f in fs)    # a search that finds some
    monkeypatch.setattr(core, "one_blas_thread", contextlib.nullcontext)
    assert found() == one
    rng = np.random.default_rng(3)
    J = rng.normal(size=(12, 5)) @ rng.normal(size=(5, 9))          # rank 5 of 9: a 4-dimensional null space
    monkeypatch.undo()
    N = core.null_space(J)
    assert N.shape == (9, 4) and np.abs(J @ N).max() < 1e-12
