"""Regression: a chain of 10 links has no translation symmetry; the search must not invent one
(it did when fewer probe states than coordinates were stacked)."""
import mechdsl
from mechdsl.analysis.integrals import first_integrals

from conftest import MODELS


def test_nlink_10_has_only_the_energy_integral():
    m = mechdsl.load(MODELS / "nlink_pendulum.mech").with_params(N=10)
    assert [fi.name for fi in first_integrals(m.eom)] == ["energy"]


def test_simulation_records_first_integrals():
    r = mechdsl.load(MODELS / "cart_pole.mech").simulate(1.0, points=11)
    assert "p_x" in r.signals
    # the cart's momentum is conserved (no force on x with F = 0): its drift measures the integrator
    assert r.stats["first_integral_drift"]["p_x"] < 1e-6
