"""The impact map on random problems, against independent computations:
- one contact: the closed forms Lambda = -(1 + e) u / W, dT = -(1 - e^2)/2 u^2 / W, with
  W = G M^-1 G^T, or W = G P G^T with P the constrained inverse mass when bilateral rows are present;
- several contacts: the linear complementarity problem solved by enumerating every active set."""
import itertools

import numpy as np
import pytest

from mechdsl.impacts import solve_impact
from mechdsl.impacts.impact_map import ImpactError


def spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.5 * n * np.eye(n)


@pytest.mark.parametrize("seed", range(5))
def test_single_contact_closed_form(seed):
    rng = np.random.default_rng(seed)
    n = 5
    M = spd(rng, n)
    G = rng.normal(size=(1, n))
    v = rng.normal(size=n)
    u = (G @ v)[0]
    if u > 0:
        G, u = -G, -u
    e = rng.uniform(0, 1)
    s = solve_impact(M, v, G, [0.0], [e])
    W = (G @ np.linalg.solve(M, G.T))[0, 0]
    assert s.impulses[0] == pytest.approx(-(1 + e) * u / W, rel=1e-10)
    assert s.speeds_after[0] == pytest.approx(-e * u, rel=1e-10)
    dT = 0.5 * s.qd @ M @ s.qd - 0.5 * v @ M @ v
    assert dT == pytest.approx(-(1 - e * e) / 2 * u * u / W, rel=1e-9)
    assert M @ (s.qd - v) == pytest.approx(G[0] * s.impulses[0], abs=1e-10)


@pytest.mark.parametrize("seed", range(5))
def test_single_contact_with_bilateral_rows(seed):
    rng = np.random.default_rng(100 + seed)
    n, r = 6, 2
    M = spd(rng, n)
    B = rng.normal(size=(r, n))
    G = rng.normal(size=(1, n))
    # a velocity that satisfies the bilateral rows
    N = np.linalg.svd(B)[2][r:].T
    v = N @ rng.normal(size=n - r)
    u = (G @ v)[0]
    if u > 0:
        G, u = -G, -u
    e = rng.uniform(0, 1)
    s = solve_impact(M, v, G, [0.0], [e], B, np.zeros(r))
    Mi = np.linalg.inv(M)
    P = Mi - Mi @ B.T @ np.linalg.solve(B @ Mi @ B.T, B @ Mi)
    W = (G @ P @ G.T)[0, 0]
    assert s.speeds_after[0] == pytest.approx(-e * u, rel=1e-9)
    assert np.max(np.abs(B @ s.qd)) < 1e-12
    dT = 0.5 * s.qd @ M @ s.qd - 0.5 * v @ M @ v
    assert dT == pytest.approx(-(1 - e * e) / 2 * u * u / W, rel=1e-8)
    assert M @ (s.qd - v) == pytest.approx(G[0] * s.impulses[0] + B.T @ s.bilateral, abs=1e-9)


def lcp_by_enumeration(M, v, G, e):
    """Newton's law with complementarity, by trying every set of contacts with an impulse."""
    k = G.shape[0]
    u = G @ v
    h = -e * np.minimum(u, 0)
    Mi = np.linalg.inv(M)
    W = G @ Mi @ G.T
    sols = []
    for r in range(k + 1):
        for S in itertools.combinations(range(k), r):
            lam = np.zeros(k)
            S = list(S)
            if S:
                lam[S] = np.linalg.solve(W[np.ix_(S, S)], h[S] - u[S])
            vp = v + Mi @ G.T @ lam
            w = G @ vp - h
            if np.all(lam >= -1e-10) and np.all(w >= -1e-10):
                sols.append(vp)
    return sols


