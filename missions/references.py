"""Trajectory references with analytic derivatives up to the 4th.

In:  a reference's parameters (set-points and waypoints: x, y, z in m, psi in rad, each with its time
     in s; the sine's amplitude m, omega rad/s, climb m/s, z0 m, psi rad), then a time t (s)
Out: ``sample(t)``: for x, y, z (m) and psi (rad) each (value, 1st, 2nd, 3rd, 4th derivative)
     (m/s .. m/s⁴, rad/s .. rad/s⁴); ``change_times()`` (s); ``to_dict()`` the ``[trajectory]`` table;
     :class:`Prefetched`, a reference's newest sample kept (and the next computed ahead)

Every reference maps time t (s) to four axes (x, y, z, psi), each a tuple
(value, 1st, 2nd, 3rd, 4th derivative) in the paper's frame (z up, psi counter-clockwise).
The BS-ST law needs them all: the x/y virtual controls use the reference's snap.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

Derivs = tuple[float, float, float, float, float]
Sample = tuple[Derivs, Derivs, Derivs, Derivs]
ZERO: Derivs = (0.0, 0.0, 0.0, 0.0, 0.0)


class Reference(Protocol):
    """A trajectory: ``sample(t)`` gives (x, y, z, psi), each with 4 derivatives."""

    def sample(self, t: float) -> Sample: ...

    def change_times(self) -> tuple[float, ...]:
        """Times at which the reference jumps (set-point changes); (0.0,) for smooth ones."""
        ...

    def to_dict(self) -> dict:
        """The ``[trajectory]`` table that defines this reference."""
        ...


def _const(v: float) -> Derivs:
    return (v, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Setpoint:
    """Position (m) and heading (rad) to hold from time t (s), paper frame."""

    t: float
    x: float
    y: float
    z: float
    psi: float = 0.0


def _sp_dict(s: Setpoint) -> dict:
    return {"t": s.t, "x": s.x, "y": s.y, "z": s.z, "psi": s.psi}


@dataclass(frozen=True)
class Step:
    """Piecewise-constant set-points: each holds from its time until the next one's."""

    setpoints: tuple[Setpoint, ...]

    def __post_init__(self) -> None:
        if not self.setpoints:
            raise ValueError("Step needs at least one set-point")
        times = [s.t for s in self.setpoints]
        if times != sorted(times) or len(set(times)) != len(times):
            raise ValueError("Step set-point times must be strictly increasing")
        object.__setattr__(self, "_times", times)

    def sample(self, t: float) -> Sample:
        i = max(bisect.bisect_right(self._times, t) - 1, 0)  # type: ignore[attr-defined]
        s = self.setpoints[i]
        return (_const(s.x), _const(s.y), _const(s.z), _const(s.psi))

    def change_times(self) -> tuple[float, ...]:
        return tuple(s.t for s in self.setpoints)

    def to_dict(self) -> dict:
        return {"kind": "step", "setpoints": [_sp_dict(s) for s in self.setpoints]}


def _sinusoid(amp: float, w: float, phase: float, t: float) -> Derivs:
    a = w * t + phase
    s = math.sin(a)
    c = math.cos(a)
    return (amp * s, amp * w * c, -amp * w * w * s, -amp * w**3 * c, amp * w**4 * s)


