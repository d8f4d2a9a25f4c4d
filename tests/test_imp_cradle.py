"""Newton's cradle with 3 and 5 balls: the two ways of resolving impacts in a touching chain.

- impact_order = "sequential": pairwise impacts, one after the other (fastest approach first).
  With e = 1 the momentum passes through the chain: the first ball stops, the last leaves
  with its speed (N - 1 impacts at one instant), as a real cradle does.
- impact_order = "simultaneous" (default): one impact of all touching contacts (Newton's law
  on every contact at once).  Balls 2..N then act as one rigid block of mass (N - 1) m:
  ball 1 rebounds with -(N - 2)/N v, the block leaves with 2/N v.

Both keep momentum, and with e = 1 both keep the energy.
"""
import numpy as np
import pytest
from scipy.special import ellipk

from imp_models import cradle
from mechdsl.impacts import simulate_with_contacts

L, G, TH0, M = 1.0, 9.81, -0.3, 0.1


def first_impact(N, order, e=1.0):
    eom, contacts = cradle(N, L=L, g=G, m=M, theta0=TH0, e=e)
    t_hit = np.sqrt(L / G) * ellipk(np.sin(-TH0 / 2) ** 2)        # quarter period
    r = simulate_with_contacts(eom, contacts, t_hit + 0.05, points=3, rtol=1e-10, atol=1e-12,
                               impact_order=order)
    assert r.success, r.message
    w = np.sqrt(2 * G / L * (1 - np.cos(TH0)))                      # omega of ball 1 at the bottom
    return r, t_hit, w


@pytest.mark.slow_cases('5')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("N", [3, 5])
def test_sequential_passes_momentum_through(N):
    r, t_hit, w = first_impact(N, "sequential")
    imp = [e for e in r.events if e["kind"] == "impact"]
    assert len(imp) == N - 1
    assert [e["contact"] for e in imp] == [f"c{i}" for i in range(1, N)]
    assert all(e["time"] == pytest.approx(t_hit, abs=1e-8) for e in imp)
    assert all(abs(e["energy_change"]) < 1e-12 for e in imp)
    # each pairwise impact between equal masses with e = 1 exchanges the velocities
    v = L * w
    assert [e["speed_before"] for e in imp] == pytest.approx([-v] * (N - 1), rel=1e-8)
    assert [e["speed_after"] for e in imp] == pytest.approx([v] * (N - 1), rel=1e-8)
    assert [e["impulse"] for e in imp] == pytest.approx([M * v] * (N - 1), rel=1e-8)
    # 0.05 s later: balls 1..N-1 hang still, ball N swings with the speed ball 1 had
    w_after = r.qd[-1]
    assert np.max(np.abs(w_after[:-1])) < 1e-8
    last = eom_pendulum_omega(w, 0.05)
    assert w_after[-1] == pytest.approx(last, rel=1e-7)
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-9


def eom_pendulum_omega(w0, dt):
    """Angular speed of a pendulum leaving the bottom with w0, after dt (energy: the angle from
    the exact solution of the pendulum ODE, here by a fine independent integration)."""
    from scipy.integrate import solve_ivp

    s = solve_ivp(lambda t, y: [y[1], -G / L * np.sin(y[0])], (0, dt), [0.0, w0], rtol=1e-12, atol=1e-14)
    return s.y[1, -1]


@pytest.mark.slow_cases('3')  # CPU budget: the cheaper tests of this file stay in the default run
@pytest.mark.parametrize("N", [3, 5])
def test_simultaneous_moves_the_chain_as_a_block(N):
    r, t_hit, w = first_impact(N, "simultaneous")
    imp = [e for e in r.events if e["kind"] == "impact"]
    assert len(imp) == 1
    ev = imp[0]
    assert ev["time"] == pytest.approx(t_hit, abs=1e-8)
    assert ev["contact"] == ", ".join(f"c{i}" for i in range(1, N))
    assert abs(ev["energy_change"]) < 1e-12
    v = L * w
    # Lambda_k = m * (velocity handed down the chain): block of N - k balls leaving with 2v/N
    expected = [M * (N - k) * 2 * v / N for k in range(1, N)]
    assert ev["impulse"] == pytest.approx(expected, rel=1e-8)
    # right after the impact (velocities from the event's speeds: relative speeds of neighbours)
    assert ev["speed_after"] == pytest.approx([v] + [0.0] * (N - 2), abs=1e-8 * v)
    # momentum (all at the bottom: sum of omegas) and energy are kept
    w_plus = np.array([-(N - 2) / N] + [2 / N] * (N - 1)) * w
    assert w_plus.sum() == pytest.approx(w)
    assert 0.5 * M * L ** 2 * np.sum(w_plus ** 2) == pytest.approx(0.5 * M * L ** 2 * w ** 2)
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-9
    # 0.05 s later the block (balls 2..N) has swung as one pendulum leaving with 2w/N
    assert r.qd[-1, 1:] == pytest.approx([eom_pendulum_omega(2 * w / N, 0.05)] * (N - 1), rel=1e-7)
    assert r.qd[-1, 0] == pytest.approx(-eom_pendulum_omega((N - 2) / N * w, 0.05), rel=1e-7)


def test_inelastic_cradle_loses_the_closed_form_energy():
    """Two balls, e = 0.5: one pairwise impact, dT = -(1 - e^2)/2 u^2 / (G M^-1 G^T)."""
    eom, contacts = cradle(2, L=L, g=G, m=M, theta0=TH0, e=0.5)
    t_hit = np.sqrt(L / G) * ellipk(np.sin(-TH0 / 2) ** 2)
    r = simulate_with_contacts(eom, contacts, t_hit + 0.01, points=2, rtol=1e-10, atol=1e-12)
    ev = [e for e in r.events if e["kind"] == "impact"][0]
    u = ev["speed_before"]
    W = 2 / (M * L ** 2) * L ** 2          # G = L [-1, 1] at the bottom, M = m L^2 I
    assert ev["energy_change"] == pytest.approx(-(1 - 0.25) / 2 * u ** 2 / W, rel=1e-9)
    assert ev["speed_after"] == pytest.approx(-0.5 * u, rel=1e-9)


@pytest.mark.slow
def test_sequential_cradle_keeps_swinging_for_20_seconds():
    """Long run (slow): 5 balls, e = 1, pairwise impacts.  Every half period of a pendulum of
    the release amplitude, N - 1 impacts pass the momentum through the chain; energy is kept."""
    N = 5
    eom, contacts = cradle(N, L=L, g=G, m=M, theta0=TH0, e=1.0)
    quarter = np.sqrt(L / G) * ellipk(np.sin(-TH0 / 2) ** 2)
    r = simulate_with_contacts(eom, contacts, 20.0, points=2001, rtol=1e-10, atol=1e-12, impact_order="sequential")
    assert r.success, r.message
    imp = [e for e in r.events if e["kind"] == "impact"]
    groups = int((20.0 - quarter) // (2 * quarter)) + 1
    assert len(imp) == groups * (N - 1)
    times = np.array([e["time"] for e in imp]).reshape(groups, N - 1)
    assert times == pytest.approx(np.repeat(quarter + 2 * quarter * np.arange(groups), N - 1).reshape(groups, N - 1),
                                  abs=1e-7)
    assert np.max(np.abs(r["energy"] - r["energy"][0])) < 1e-8
    assert np.max(np.abs(r.q)) <= -TH0 + 1e-8