@pytest.mark.parametrize("seed", range(8))
def test_several_contacts_solve_the_complementarity_problem(seed):
    rng = np.random.default_rng(200 + seed)
    n, k = 6, 4
    M = spd(rng, n)
    G = rng.normal(size=(k, n))
    v = rng.normal(size=n)
    e = rng.uniform(0, 1, size=k)
    s = solve_impact(M, v, G, np.zeros(k), e)
    sols = lcp_by_enumeration(M, v, G, e)
    assert sols, "the enumeration found no solution"
    # the post-impact velocity of a complementarity problem with W > 0 is unique
    for vp in sols:
        assert s.qd == pytest.approx(vp, abs=1e-9)
    assert np.all(s.impulses >= 0)
    u = G @ v
    assert np.all(s.speeds_after >= -e * np.minimum(u, 0) - 1e-10)
    # (Newton's law on several contacts with different e may gain energy; plastic impacts never do)
    p = solve_impact(M, v, G, np.zeros(k), np.zeros(k))
    assert 0.5 * p.qd @ M @ p.qd <= 0.5 * v @ M @ v + 1e-12


def test_dependent_contact_rows():
    """A body resting on three collinear contacts of a plane (rank 2): velocities are unique."""
    M = np.diag([1.0, 1.0, 0.1])          # (y, phi) of a bar plus one more dof
    G = np.array([[1.0, -0.5, 0.0], [1.0, 0.0, 0.0], [1.0, 0.5, 0.0]])
    v = np.array([-1.0, 0.0, 0.3])
    s = solve_impact(M, v, G, np.zeros(3), [0.0, 0.0, 0.0])
    assert s.qd == pytest.approx([0.0, 0.0, 0.3], abs=1e-12)
    assert G.T @ s.impulses == pytest.approx(M @ (s.qd - v), abs=1e-12)


def test_contradictory_bilateral_rows_are_reported():
    M = np.eye(2)
    B = np.array([[1.0, 0.0], [1.0, 0.0]])
    with pytest.raises(ImpactError):
        solve_impact(M, np.zeros(2), np.zeros((0, 2)), [], [], B, np.array([1.0, 2.0]))


@pytest.mark.parametrize("seed", range(4))
def test_single_contact_shortcut_equals_the_general_solve(seed):
    """A lone contact without bilateral rows takes the closed-form shortcut; the same row given
    twice (dependent rows) goes through the general least-distance solve: same velocities, the
    same total impulse; a separating contact gets no impulse."""
    rng = np.random.default_rng(100 + seed)
    n = 4
    M, G, v = spd(rng, n), rng.normal(size=(1, n)), rng.normal(size=n)
    gt = rng.normal(size=1)
    e = rng.uniform(0, 1)
    one = solve_impact(M, v, G, gt, [e])
    two = solve_impact(M, v, np.vstack([G, G]), np.r_[gt, gt], [e, e])
    assert one.qd == pytest.approx(two.qd, abs=1e-12)
    assert one.impulses[0] == pytest.approx(two.impulses.sum(), abs=1e-12)
    u = (G @ v + gt)[0]
    if u >= 0:
        assert one.impulses[0] == pytest.approx(0.0, abs=1e-15) and one.qd == pytest.approx(v, abs=1e-15)
    else:
        assert one.speeds_after[0] == pytest.approx(-e * u, rel=1e-10)


def test_triangular_solves_of_the_general_path_solve_their_systems():
    """The general path's G L^-T (BLAS trsv/trsm on the Cholesky factor, see impact_map._lower_solve)
    for no row, one row and several rows: L X^T = R^T holds to round-off."""
    from mechdsl.impacts.impact_map import _lower_solve
    rng = np.random.default_rng(7)
    for n, k in [(3, 0), (3, 1), (4, 2), (7, 5), (12, 3)]:
        L = np.linalg.cholesky(spd(rng, n))
        R = rng.normal(size=(k, n))
        X = _lower_solve(L, R)
        assert X.shape == (k, n)
        assert L @ X.T == pytest.approx(R.T, abs=1e-12)


def test_a_non_finite_mass_matrix_is_an_impact_error():
    M = np.eye(3)
    M[1, 1] = np.inf
    with pytest.raises(ImpactError):
        solve_impact(M, np.array([0.0, -1.0, 0.0]), np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]), [0.0, 0.0], [0.5, 0.5])