@dataclass(frozen=True)
class Sine:
    """The paper's second scenario: x = x0 + A sin(w t), y = y0 + A cos(w t), z = z0 + climb t, psi const
    (x0, y0: a centre moved off the origin, as a vehicle of a formation flies it; 0 in the paper)."""

    amplitude: float = 1.0
    omega: float = 0.5
    climb: float = 0.1
    z0: float = 0.0
    psi: float = 0.0
    x0: float = 0.0
    y0: float = 0.0

    def sample(self, t: float) -> Sample:
        x = _sinusoid(self.amplitude, self.omega, 0.0, t)
        y = _sinusoid(self.amplitude, self.omega, math.pi / 2, t)
        if self.x0 or self.y0:  # (only then: the paper's centre adds nothing, not even a -0.0 turned 0.0)
            x, y = (x[0] + self.x0, *x[1:]), (y[0] + self.y0, *y[1:])
        return (x, y, (self.z0 + self.climb * t, self.climb, 0.0, 0.0, 0.0), _const(self.psi))

    def change_times(self) -> tuple[float, ...]:
        return (0.0,)

    def to_dict(self) -> dict:
        d = {"kind": "sine", "amplitude": self.amplitude, "omega": self.omega, "climb": self.climb,
             "z0": self.z0, "psi": self.psi}
        return d | ({"x0": self.x0, "y0": self.y0} if self.x0 or self.y0 else {})  # the paper's: as before


def _min_jerk(p0: float, p1: float, T: float, tau: float) -> Derivs:
    """Quintic minimum-jerk blend from p0 to p1 over T, at tau in [0, T], rest to rest."""
    s = min(max(tau / T, 0.0), 1.0)
    d = p1 - p0
    s2 = s * s
    s3 = s2 * s
    return (
        p0 + d * (10 * s3 - 15 * s3 * s + 6 * s3 * s2),
        d * (30 * s2 - 60 * s3 + 30 * s2 * s2) / T,
        d * (60 * s - 180 * s2 + 120 * s3) / T**2,
        d * (60 - 360 * s + 360 * s2) / T**3,
        d * (-360 + 720 * s) / T**4,
    )


@dataclass(frozen=True)
class Waypoints:
    """Waypoints joined by minimum-jerk (quintic) segments, at rest at each waypoint.

    ``points`` are Setpoints; the vehicle holds the first until its time, then blends to
    each next one, arriving at that point's time.
    """

    points: tuple[Setpoint, ...]

    def __post_init__(self) -> None:
        if len(self.points) < 1:
            raise ValueError("Waypoints needs at least one point")
        times = [p.t for p in self.points]
        if times != sorted(times) or len(set(times)) != len(times):
            raise ValueError("waypoint times must be strictly increasing")
        object.__setattr__(self, "_times", times)

    def sample(self, t: float) -> Sample:
        pts = self.points
        i = bisect.bisect_right(self._times, t)  # type: ignore[attr-defined]
        if i == 0:
            a = pts[0]
            return (_const(a.x), _const(a.y), _const(a.z), _const(a.psi))
        if i >= len(pts):
            a = pts[-1]
            return (_const(a.x), _const(a.y), _const(a.z), _const(a.psi))
        a, b = pts[i - 1], pts[i]
        T = b.t - a.t
        tau = t - a.t
        return (
            _min_jerk(a.x, b.x, T, tau),
            _min_jerk(a.y, b.y, T, tau),
            _min_jerk(a.z, b.z, T, tau),
            _min_jerk(a.psi, b.psi, T, tau),
        )

    def change_times(self) -> tuple[float, ...]:
        return (0.0,)

    def to_dict(self) -> dict:
        return {"kind": "waypoints", "points": [_sp_dict(p) for p in self.points]}


class Prefetched:
    """A reference's samples with the newest kept: asked for the same time t (s) again, the sample is returned, not
    computed again, and :meth:`ahead` computes the next one before it is asked for (a lockstep controller does it
    after its command is out, off the step's critical path). The reference must be a function of t alone (every
    :class:`Reference` here is)."""

    __slots__ = ("_sample", "_t", "_s")

    def __init__(self, sample: Callable[[float], Sample]) -> None:
        self._sample = sample
        self._t = math.nan  # (nan equals nothing: the first call computes)
        self._s: Sample | None = None

    def __call__(self, t: float) -> Sample:
        if t == self._t:
            return self._s  # type: ignore[return-value]
        s = self._s = self._sample(t)
        self._t = t
        return s

    def ahead(self, t: float) -> None:
        """Compute the sample at t (s) now, for a later call at that time."""
        self(t)
