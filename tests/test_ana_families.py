"""Continuous families of equilibria in ordinary (revolute) coordinates: the seven-joint arm
hanging or standing straight can turn its vertical-axis joints (j1, j3, j5, j7) freely, so its
equilibria are 2^3 = 8 families (j2, j4, j6 each 0 or pi: every link vertical), not hundreds of
points sampled on them; the one hanging down (j2 = pi, j4 = j6 = 0) is stable, neutral along its
family, and the rest are unstable (a link above a pivot)."""
import numpy as np

import mechdsl
import mechdsl.examples


def test_arm7_equilibria_are_eight_families():
    eqs = mechdsl.load(mechdsl.examples.path("arm7")).equilibria()
    assert len(eqs) == 8
    upright = set()
    for e in eqs:
        v = e.values
        assert all(min(abs(v[j]), abs(abs(v[j]) - np.pi)) < 1e-6 for j in ("j2.phi", "j4.phi", "j6.phi"))
        upright.add(tuple(abs(v[j]) < 1e-6 for j in ("j2.phi", "j4.phi", "j6.phi")))
    assert len(upright) == 8                       # every combination once
    stable = [e for e in eqs if e.stable]
    assert len(stable) == 1
    v = stable[0].values
    assert abs(abs(v["j2.phi"]) - np.pi) < 1e-6 and abs(v["j4.phi"]) < 1e-6 and abs(v["j6.phi"]) < 1e-6
    assert any("continuous family" in n for n in stable[0].notes)
