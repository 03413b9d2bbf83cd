"""Covers missions.references: Step, Sine and Waypoints give their derivatives up to the 4th.

Each derivative k (1..4) must equal the central finite difference of derivative k - 1;
waypoint segments join with continuous value, velocity and acceleration (C^2) and rest at
each waypoint.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from missions import Setpoint, Sine, Step, Waypoints
from missions.references import Prefetched, Reference

H = 1e-5  # s, central-difference step

STEP = Step((Setpoint(0.0, 1.0, 1.0, 1.0, math.pi / 4), Setpoint(10.0, -1.0, 2.0, 2.0, 0.0),
             Setpoint(20.0, 0.0, 0.0, 1.5, -math.pi / 4)))
SINE = Sine(amplitude=1.3, omega=0.7, climb=-0.2, z0=0.5, psi=0.3)
POINTS = (
    Setpoint(1.0, 0.0, 0.0, 0.0, 0.0),
    Setpoint(5.0, 0.0, 0.0, 2.0, 0.0),
    Setpoint(12.0, 3.0, -1.0, 2.0, 1.5),
    Setpoint(19.0, 3.0, 3.0, 2.5, 3.0),
)
WAYPOINTS = Waypoints(POINTS)


def check_derivatives(ref: Reference, t: float) -> None:
    """d/dt of derivative k-1 (central difference) == derivative k, for k = 1..4, all axes."""
    lo, mid, hi = ref.sample(t - H), ref.sample(t), ref.sample(t + H)
    for axis in range(4):
        for k in range(1, 5):
            fd = (hi[axis][k - 1] - lo[axis][k - 1]) / (2 * H)
            scale = max(1.0, abs(mid[axis][k]))
            assert abs(fd - mid[axis][k]) <= 1e-5 * scale, (axis, k, t, fd, mid[axis][k])


@given(st.floats(0.0, 60.0))
def test_sine_derivatives(t: float) -> None:
    check_derivatives(SINE, t + H)


def test_sine_is_the_papers_scenario() -> None:
    s = Sine()
    for t in (0.0, 1.0, 7.3, 29.9):
        x, y, z, psi = s.sample(t)
        assert x[0] == pytest.approx(math.sin(0.5 * t)) and y[0] == pytest.approx(math.cos(0.5 * t))
        assert z[0] == pytest.approx(0.1 * t) and psi == (0.0, 0.0, 0.0, 0.0, 0.0)
        assert x[4] == pytest.approx(0.5**4 * math.sin(0.5 * t))


@given(st.floats(0.0, 30.0).filter(lambda t: all(abs(t - c) > 2 * H for c in (0.0, 10.0, 20.0))))
def test_step_is_piecewise_constant(t: float) -> None:
    check_derivatives(STEP, t)
    sp = STEP.setpoints[sum(t >= s.t for s in STEP.setpoints) - 1]
    assert STEP.sample(t) == ((sp.x, 0, 0, 0, 0), (sp.y, 0, 0, 0, 0), (sp.z, 0, 0, 0, 0), (sp.psi, 0, 0, 0, 0))


def test_step_changes_and_before_the_first() -> None:
    assert STEP.change_times() == (0.0, 10.0, 20.0)
    assert STEP.sample(9.999)[0][0] == 1.0 and STEP.sample(10.0)[0][0] == -1.0
    late = Step((Setpoint(2.0, 1.0, 2.0, 3.0),))
    assert late.sample(0.0)[2][0] == 3.0  # the first set-point also holds before its time
    with pytest.raises(ValueError):
        Step(())
    with pytest.raises(ValueError):
        Step((Setpoint(1.0, 0, 0, 0), Setpoint(1.0, 1, 1, 1)))


@given(st.floats(0.0, 25.0).filter(lambda t: all(abs(t - p.t) > 2 * H for p in POINTS)))
def test_waypoint_derivatives(t: float) -> None:
    check_derivatives(WAYPOINTS, t)


@pytest.mark.parametrize("p", POINTS, ids=lambda p: f"t={p.t:g}")
def test_waypoints_rest_at_each_point_and_join_c2(p: Setpoint) -> None:
    at = WAYPOINTS.sample(p.t)
    assert tuple(a[0] for a in at) == pytest.approx((p.x, p.y, p.z, p.psi), abs=1e-12)
    for a in at:
        assert a[1] == pytest.approx(0.0, abs=1e-12) and a[2] == pytest.approx(0.0, abs=1e-12)
    d = 1e-9
    before, after = WAYPOINTS.sample(p.t - d), WAYPOINTS.sample(p.t + d)
    for b, a in zip(before, after, strict=True):
        for k, tol in ((0, 1e-8), (1, 1e-7), (2, 1e-6)):  # value, velocity, acceleration continuous
            assert abs(b[k] - a[k]) <= tol, (p.t, k, b[k], a[k])


def test_waypoints_hold_outside_their_times_and_reject_bad_times() -> None:
    first, last = POINTS[0], POINTS[-1]
    assert WAYPOINTS.sample(0.0) == tuple((v, 0.0, 0.0, 0.0, 0.0) for v in (first.x, first.y, first.z, first.psi))
    assert WAYPOINTS.sample(99.0) == tuple((v, 0.0, 0.0, 0.0, 0.0) for v in (last.x, last.y, last.z, last.psi))
    assert WAYPOINTS.change_times() == (0.0,)
    with pytest.raises(ValueError):
        Waypoints((Setpoint(3.0, 0, 0, 0), Setpoint(2.0, 1, 1, 1)))


def test_waypoints_are_minimum_jerk() -> None:
    """Half-way through a segment the blend is at the middle, at its top speed 15/8 d/T."""
    a, b = POINTS[1], POINTS[2]
    T = b.t - a.t
    mid = WAYPOINTS.sample(a.t + T / 2)
    assert mid[0][0] == pytest.approx((a.x + b.x) / 2)
    assert mid[0][1] == pytest.approx(15 / 8 * (b.x - a.x) / T)
    assert mid[0][2] == pytest.approx(0.0, abs=1e-12)


def test_a_prefetched_reference_is_the_reference_computed_once_a_time() -> None:
    """Prefetched gives the reference's own samples; a time asked for again (or computed ahead) is not computed
    again; another time is."""
    sine = Sine()
    calls: list[float] = []

    def counted(t: float):
        calls.append(t)
        return sine.sample(t)

    ref = Prefetched(counted)
    for k in range(50):
        t = k / 250.0
        assert ref(t) == sine.sample(t)
        assert ref(t) == sine.sample(t)  # the row's second look: no computation
        ref.ahead((k + 1) / 250.0)  # the next step's, before it is asked for
    assert calls == [k / 250.0 for k in range(51)]  # each time once: t = 0 by the first call, the rest ahead
