"""The multipliers of a resting phase's output rows in one batched evaluation
(ContactSystem.multipliers_at: a mapped call, padded to a few sizes and chunked): the same as
the per-state solve of ``accel`` (Cholesky of M, then the rows' Schur complement) at random
states, and the same forces in a run as with every row evaluated alone."""
import warnings

import numpy as np
import pytest

import mechdsl
from conftest import MODELS
from mechdsl.eom import parameter_vector
from mechdsl.impacts.contact_system import ContactSystem
from mechdsl.simulation.backends import event_loop
from mechdsl.simulation.backends.events import _contact_setup


@pytest.mark.parametrize("K", [1, 3, 5, 70])
def test_batched_multipliers_are_the_per_state_ones(K):
    m = mechdsl.load(MODELS / "falling_rod.mech", scene="Drop")
    eom = m.eom
    gaps, fixes, functions = _contact_setup(eom, None, ())
    system = ContactSystem(eom, gaps, fixes, parameter_vector(eom, None), functions=functions)
    rows = [system.contact_row(0), system.contact_row(1)]
    rng = np.random.default_rng(K)
    ts, Y = rng.uniform(0, 1, K), rng.uniform(-1, 1, (2 * eom.n, K))
    lam = system.multipliers_at(ts, Y, rows)
    assert lam.shape == (K, 2)
    for j in range(K):
        _, one = system.accel(ts[j], Y[:eom.n, j], Y[eom.n:, j], rows)
        assert lam[j] == pytest.approx(one, rel=1e-10, abs=1e-12)


def test_a_run_gives_the_same_forces_with_its_rows_batched(monkeypatch):
    m = mechdsl.load(MODELS / "falling_rod.mech", scene="Drop")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = m.simulate(rtol=1e-4, atol=1e-4, error_estimate="off")
        monkeypatch.setattr(event_loop, "BATCH", 10 ** 9)
        b = m.simulate(rtol=1e-4, atol=1e-4, error_estimate="off")
    assert len(a.events) == len(b.events) and np.abs(a.q - b.q).max() < 1e-12
    for k in ("end_a.force", "end_b.force"):
        assert np.abs(a[k] - b[k]).max() < 1e-9 * max(1.0, np.abs(b[k]).max())
    assert np.abs(a["end_a.force"][-50:]).max() > 1.0           # the rows compared include the resting phase
