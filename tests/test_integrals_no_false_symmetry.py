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


def test_overflowing_values_end_the_search_without_a_hang_or_a_warning(capsys):
    """Fuzz mutant (issue 18): heavy_top.mech with gravity {1e308, 0, 0} and r_cm = {1, 1, 1}.
    The rotation-symmetry search multiplied values near 1e308, got inf/nan and handed them to
    LAPACK's SVD, which never returned (`mech check` hung); numpy's overflow warnings went to
    stderr.  Now the search claims nothing from non-finite data, quietly."""
    import warnings

    import numpy as np
    from mechdsl.analysis.core import null_space

    assert null_space(np.array([[1.0, np.nan], [np.inf, 0.0]])).shape == (2, 0)
    text = (MODELS / "heavy_top.mech").read_text()
    old_g, old_r = "Gravity gravity(g = {0, 0, -g});", "r_cm = {0, 0, l}"
    assert old_g in text and old_r in text
    m = mechdsl.loads(text.replace(old_g, "Gravity gravity(g = {1e308, 0, 0});").replace(old_r, "r_cm = {1, 1, 1}"),
                      model="HeavyTop")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        names = [fi.name for fi in first_integrals(m.eom)]
    assert "energy" in names
