"""Covers missions.minsnap: the minimum-snap polynomials pass through every knot, stop where asked, are C⁶
(velocity to snap and beyond continuous) at pass-through knots, give analytic derivatives up to the 4th that
match finite differences, minimise the snap integral against perturbed curves, and stretch exactly; the banded
solver agrees with the dense solve it replaced, and 10 000 knots solve in tens of megabytes; the yaw flown is C²
and monotone between knots (on plans: tests/test_route_yaw.py)."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from missions.minsnap import ORDER, Knot, Smooth, demands, knot_arrays, solve, stretched, yaw_rate_peaks

KNOTS = (Knot(0.0, 0.0, 0.0, 0.0, 0.0, True), Knot(3.0, 0.0, 0.0, 5.0, 0.0, True),
         Knot(7.0, 8.0, 1.0, 5.0, 0.5), Knot(10.0, 8.0, 9.0, 6.0, 1.5), Knot(14.0, 0.0, 9.0, 5.0, 2.5),
         Knot(16.0, 0.0, 9.0, 5.0, 2.5, True), Knot(20.0, 0.0, 0.0, 0.0, 3.0, True))


def test_passes_through_every_knot_and_rests_at_stops() -> None:
    ref = Smooth(KNOTS)
    for k in KNOTS:
        for eps in (-1e-9, 1e-9):
            s = ref.sample(k.t + eps)
            assert [a[0] for a in s] == pytest.approx([k.x, k.y, k.z, k.psi], abs=1e-6)
        if k.stop:
            for axis in ref.sample(k.t + 1e-9)[:3]:
                assert axis[1:4] == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    assert ref.sample(-1.0) == ref.sample(0.0) and ref.sample(25.0)[2][0] == 0.0


@pytest.mark.parametrize("i", [2, 3, 4])
def test_derivatives_continuous_at_pass_through_knots(i: int) -> None:
    """The positions' derivatives 1-4; the yaw's 1-2, which the law uses (its 3rd and 4th are each quintic
    piece's own: missions.minsnap's docstring)."""
    ref = Smooth(KNOTS)
    t = KNOTS[i].t
    before, after = ref.sample(t - 1e-9), ref.sample(t + 1e-9)
    for axis, (a, b) in enumerate(zip(before, after)):
        for m in range(1, 5 if axis < 3 else 3):
            assert a[m] == pytest.approx(b[m], rel=1e-5, abs=1e-5)
    assert math.hypot(after[0][1], after[1][1]) > 0.1  # it does pass through, not stop
    assert i == 4 or after[3][1] > 0.05  # and turns through (KNOTS' yaw rises from knot 1 to 4, then holds)


def test_derivatives_are_those_of_the_position() -> None:
    """Each derivative is that of the one below (central differences); the yaw's 3rd and 4th away from the
    knots, where its 2nd has a kink."""
    ref = Smooth(KNOTS)
    h = 1e-4
    for t in np.linspace(0.1, 19.9, 37):
        near_knot = min(abs(t - k.t) for k in KNOTS) < 2 * h
        for m in range(4):
            lo, hi = ref.sample(t - h), ref.sample(t + h)
            for axis in range(3 if m >= 2 and near_knot else 4):
                fd = (hi[axis][m] - lo[axis][m]) / (2 * h)
                assert ref.sample(t)[axis][m + 1] == pytest.approx(fd, rel=1e-4, abs=1e-4)


def test_the_yaw_is_monotone_between_knots_and_holds_a_value_two_knots_share() -> None:
    """The yaw flown (missions.minsnap.yaw_pieces) never leaves the range of its segment's two knots (the
    minimum-snap polynomial's went 0.005 rad past KNOTS' yaws, and off the 2.5 knots 4 and 5 share); its exact
    peak rate (yaw_rate_peaks) bounds the sampled one. Fails on the minimum-snap yaw (and yaw_rate_peaks is new)."""
    ref = Smooth(KNOTS)
    peaks = yaw_rate_peaks(*knot_arrays(KNOTS))
    for j, (a, b) in enumerate(zip(KNOTS, KNOTS[1:])):
        lo, hi = min(a.psi, b.psi), max(a.psi, b.psi)
        samples = [ref.sample(a.t + (b.t - a.t) * i / 500)[3] for i in range(1, 500)]
        assert all(lo - 1e-12 <= p[0] <= hi + 1e-12 for p in samples), j
        if a.psi == b.psi:
            assert all(p[0] == a.psi and p[1] == 0.0 for p in samples), j
        fastest = max(abs(p[1]) for p in samples)
        assert peaks[j] * (1 - 1e-4) <= fastest <= peaks[j] * (1 + 1e-12), j


def qp_minimum_snap(knots: tuple[Knot, ...], axis: int) -> np.ndarray:
    """The textbook quadratic programme, solved through its KKT system: minimise the integrated squared snap
    subject to the positions, rest at stops, and only velocity, acceleration and jerk continuous at the other
    knots (Mellinger and Kumar 2011). Coefficients (segments, 8) in normalised time."""
    n = len(knots) - 1
    T = [knots[j + 1].t - knots[j].t for j in range(n)]
    f = [math.factorial(k) / math.factorial(k - 4) if k >= 4 else 0.0 for k in range(ORDER)]
    Q = np.zeros((ORDER * n, ORDER * n))
    for j in range(n):
        for k in range(4, ORDER):
            for m in range(4, ORDER):
                Q[ORDER * j + k, ORDER * j + m] = f[k] * f[m] / (k + m - 7) / T[j] ** 7

    def row(j: int, s: float, d: int) -> np.ndarray:
        r = np.zeros(ORDER * n)
        for k in range(d, ORDER):
            r[ORDER * j + k] = math.factorial(k) / math.factorial(k - d) * s ** (k - d) / T[j] ** d
        return r

    rows, rhs = [], []
    value = [(k.x, k.y, k.z, k.psi)[axis] for k in knots]
    for j in range(n):
        rows += [row(j, 0.0, 0), row(j, 1.0, 0)]
        rhs += [value[j], value[j + 1]]
    for i, k in enumerate(knots):
        for d in (1, 2, 3):
            if k.stop or i in (0, n):
                for j, s in ((i - 1, 1.0), (i, 0.0)):
                    if 0 <= j < n:
                        rows.append(row(j, s, d))
                        rhs.append(0.0)
            else:
                rows.append(row(i - 1, 1.0, d) - row(i, 0.0, d))
                rhs.append(0.0)
    A = np.array(rows)
    kkt = np.block([[2 * Q, A.T], [A, np.zeros((len(rows), len(rows)))]])
    sol = np.linalg.lstsq(kkt, np.concatenate([np.zeros(ORDER * n), rhs]), rcond=None)[0]
    return sol[:ORDER * n].reshape(n, ORDER)


@pytest.mark.parametrize("axis", [0, 1, 2, 3])
def test_it_is_the_minimum_of_the_snap_integral(axis: int) -> None:
    ours = solve(KNOTS)[:, axis, :]
    qp = qp_minimum_snap(KNOTS, axis)
    assert np.allclose(ours, qp, rtol=1e-6, atol=1e-6)


def dense_minimum_snap(knots: tuple[Knot, ...]) -> np.ndarray:
    """The solve the banded one replaced: the same rows (missions.minsnap's docstring) as one dense (8n x 8n)
    matrix, solved by numpy (LAPACK gesv). Coefficients (segments, 4 axes, 8) in normalised time."""
    n = len(knots) - 1
    T = [knots[j + 1].t - knots[j].t for j in range(n)]
    A, B = np.zeros((ORDER * n, ORDER * n)), np.zeros((ORDER * n, 4))

    def row(j: int, s: float, m: int, u: float) -> np.ndarray:
        r = np.zeros(ORDER * n)
        for k in range(m, ORDER):
            r[ORDER * j + k] = u**m * math.factorial(k) / math.factorial(k - m) * s ** (k - m) / T[j] ** m
        return r

    rows = []
    for j in range(n):
        rows += [(row(j, 0.0, 0, 1.0), knots[j]), (row(j, 1.0, 0, 1.0), knots[j + 1])]
    for i, k in enumerate(knots):
        if k.stop or i in (0, n):
            rows += [(row(j, s, m, T[j]), None) for m in (1, 2, 3) for j, s in ((i - 1, 1.0), (i, 0.0)) if 0 <= j < n]
        else:
            u = 0.5 * (T[i - 1] + T[i])
            rows += [(row(i - 1, 1.0, m, u) - row(i, 0.0, m, u), None) for m in range(1, ORDER - 1)]
    for r, (a, k) in enumerate(rows):
        A[r] = a
        B[r] = (k.x, k.y, k.z, k.psi) if k else 0.0
    return np.linalg.solve(A, B).reshape(n, ORDER, 4).transpose(0, 2, 1)


def random_knots(rng: np.random.Generator, n: int, stop_share: float = 0.3) -> tuple[Knot, ...]:
    """n + 1 knots: durations log-uniform over 0.25-4 s (neighbours up to 16 times apart), positions and yaw
    scattered over tens of metres (radians), a ``stop_share`` of them stops."""
    t = np.concatenate([[0.0], np.cumsum(np.exp(rng.uniform(math.log(0.25), math.log(4.0), n)))])
    return tuple(Knot(float(t[i]), *(float(v) for v in rng.normal(0.0, 20.0, 4)), bool(rng.random() < stop_share))
                 for i in range(n + 1))


@pytest.mark.parametrize("seed", range(8))
def test_agrees_with_the_dense_solve(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in (1, 2, 3, int(rng.integers(4, 60))):
        knots = random_knots(rng, n)
        ours, dense = solve(knots), dense_minimum_snap(knots)
        assert ours.shape == (n, 4, ORDER)
        assert np.abs(ours - dense).max() <= 1e-9 * np.abs(dense).max()
    assert np.abs(solve(KNOTS) - dense_minimum_snap(KNOTS)).max() <= 1e-9 * np.abs(solve(KNOTS)).max()


def test_three_thousand_knots_solve_in_little_memory() -> None:
    """The dense matrix of 2 999 segments would be 4.6 GB; the banded solve holds 8 rows a segment, linear in
    them (7 MB here, 23 MB for a plan's 10 000 items: docs/missions.md; tracemalloc slows the solve tenfold,
    so the test keeps to 3 000)."""
    knots = random_knots(np.random.default_rng(7), 2_999, stop_share=0.02)
    tracemalloc.start()
    try:
        ref = Smooth(knots)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 60e6
    for k in knots[::997] + knots[-1:]:
        assert [a[0] for a in ref.sample(k.t)] == pytest.approx([k.x, k.y, k.z, k.psi], abs=1e-6)


def test_stretching_scales_every_derivative_exactly() -> None:
    ref = Smooth(KNOTS)
    slow = stretched(ref, 2.0)
    assert slow.end_s == 40.0 and slow.stretched_by == 2.0
    for t in (1.0, 5.0, 8.5, 12.0, 17.0):
        a, b = ref.sample(t), slow.sample(2.0 * t)
        for axis in range(4):
            for m in range(5):
                assert b[axis][m] == pytest.approx(a[axis][m] / 2.0**m, rel=1e-9, abs=1e-9)
    d1, d2 = demands(ref, 1.0, 9.81), demands(slow, 1.0, 9.81)
    assert d2.thrust_n < d1.thrust_n and d2.tilt_rad < d1.tilt_rad
    assert d2.thrust_n == pytest.approx(demands(ref, 1.0, 9.81, 2.0).thrust_n, rel=1e-9)


def test_round_trips_through_its_table() -> None:
    from missions.trajectories import _smooth  # the loader's reading of kind = "smooth" (not exported)
    from params import Table

    ref = Smooth(KNOTS, lands=True)
    back = _smooth(Table(ref.to_dict(), "<t>"), 100.0)
    assert back == ref and back.sample(8.123) == ref.sample(8.123)


def test_refuses_bad_knots() -> None:
    with pytest.raises(ValueError):
        Smooth(KNOTS[:1])
    with pytest.raises(ValueError):
        Smooth((KNOTS[0], Knot(0.0, 1.0, 0.0, 0.0)))
