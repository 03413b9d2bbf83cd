"""Minimum-snap trajectories through waypoints: 7th-order polynomials, stops where asked.

In:  knots (t s, x, y, z m, psi rad in the paper frame, and whether the vehicle stops there), solved once
Out: :class:`Smooth`, a :class:`~missions.references.Reference`: ``sample(t)`` gives each axis with its
     1st to 4th derivatives (m/s .. m/s⁴, rad/s .. rad/s⁴); :func:`demands` the thrust (N) and tilt
     (rad) the law will need along it; ``to_dict()`` the ``[trajectory]`` table (``kind = "smooth"``)

Each segment between two knots is, per axis, a polynomial of degree 7 in the normalised time
s = (t - t_j) / T_j. The polynomials pass through every knot. At a knot the vehicle stops at (the
first, the last, a hold, a takeoff or a landing) velocity, acceleration and jerk are zero on both
sides; at any other knot (a pass-through waypoint) the derivatives 1 to 6 are continuous. With only
the positions fixed there, this is exactly the minimum of the integrated squared snap: the
Euler-Lagrange condition makes each piece a 7th-order polynomial and the free knots C⁶ (Mellinger and
Kumar, "Minimum snap trajectory generation and control for quadrotors", ICRA 2011; Richter, Bry and Roy,
"Polynomial trajectory planning for aggressive quadrotor flight in dense indoor environments", ISRR
2013, the unconstrained form). So the coefficients are one square linear system, solved with numpy;
the four axes share its matrix. In normalised time they do not change when every duration is stretched
by the same factor, which is how :func:`stretch_to_fit` slows a trajectory: derivative k scales by 1/factor^k.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from missions.references import Derivs, Sample

ORDER = 8  # coefficients per segment and axis (degree 7)
_FACT = [math.factorial(k) for k in range(ORDER)]


@dataclass(frozen=True)
class Knot:
    """A point the trajectory passes at time t (s), paper frame (m, rad); ``stop``: at rest there."""

    t: float
    x: float
    y: float
    z: float
    psi: float = 0.0
    stop: bool = False


def _falling(k: int, m: int) -> float:
    """k (k-1) ... (k-m+1): the m-th derivative's factor of s^k."""
    return _FACT[k] / _FACT[k - m] if k >= m else 0.0


def solve(knots: tuple[Knot, ...]) -> np.ndarray:
    """Coefficients, shape (segments, 4 axes, 8), of the minimum-snap polynomials in normalised time."""
    n = len(knots) - 1
    durations = [knots[j + 1].t - knots[j].t for j in range(n)]
    A = np.zeros((ORDER * n, ORDER * n))
    B = np.zeros((ORDER * n, 4))
    row = 0

    def put(j: int, s: float, m: int, scale: float) -> np.ndarray:
        """The row fragment of derivative m (per second^m) at s of segment j, times ``scale``."""
        frag = np.zeros(ORDER * n)
        T = durations[j]
        for k in range(m, ORDER):
            frag[ORDER * j + k] = scale * _falling(k, m) * (s ** (k - m)) / T**m
        return frag

    for j in range(n):  # positions at both ends of every segment
        a, b = knots[j], knots[j + 1]
        A[row] = put(j, 0.0, 0, 1.0)
        B[row] = (a.x, a.y, a.z, a.psi)
        A[row + 1] = put(j, 1.0, 0, 1.0)
        B[row + 1] = (b.x, b.y, b.z, b.psi)
        row += 2
    for i in range(n + 1):
        stop = knots[i].stop or i in (0, n)
        if stop:  # at rest: velocity, acceleration and jerk zero on each side there is
            for m in (1, 2, 3):
                for j, s in ((i - 1, 1.0), (i, 0.0)):
                    if 0 <= j < n:
                        u = durations[j] ** m  # rows in units of position: conditioned alike
                        A[row] = put(j, s, m, u)
                        row += 1
        else:  # a pass-through: derivatives 1..6 continuous
            u_ref = 0.5 * (durations[i - 1] + durations[i])
            for m in range(1, ORDER - 1):
                A[row] = put(i - 1, 1.0, m, u_ref**m) - put(i, 0.0, m, u_ref**m)
                row += 1
    assert row == ORDER * n
    return np.linalg.solve(A, B).reshape(n, ORDER, 4).transpose(0, 2, 1)


def _derivs(c: tuple[float, ...], s: float, T: float) -> Derivs:
    """Value and derivatives 1..4 (per second) at s of the polynomial sum c_k s^k over a segment of T s."""
    out = []
    for m in range(5):
        acc = 0.0
        for k in range(ORDER - 1, m - 1, -1):
            acc = acc * s + c[k] * _falling(k, m)
        out.append(acc / T**m)
    return (out[0], out[1], out[2], out[3], out[4])


