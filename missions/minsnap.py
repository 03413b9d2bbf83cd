"""Minimum-snap trajectories through waypoints: 7th-order polynomials, stops where asked.

In:  knots (t s, x, y, z m, psi rad in the paper frame, and whether the vehicle stops there), solved once
Out: :class:`Smooth`, a :class:`~missions.references.Reference`: ``sample(t)`` gives each axis with its
     1st to 4th derivatives (m/s .. m/s⁴, rad/s .. rad/s⁴); :func:`demands` the thrust (N) and tilt
     (rad) the law will need along it; ``to_dict()`` the ``[trajectory]`` table (``kind = "smooth"``);
     :func:`yaw_rate_peaks` and ``snap_yaw_rate(t)`` (rad/s) for the route's timing

Each segment between two knots is, per axis, a polynomial of degree 7 in the normalised time
s = (t - t_j) / T_j. The polynomials pass through every knot. At a knot the vehicle stops at (the
first, the last, a hold, a takeoff or a landing) velocity, acceleration and jerk are zero on both
sides; at any other knot (a pass-through waypoint) the derivatives 1 to 6 are continuous. With only
the positions fixed there, this is exactly the minimum of the integrated squared snap: the
Euler-Lagrange condition makes each piece a 7th-order polynomial and the free knots C⁶ (Mellinger and
Kumar, "Minimum snap trajectory generation and control for quadrotors", ICRA 2011; Richter, Bry and Roy,
"Polynomial trajectory planning for aggressive quadrotor flight in dense indoor environments", ISRR
2013, the unconstrained form). So the coefficients are one square linear system, 8 unknowns a segment;
the four axes share its matrix. In normalised time they do not change when every duration is stretched
by the same factor, which is how :func:`stretched` slows a trajectory: derivative k scales by 1/factor^k.

The system (:func:`solve`), with p_j⁽ᵐ⁾(s) = T_j⁻ᵐ sum_k k!/(k-m)! c_jk s^(k-m) (m/s^m):

- segment j's positions: p_j(0) = x_j, p_j(1) = x_j+1;
- a stop at knot i: T^m p⁽ᵐ⁾ = 0, m = 1, 2, 3, on each side (T that side's duration);
- a pass-through knot i: u^m (p_i-1⁽ᵐ⁾(1) - p_i⁽ᵐ⁾(0)) = 0, m = 1 .. 6, u = (T_i-1 + T_i)/2.

Every row is in units of position, so the rows are conditioned alike. Ordered knot by knot (knot i's
rows, then segment i's two), each row touches at most the segments i-1 and i: the matrix is banded.
Gaussian elimination with partial pivoting runs over it one segment (8 columns) at a time on a window
of 11 rows (3 carried from the last step, 2 positions, the 6 of the next knot) by 16 columns (this
segment and the next): no row outside the window has a nonzero in those columns, so the pivots are
those of the dense elimination (LAPACK's gesv), and so is its stability, at O(n) time and memory
(LAPACK's gbsv does the same). Stops need no second path: a stop's rows touch one segment each, so
the runs between stops come out independent. (Hermite data at the knots as unknowns, derivatives 1 to
3, with continuity of 4 to 6 as a 3×3 block-tridiagonal system, was tried: it cancels where a short
segment lies between long ones, the error growing as about (T_long/T_short)^7 eps: 5e-9 of the
coefficients at a ratio of 10, 5e-5 at 100, against at most 1e-12 here.)

The yaw is not flown on its minimum-snap polynomial (:func:`yaw_pieces`): that one overshoots between knots (on
a plan's straight leg, whose two guide knots both hold the leg's heading, by up to 12°; 29° round an out-and-back
waypoint). Each segment's yaw is a quintic Hermite piece instead, its second derivative zero at both knots (so
psi, psi' and psi'', which the law uses, are continuous; psi''' and psi'''' are each piece's own, and jump at the
knots): at a stop (and the first and last knot) the rate is zero; elsewhere it is the harmonic mean of the two
neighbouring segments' mean rates when they turn the same way, else zero. With both end rates within twice the
segment's mean rate (the harmonic mean's bound) a quintic piece is monotone, so the yaw never passes its knots'
values: it holds a value two knots share (a straight leg's heading) exactly, and turns one way between others.
Until the third wave's forty-fourth session the yaw was the polynomial's, as the positions are. The minimum-snap
yaw is kept (``snap_yaw_rate``): the route still times its legs by it, so that every position is what it was, to
the bit.
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


def knot_arrays(knots: tuple[Knot, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The knots' times (s), yaws (rad) and stops, as arrays (:func:`yaw_pieces`)."""
    return (np.array([k.t for k in knots]), np.array([k.psi for k in knots]),
            np.array([k.stop for k in knots], dtype=bool))


