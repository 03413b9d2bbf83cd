"""Covers bridge.core.wire.

The wire's frame conventions (bridge.core.wire): NWU <-> NED, ODOMETRY fields, actuators, time keys."""

from __future__ import annotations

import struct
from math import pi

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.core.wire import (
    command_from_wire,
    command_to_wire,
    odometry_to_state,
    paper_to_ned,
    rotate,
    rotate_inverse,
    state_to_odometry,
    step_of_usec,
    step_usec,
)
from controller.bsst import wrap_angle

finite = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)
angle = st.floats(min_value=-pi + 1e-6, max_value=pi)
# Z-Y-X Euler angles are singular at pitch = +-90 deg; the round trip is only defined away from it
tilt = st.floats(min_value=-1.5, max_value=1.5)
states = st.tuples(finite, finite, finite, finite, finite, finite, tilt, finite, tilt, finite, angle, finite)


def _close(a, b, tol):
    return all(abs(x - y) <= tol * (1.0 + abs(y)) for x, y in zip(a, b, strict=True))


@settings(max_examples=400, deadline=None)
@given(states)
def test_odometry_round_trip(X):
    """paper -> ODOMETRY fields -> paper returns the state (psi wrapped)."""
    back = odometry_to_state(*state_to_odometry(X))
    assert _close(back[:10], X[:10], 1e-9)
    assert abs(wrap_angle(back[10] - X[10])) < 1e-9
    assert abs(back[11] - X[11]) < 1e-9 * (1.0 + abs(X[11]))


@settings(max_examples=200, deadline=None)
@given(states)
def test_odometry_round_trip_through_float32(X):
    """What the controller sees: every field rounded to float32 on the wire."""
    pos, q, vel, rates = state_to_odometry(X)

    def f32(v):
        return tuple(struct.unpack(f"<{len(v)}f", struct.pack(f"<{len(v)}f", *v)))

    back = odometry_to_state(f32(pos), f32(q), f32(vel), f32(rates))
    assert _close(back[0:6:2], X[0:6:2], 1e-6)  # positions


@settings(max_examples=200, deadline=None)
@given(st.tuples(angle, tilt, angle), st.tuples(finite, finite, finite))
def test_rotation_is_orthogonal(euler, v):
    from bridge.core.wire import euler_to_quaternion

    q = euler_to_quaternion(*euler)
    assert _close(rotate_inverse(q, rotate(q, v)), v, 1e-12)
    n = sum(c * c for c in v) ** 0.5
    assert abs(sum(c * c for c in rotate(q, v)) ** 0.5 - n) < 1e-9 * (1.0 + n)


def test_ned_frd_signs():
    """docs/design.md, "Frames and units": north = x, east = -y, down = -z; pitch = -theta, yaw = -psi."""
    X = (1.0, 0.5, 2.0, 0.0, 3.0, -0.25, 0.1, 0.0, 0.2, 0.0, 0.3, 0.0)
    n = paper_to_ned(X)
    assert n["pos"] == (1.0, -2.0, -3.0)
    assert _close(n["euler"], (0.1, -0.2, -0.3), 1e-15)
    pos, q, vel, _ = state_to_odometry(X)
    assert pos == (1.0, -2.0, -3.0)
    # level, heading north: body FRD velocity is NED velocity
    pos, q, vel, _ = state_to_odometry((0, 1.0, 0, -2.0, 0, 3.0, 0, 0, 0, 0, 0, 0))
    assert _close(vel, (1.0, 2.0, -3.0), 1e-15)
    # yawed 90 deg left (psi = +pi/2, nose west): flying west is flying forward
    pos, q, vel, _ = state_to_odometry((0, 0.0, 0, 1.0, 0, 0.0, 0, 0, 0, 0, pi / 2, 0))
    assert _close(vel, (1.0, 0.0, 0.0), 1e-12)
    # yaw rate: psi' > 0 (counter-clockwise from above) is r < 0 in FRD
    *_, rates = state_to_odometry((0,) * 11 + (0.5,))
    assert _close(rates, (0.0, 0.0, -0.5), 1e-15)
    # level: the pitch rate follows pitch = -theta, so q = -theta'
    *_, rates = state_to_odometry((0,) * 9 + (0.4, 0, 0))
    assert _close(rates, (0.0, -0.4, 0.0), 1e-15)


@pytest.mark.parametrize("act", ["wrench", "motors"])
@settings(max_examples=100, deadline=None)
@given(c=st.tuples(*[st.floats(-1, 1)] * 4))
def test_actuator_round_trip(act, c):
    assert command_from_wire(act, command_to_wire(act, c)) == c


@given(st.integers(0, 10**9), st.sampled_from([50.0, 100.0, 250.0, 300.0, 333.0, 400.0, 500.0, 1000.0]))
def test_step_time_key(k, rate):
    """time_usec carries the step exactly: both sides recompute t_k = k / rate."""
    assert step_of_usec(step_usec(k, rate), rate) == k


def test_the_fast_state_over_wire_is_the_definition_to_the_bit():
    """bridge.core.wire.state_over_wire (written out for speed) against its definition: state_to_odometry,
    each field rounded to float32, odometry_to_state; bit for bit, over attitudes up to +-3 rad and yaw wraps."""
    import random

    from bridge.core.wire import state_over_wire, state_over_wire_reference

    rng = random.Random(5)
    for _ in range(20000):
        X = tuple(rng.uniform(-3.0, 3.0) * (30.0 if j in (0, 2, 4) else 1.0) for j in range(12))
        assert state_over_wire(X) == state_over_wire_reference(X), X


def test_each_flat_half_is_its_definition_to_the_bit():
    """The vehicle sends ODOMETRY by odometry_fields and the controller reads it by state_from_odometry_fields
    (one call each on the lockstep's hot path): each half bit for bit its definition (state_to_odometry;
    odometry_to_state of the float32 fields as the wire carries them), over attitudes up to +-3 rad."""
    import random

    from bridge.core.wire import odometry_fields, state_from_odometry_fields

    f32 = struct.Struct("<13f")
    rng = random.Random(25)
    for _ in range(20000):
        X = tuple(rng.uniform(-3.0, 3.0) * (30.0 if j in (0, 2, 4) else 1.0) for j in range(12))
        pos, q, vel, rates = state_to_odometry(X)
        f = odometry_fields(X)
        assert f == (*pos, *q, *vel, *rates), X
        w = f32.unpack(f32.pack(*f))
        assert state_from_odometry_fields(w) == odometry_to_state(w[0:3], w[3:7], w[7:10], w[10:13]), X