@dataclass(frozen=True)
class Smooth:
    """The minimum-snap trajectory through ``knots`` (at least two, times strictly increasing).

    Before the first knot it rests at the first; after the last, at the last. ``lands``: the last knot
    is a touchdown (the flight ends landed and disarmed there); ``stretched_by``: the factor its times
    were slowed by to fit the airframe (:func:`stretch_to_fit`), 1 if not."""

    knots: tuple[Knot, ...]
    lands: bool = False
    stretched_by: float = 1.0

    def __post_init__(self) -> None:
        if len(self.knots) < 2:
            raise ValueError("a smooth trajectory needs at least two knots")
        times = [k.t for k in self.knots]
        if any(b <= a for a, b in zip(times, times[1:])) or not all(math.isfinite(t) for t in times):
            raise ValueError("knot times must be finite and strictly increasing")
        coeffs = solve(self.knots)
        if not np.isfinite(coeffs).all():
            raise ValueError("the minimum-snap system has no finite solution")
        table = tuple(tuple(tuple(float(v) for v in coeffs[j, a]) for a in range(4)) for j in range(len(coeffs)))
        object.__setattr__(self, "_times", times)
        object.__setattr__(self, "_coeffs", table)

    def sample(self, t: float) -> Sample:
        times: list[float] = self._times  # type: ignore[attr-defined]
        if t <= times[0] or t >= times[-1]:
            k = self.knots[0] if t <= times[0] else self.knots[-1]
            return ((k.x, 0.0, 0.0, 0.0, 0.0), (k.y, 0.0, 0.0, 0.0, 0.0), (k.z, 0.0, 0.0, 0.0, 0.0),
                    (k.psi, 0.0, 0.0, 0.0, 0.0))
        j = bisect.bisect_right(times, t) - 1
        T = times[j + 1] - times[j]
        s = (t - times[j]) / T
        c = self._coeffs[j]  # type: ignore[attr-defined]
        return (_derivs(c[0], s, T), _derivs(c[1], s, T), _derivs(c[2], s, T), _derivs(c[3], s, T))

    @property
    def end_s(self) -> float:
        """Time of the last knot (s)."""
        return self.knots[-1].t

    def change_times(self) -> tuple[float, ...]:
        return (0.0,)

    def to_dict(self) -> dict:
        d: dict = {"kind": "smooth", "lands": self.lands}
        if self.stretched_by != 1.0:
            d["stretched_by"] = self.stretched_by
        d["points"] = [{"t": k.t, "x": k.x, "y": k.y, "z": k.z, "psi": k.psi, "stop": k.stop} for k in self.knots]
        return d


@dataclass(frozen=True)
class Demand:
    """The most the law will need along a trajectory to follow it exactly (rigid body, no drag)."""

    thrust_n: float
    thrust_t: float  # s: where
    tilt_rad: float
    tilt_t: float


def accelerations(ref: Smooth, per_segment: int = 64) -> list[tuple[float, float, float, float]]:
    """(t s, ax, ay, az m/s²) sampled ``per_segment`` times a segment and at every knot."""
    out = []
    times = [k.t for k in ref.knots]
    for j in range(len(times) - 1):
        for i in range(per_segment + 1):
            t = times[j] + (times[j + 1] - times[j]) * i / per_segment
            x, y, z, _ = ref.sample(t)  # a knot's end: the next piece (continuous, or at rest on both sides)
            out.append((t, x[2], y[2], z[2]))
    return out


def demands(ref: Smooth, mass: float, gravity: float, factor: float = 1.0,
            samples: list[tuple[float, float, float, float]] | None = None) -> Demand:
    """The thrust (N) and tilt from vertical (rad) the trajectory needs at most, its times stretched by
    ``factor`` (accelerations / factor²), over :func:`accelerations` (``samples``, if already taken)."""
    thrust = tilt = t_thrust = t_tilt = 0.0
    t0 = ref.knots[0].t
    for t, ax, ay, az in samples if samples is not None else accelerations(ref):
        ax, ay, az = ax / factor**2, ay / factor**2, az / factor**2 + gravity
        f = mass * math.sqrt(ax * ax + ay * ay + az * az)
        a = math.atan2(math.hypot(ax, ay), az)
        if f > thrust:
            thrust, t_thrust = f, t0 + (t - t0) * factor
        if a > tilt:
            tilt, t_tilt = a, t0 + (t - t0) * factor
    return Demand(thrust, t_thrust, tilt, t_tilt)


def stretched(ref: Smooth, factor: float) -> Smooth:
    """The same path with every knot time (from the first) times ``factor``."""
    t0 = ref.knots[0].t
    knots = tuple(Knot(t0 + (k.t - t0) * factor, k.x, k.y, k.z, k.psi, k.stop) for k in ref.knots)
    return Smooth(knots, ref.lands, ref.stretched_by * factor)