def _falling(k: int, m: int) -> float:
    """k (k-1) ... (k-m+1): the m-th derivative's factor of s^k."""
    return _FACT[k] / _FACT[k - m] if k >= m else 0.0


_FALLING = [[_falling(k, m) for k in range(ORDER)] for m in range(ORDER - 1)]  # [m][k]: k!/(k-m)!, 0 for k < m
_AT_END = np.array(_FALLING)  # row m: derivative m at s = 1
_AT_START = np.diag([float(f) for f in _FACT[:ORDER - 1]] + [0.0])[:ORDER - 1]  # s = 0: m! at k = m
_M = np.arange(1, ORDER - 1)  # derivative orders of a pass-through's rows (1..6); a stop's are its first 3
_WINDOW = 11  # rows carried (3) + a segment's positions (2) + a knot's (6)


def _knot_rows(knots: tuple[Knot, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Each knot's 6 rows (module docstring), as their parts on the segment ending there (``left``) and the
    one starting there (``right``), each (n+1, 6, 8 coefficients). A stop's rows 0-2 are its left side's,
    3-5 its right side's; the first knot has no left rows, the last no right rows (zero rows)."""
    n = len(knots) - 1
    T = np.diff([k.t for k in knots])
    free = np.array([not (k.stop or i in (0, n)) for i, k in enumerate(knots)])
    left, right = np.zeros((n + 1, 6, ORDER)), np.zeros((n + 1, 6, ORDER))
    left[1:, :3], right[:-1, 3:] = _AT_END[1:4], _AT_START[1:4]  # stops: T^m p^(m) = d^m p/ds^m
    i = np.flatnonzero(free)
    if len(i):
        u = 0.5 * (T[i - 1] + T[i])
        left[i] = ((u / T[i - 1])[:, None] ** _M)[:, :, None] * _AT_END[1:]
        right[i] = -((u / T[i])[:, None] ** _M)[:, :, None] * _AT_START[1:]
    return left, right


def _eliminate(W: np.ndarray) -> None:
    """Gaussian elimination with partial pivoting, in place, of the first 8 columns of the window ``W``
    (11 rows; this segment's 8 columns, the next one's, the 4 right sides): rows 0-7 become the pivot rows
    (upper triangular in the first 8 columns), rows 8-10 zero there."""
    for c in range(ORDER):
        p = c + int(np.argmax(np.abs(W[c:, c])))
        if p != c:
            W[[c, p]] = W[[p, c]]
        W[c + 1:, c:] -= np.outer(W[c + 1:, c] / W[c, c], W[c, c:])


def solve(knots: tuple[Knot, ...]) -> np.ndarray:
    """Coefficients, shape (segments, 4 axes, 8), of the minimum-snap polynomials in normalised time: the
    module docstring's banded system, eliminated segment by segment, then solved back."""
    n = len(knots) - 1
    pos = np.array([(k.x, k.y, k.z, k.psi) for k in knots])  # (n+1, 4): the right sides of the positions
    left, right = _knot_rows(knots)
    U = np.empty((n, ORDER, 2 * ORDER + 4))  # each segment's pivot rows: its columns, the next's, right sides
    carried = np.zeros((3, 2 * ORDER + 4))  # the rows left over, in the next segment's columns
    carried[:, ORDER:2 * ORDER] = right[0, 3:]  # the first knot's rest
    with np.errstate(divide="ignore", invalid="ignore"):  # a singular system: NaN, refused by Smooth
        for j in range(n):
            W = np.zeros((_WINDOW, 2 * ORDER + 4))
            W[:3, :ORDER], W[:3, 2 * ORDER:] = carried[:, ORDER:2 * ORDER], carried[:, 2 * ORDER:]
            W[3, 0], W[3, 2 * ORDER:] = 1.0, pos[j]  # p_j(0) = x_j
            W[4, :ORDER], W[4, 2 * ORDER:] = 1.0, pos[j + 1]  # p_j(1) = x_j+1
            W[5:, :ORDER], W[5:, ORDER:2 * ORDER] = left[j + 1], right[j + 1]
            _eliminate(W)
            U[j], carried = W[:ORDER], W[ORDER:]
        c = np.zeros((n + 1, ORDER, 4))  # c[n]: no segment, zero
        for j in range(n - 1, -1, -1):
            c[j] = np.linalg.solve(U[j, :, :ORDER], U[j, :, 2 * ORDER:] - U[j, :, ORDER:2 * ORDER] @ c[j + 1])
    return c[:n].transpose(0, 2, 1)


def yaw_pieces(t: np.ndarray, psi: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Coefficients, shape (segments, 8), of the yaw's quintic Hermite pieces in normalised time (module
    docstring) through knots at times ``t`` (s) of yaw ``psi`` (rad), ``stop`` where at rest: rate zero at stops
    and the ends, else the harmonic mean of the neighbouring mean rates (zero where they differ in sign or one is
    zero), psi'' zero at every knot."""
    T, D = np.diff(t), np.diff(psi)
    rate = np.zeros(len(t))
    if len(t) > 2:
        a, b = D[:-1] / T[:-1], D[1:] / T[1:]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            mean = np.where(a * b > 0.0, 2.0 * a * b / (a + b), 0.0)
        rate[1:-1] = np.where(stop[1:-1], 0.0, mean)
    m0, m1 = rate[:-1] * T, rate[1:] * T  # per normalised time
    c = np.zeros((len(T), ORDER))
    c[:, 0], c[:, 1] = psi[:-1], m0
    c[:, 3] = 10.0 * D - 6.0 * m0 - 4.0 * m1
    c[:, 4] = -15.0 * D + 8.0 * m0 + 7.0 * m1
    c[:, 5] = 6.0 * D - 3.0 * (m0 + m1)
    return c


def yaw_rate_peaks(t: np.ndarray, psi: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """The largest |psi'| (rad/s) over each segment of :func:`yaw_pieces`' yaw, exactly: at an end, or where
    psi'' = s (6 c3 + 12 c4 s + 20 c5 s²) / T² is zero inside."""
    c, T = yaw_pieces(t, psi, stop), np.diff(t)
    qa, qb, qc = 20.0 * c[:, 5], 12.0 * c[:, 4], 6.0 * c[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(qb * qb - 4.0 * qa * qc)
        linear = -qc / qb
        at = [np.zeros_like(T), np.ones_like(T), (-qb + root) / (2.0 * qa), (-qb - root) / (2.0 * qa),
              np.where(qa == 0.0, linear, np.nan)]
    peak = np.zeros_like(T)
    for s in at:
        s = np.where((s >= 0.0) & (s <= 1.0), s, 0.0)  # outside the segment (or NaN): its start instead
        peak = np.maximum(peak, np.abs(c[:, 1] + 3.0 * c[:, 3] * s**2 + 4.0 * c[:, 4] * s**3 + 5.0 * c[:, 5] * s**4))
    return peak / T


def _derivs(c: tuple[float, ...], s: float, T: float) -> Derivs:
    """Value and derivatives 1..4 (per second) at s of the polynomial sum c_k s^k over a segment of T s."""
    out = []
    for m in range(5):
        f, acc = _FALLING[m], 0.0
        for k in range(ORDER - 1, m - 1, -1):
            acc = acc * s + c[k] * f[k]
        out.append(acc / T**m)
    return (out[0], out[1], out[2], out[3], out[4])


@dataclass(frozen=True)
class Smooth:
    """The minimum-snap trajectory through ``knots`` (at least two, times strictly increasing).

    Before the first knot it rests at the first; after the last, at the last. ``lands``: the last knot
    is a touchdown (the flight ends landed and disarmed there); ``stretched_by``: the factor its times
    were slowed by to fit the airframe (:func:`stretched`), 1 if not."""

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
        snap_yaw = tuple(tuple(float(v) for v in coeffs[j, 3]) for j in range(len(coeffs)))
        coeffs[:, 3] = yaw_pieces(*knot_arrays(self.knots))  # the yaw flown: monotone between knots (module docstring)
        table = tuple(tuple(tuple(float(v) for v in coeffs[j, a]) for a in range(4)) for j in range(len(coeffs)))
        object.__setattr__(self, "_times", times)
        object.__setattr__(self, "_coeffs", table)
        object.__setattr__(self, "_snap_yaw", snap_yaw)

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

    def snap_yaw_rate(self, t: float) -> float:
        """psi' (rad/s) at t of the minimum-snap yaw through the knots, which is not flown (module docstring):
        the route times its legs by it, as it did when it was flown."""
        times: list[float] = self._times  # type: ignore[attr-defined]
        if t <= times[0] or t >= times[-1]:
            return 0.0
        j = bisect.bisect_right(times, t) - 1
        T = times[j + 1] - times[j]
        return _derivs(self._snap_yaw[j], (t - times[j]) / T, T)[1]  # type: ignore[attr-defined]

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
