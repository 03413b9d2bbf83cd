"""The air the vehicle flies through: steady wind, Dryden turbulence and discrete 1 − cos gusts (pure, seeded).

In:  a mission's ``[wind]`` table (``speed_mps`` m/s, ``from_deg`` the compass direction it blows FROM,
     ``turbulence`` none|light|moderate|severe, ``turbulence_scaling`` exact|none, ``altitude_m`` m, ``gusts``
     [[t_s, duration_s, amplitude_mps, from_deg]]), the mission's duration (s), a seed, the physics step (s)
Out: the wind velocity (m/s, paper frame NWU: x north, y west, z up) held over each physics step, and its
     statistics over the flight (the ``wind`` block of ``summary.json``); the turbulence's samples of a whole
     flight (:func:`turbulence_series`, m/s NWU per physics step: what the batch engine flies); the ``[wind]``
     gusts as the lines that say them (:meth:`WindConfig.gust_notes`: mission time s, text)

Every formula and number, with its source: docs/weather.md.

- **Steady wind** from compass bearing β (clockwise from north) blows toward β + 180°: in NWU it is
  ``speed · (−cos β, sin β, 0)``.
- **Dryden turbulence** (MIL-F-8785C §3.7.2, MIL-HDBK-1797 low altitude, h in ft, 10 ≤ h ≤ 1000):
  σ_w = 0.1 W20, σ_u = σ_v = σ_w / (0.177 + 0.000823 h)^0.4, L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2,
  W20 (the wind at 20 ft) 15, 30, 45 kt for light, moderate, severe. The velocity spectra, one-sided in ω
  (rad/s) for a frozen field passed at the speed V, are
  Φ_u(ω) = σ_u² (2 L_u / π V) / (1 + (L_u ω / V)²) and
  Φ_v(ω) = σ_v² (L_v / π V) (1 + 3 (L_v ω / V)²) / (1 + (L_v ω / V)²)² (w as v with L_w, σ_w).
  u runs along the mean wind, v across it (horizontal), w up. V is the mean wind speed (the vehicle
  roughly holds station: the air passes it at the mean wind), at least :data:`MIN_PASS_SPEED_MPS`.
- The shaping filters are discretized **exactly**: u is the Ornstein-Uhlenbeck process
  u_{k+1} = e^{−ah} u_k + σ √(1 − e^{−2ah}) n_k (a = V/L); v and w are the second-order filter
  H(s) = σ √(L/V) (1 + √3 (L/V) s) / (1 + (L/V) s)² in state space, stepped with its matrix exponential
  and the exact covariance of the noise it integrates over h (Q_d = ∫₀ʰ e^{Aτ} B Bᵀ e^{Aᵀτ} dτ, in closed
  form). Each filter starts in its stationary distribution, so the turbulence is stationary from t = 0.
- **Scaling** (``turbulence_scaling``): ``exact`` (the default) flies the filters' samples over the mission as
  one record, each axis shifted to a zero mean and scaled to its σ (:class:`TurbulenceRecord`: TurbSim's
  ScaleIEC), then on through the filters, free, should the flight outlast its mission; ``none`` flies them as
  they come (a 30 s flight's sample then strays by seconds-long correlation).
- **Gusts** (MIL-F-8785C §3.7.4, the 1 − cos shape of CS-25.341): from t_s for duration_s,
  ``amplitude/2 · (1 − cos(2π (t − t_s) / duration))`` along the gust's direction, then nothing.

**Seeding.** The turbulence draws from its own numpy ``Generator`` seeded with (seed, :data:`_DOMAIN`):
apart from the sensors' and the link's streams, so adding wind changes neither.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from params import ConfigError, Table, finite_float
from plant.events import EVENT_RANGES, TimedEvent, range_problem, ranged_number, start_problem

FT = 0.3048  # m per foot
KT = 1852.0 / 3600.0  # m/s per knot
TURBULENCE = ("none", "light", "moderate", "severe")
SCALING = ("exact", "none")  # [wind] turbulence_scaling: the flight's record scaled to the asked σ, or free-running
W20_KT = {"light": 15.0, "moderate": 30.0, "severe": 45.0}  # MIL-F-8785C fig. 11 / MIL-HDBK-1797: W20 by level
LOW_ALTITUDE_FT = (10.0, 1000.0)  # the low-altitude model's range of h
MIN_PASS_SPEED_MPS = 1.0  # the frozen field passes the vehicle at least this fast (no mean wind: still defined)
_DOMAIN = 0x3D1D  # keeps the turbulence's stream apart from any other use of the seed
# [wind]'s numbers' [lo, hi]: the events' table's (plant.events.EVENT_RANGES: one range and unit per key, said alike)
WIND_RANGES = {k: EVENT_RANGES[k][:2] for k in ("speed_mps", "from_deg", "altitude_m")}
GUST_SHAPE = "[t_s, duration_s, amplitude_mps] or [t_s, duration_s, amplitude_mps, from_deg] (from_deg 0 if left out)"

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Gust:
    """A discrete 1 − cos gust: starts at ``t_s`` (s), lasts ``duration_s`` (s), peaks at ``amplitude_mps``
    (m/s) half-way, blowing from compass ``from_deg``."""

    t_s: float
    duration_s: float
    amplitude_mps: float
    from_deg: float = 0.0

    def velocity(self, t: float) -> Vec3:
        """The gust's wind (m/s, NWU) at time t (s)."""
        s = t - self.t_s
        if s <= 0.0 or s >= self.duration_s:
            return (0.0, 0.0, 0.0)
        m = 0.5 * self.amplitude_mps * (1.0 - math.cos(2.0 * math.pi * s / self.duration_s))
        return blowing(m, self.from_deg)


@dataclass(frozen=True, slots=True)
class WindConfig:
    """One ``[wind]`` table, validated (:func:`wind_from_table`). ``altitude_m`` None: the flight's own
    (:func:`bridge.core.flight.prepare` sets the mean height of the reference)."""

    speed_mps: float = 0.0
    from_deg: float = 0.0
    turbulence: str = "none"
    altitude_m: float | None = None
    gusts: tuple[Gust, ...] = ()
    scaling: str = "exact"  # SCALING: exact (TurbulenceRecord) or none (the free-running filters)
    record_s: float = 60.0  # the record's length (s) under exact scaling: the mission's duration (wind_from_table)
    # the steady wind a wind event at the flight's first control step sets, flown from the start in place of
    # speed_mps, from_deg (which stay the turbulence's pass speed and axes): (m/s, deg, where the event was given)
    start: tuple[float, float, str] | None = None

    def at_altitude(self, altitude_m: float) -> WindConfig:
        return replace(self, altitude_m=altitude_m)

    def as_table(self) -> dict:
        d: dict = {"speed_mps": self.speed_mps, "from_deg": self.from_deg, "turbulence": self.turbulence,
                   "turbulence_scaling": self.scaling}
        if self.altitude_m is not None:
            d["altitude_m"] = self.altitude_m
        if self.gusts:
            d["gusts"] = [[g.t_s, g.duration_s, g.amplitude_mps, g.from_deg] for g in self.gusts]
        return d

    def gust_notes(self) -> tuple[tuple[float, str], ...]:
        """Its gusts as the lines that say them (mission time s, the text of an ``--at`` gust's event and where it
        was given), in time order: the vehicle's ``wind`` event and a flight's ``not_reached`` line, as an ``--at``
        gust has (the gust itself is flown from its exact t_s by :class:`Wind`)."""
        said = [(g.t_s, TimedEvent(g.t_s, "gust", (("duration_s", g.duration_s), ("amplitude_mps", g.amplitude_mps),
                                                   ("from_deg", g.from_deg))).text() + f" ([wind] gusts[{i}])")
                for i, g in enumerate(self.gusts)]
        return tuple(sorted(said, key=lambda n: n[0]))


def blowing(speed: float, from_deg: float) -> Vec3:
    """The NWU velocity (m/s) of a wind of ``speed`` blowing FROM compass bearing ``from_deg``."""
    b = math.radians(from_deg)
    return (-speed * math.cos(b), speed * math.sin(b), 0.0)


def wind_from_table(t: Table, duration_s: float) -> WindConfig:
    """Validate a mission's ``[wind]`` table (errors name the file and key)."""
    speed = ranged_number(t, "speed_mps", 0.0)  # (its range and unit: the wind event's)
    from_deg = ranged_number(t, "from_deg", 0.0)
    level = t.string("turbulence", "none", choices=TURBULENCE)
    scaling = t.string("turbulence_scaling", "exact", choices=SCALING)
    altitude = ranged_number(t, "altitude_m") if t.has("altitude_m") else None
    raw = t.raw("gusts", [])
    if not isinstance(raw, list):
        raise t.error("gusts", f"expected a list of gusts, each {GUST_SHAPE}")
    gusts = tuple(gust_from_list(g, f"{t.key('gusts')}[{i}]", t, duration_s) for i, g in enumerate(raw))
    t.done()
    return WindConfig(speed, from_deg, level, altitude, gusts, scaling, duration_s)


def gust_from_list(g: object, where: str, t: Table, duration_s: float) -> Gust:
    """One gust ``[t_s, duration_s, amplitude_mps]`` or with ``from_deg``; ConfigError naming ``where``."""
    if (not isinstance(g, (list, tuple)) or len(g) not in (3, 4)
            or not all(isinstance(v, float) or finite_float(v) is not None for v in g)):  # (float(): no overflow)
        raise ConfigError(f"{t._source}: {where}: expected {GUST_SHAPE}, got {g!r}"[:300])
    ts, dur, amp = float(g[0]), float(g[1]), float(g[2])
    frm = float(g[3]) if len(g) == 4 else 0.0
    problems = [("t_s", start_problem(ts, duration_s)),
                *((k, range_problem(k, v)) for k, v in (("duration_s", dur), ("amplitude_mps", amp),
                                                        ("from_deg", frm)))]  # the events' ranges and texts
    for key, why in problems:
        if why is not None:
            raise ConfigError(f"{t._source}: {where}: {key}: {why}")
    return Gust(ts, dur, amp, frm)


def dryden_low_altitude(level: str, altitude_m: float) -> tuple[float, float, float, float, float, float]:
    """(σ_u, σ_v, σ_w m/s, L_u, L_v, L_w m) of MIL-F-8785C / MIL-HDBK-1797 low-altitude turbulence at
    ``altitude_m`` (clamped to 10-1000 ft, the model's range); all 0 for ``none``."""
    if level == "none":
        return (0.0,) * 6  # type: ignore[return-value]
    h = min(max(altitude_m / FT, LOW_ALTITUDE_FT[0]), LOW_ALTITUDE_FT[1])  # ft
    s = 0.177 + 0.000823 * h
    sigma_w = 0.1 * W20_KT[level] * KT
    sigma_uv = sigma_w / s**0.4
    l_uv = h / s**1.2 * FT
    return (sigma_uv, sigma_uv, sigma_w, l_uv, l_uv, h * FT)


def _tail(x: float, n: int) -> float:
    """1 − e^{−x} Σ_{k=0..n} x^k/k! (the regularised lower incomplete gamma P(n+1, x)), accurate for small x."""
    if x < 1.0:  # the series e^{−x} Σ_{k>n} x^k/k!: no cancellation
        term = x ** (n + 1) / math.factorial(n + 1)
        total, k = 0.0, n + 1
        while term > 1e-18 * total or total == 0.0:
            total += term
            k += 1
            term *= x / k
            if term == 0.0:
                break
        return math.exp(-x) * total
    return 1.0 - math.exp(-x) * sum(x**k / math.factorial(k) for k in range(n + 1))


def dryden_second_order(a: float, h: float) -> tuple[tuple[float, ...], tuple[float, float, float]]:
    """The exact step over h of x' = A x + B η, A = [[0, 1], [−a², −2a]], B = (0, 1), η white of unit
    two-sided density: (e^{Ah} row-major, the lower Cholesky factor (l11, l21, l22) of Q_d)."""
    e = math.exp(-a * h)
    phi = (e * (1.0 + a * h), e * h, -e * a * a * h, e * (1.0 - a * h))
    c = 2.0 * a
    x = c * h
    i0, i1, i2 = _tail(x, 0) / c, _tail(x, 1) / c**2, 2.0 * _tail(x, 2) / c**3  # ∫₀ʰ τⁿ e^{−cτ} dτ
    q11, q12, q22 = i2, i1 - a * i2, i0 - 2.0 * a * i1 + a * a * i2  # e^{Aτ}B = e^{−aτ} (τ, 1 − aτ)
    l11 = math.sqrt(q11)
    l21 = q12 / l11
    return phi, (l11, l21, math.sqrt(max(q22 - l21 * l21, 0.0)))


class Turbulence:
    """Dryden turbulence (u along the mean wind, v across, w up), stepped exactly every ``h`` s."""

    def __init__(self, level: str, altitude_m: float, pass_speed_mps: float, seed: int, h: float) -> None:
        self.sigma_u, self.sigma_v, self.sigma_w, self.l_u, self.l_v, self.l_w = dryden_low_altitude(level, altitude_m)
        self.speed = max(pass_speed_mps, MIN_PASS_SPEED_MPS)
        self.h = h
        self._gen = np.random.default_rng([seed, _DOMAIN])
        self._rows: list[list[float]] = []
        self._i = 0
        a_u = self.speed / self.l_u
        self._phi_u = math.exp(-a_u * h)
        self._k_u = self.sigma_u * math.sqrt(-math.expm1(-2.0 * a_u * h))
        self._vw = []
        n0 = self._normals()
        for sigma, length, (m1, m2) in ((self.sigma_v, self.l_v, (n0[1], n0[2])), (self.sigma_w, self.l_w,
                                                                                    (n0[3], n0[4]))):
            a = self.speed / length
            phi, chol = dryden_second_order(a, h)
            k = sigma / math.sqrt(a)  # σ √(L/V)
            out = (k * a * a, k * math.sqrt(3.0) * a)  # y = K (a² x1 + √3 a x2)
            state = [m1 / (2.0 * a * math.sqrt(a)), m2 / (2.0 * math.sqrt(a))]  # stationary: P = diag(1/4a³, 1/4a)
            self._vw.append((phi, chol, out, state))
        self.u = self.sigma_u * n0[0]
        self.v = self._output(0)
        self.w = self._output(1)

    def _normals(self) -> list[float]:
        if self._i >= len(self._rows):
            self._rows = self._gen.standard_normal((512, 5)).tolist()
            self._i = 0
        row = self._rows[self._i]
        self._i += 1
        return row

    def now(self) -> tuple[float, float, float]:
        """This physics step's (u, v, w), m/s."""
        return (self.u, self.v, self.w)

    def rescale(self, scale: list[float], offset: list[float]) -> None:
        """Map each filter's state so that its output y becomes scale · (y − offset) (u, v, w): the filters then
        continue a record so scaled without a jump. u is its own state; v and w shift x1 (y = K(a² x1 + √3 a
        x2): the offset over K a²) and scale both states."""
        self.u = scale[0] * (self.u - offset[0])
        for j in range(2):
            _, _, out, x = self._vw[j]
            c = scale[1 + j]
            x[0] = c * x[0] - c * offset[1 + j] / out[0]
            x[1] = c * x[1]
        self.v = self._output(0)
        self.w = self._output(1)

    def _output(self, j: int) -> float:
        _, _, out, x = self._vw[j]
        return out[0] * x[0] + out[1] * x[1]

    def advance(self) -> None:
        """Step the three filters over h."""
        n = self._normals()
        self.u = self._phi_u * self.u + self._k_u * n[0]
        for j, (m1, m2) in enumerate(((n[1], n[2]), (n[3], n[4]))):
            phi, (l11, l21, l22), _, x = self._vw[j]
            x0, x1 = x
            x[0] = phi[0] * x0 + phi[1] * x1 + l11 * m1
            x[1] = phi[2] * x0 + phi[3] * x1 + l21 * m1 + l22 * m2
        self.v = self._output(0)
        self.w = self._output(1)


class TurbulenceRecord:
    """Dryden turbulence as a flight's record (``turbulence_scaling = "exact"``, the default): the shaping
    filters' (:class:`Turbulence`) samples over ``steps`` physics steps, each axis then shifted to a zero mean
    and scaled to MIL-HDBK-1797's σ over the record, as TurbSim scales its records to the exact target σ
    (its ``ScaleIEC``) and as any FFT generator leaves a record's mean at the asked mean wind.

    Why: over a flight of T s, the part of Dryden's u slower than 1/T is, in the flight, a different mean wind
    (Reynolds' decomposition over T); at L_u/V = 4.6 s and T = 30 s one free-running sample strays ±1.7 m/s on
    the mean and ±28 % on σ_u (:func:`sampling_errors`), so "moderate" would be flown at 0.55-1.22 of its σ
    by seed. A record gives every flight the asked mean wind and σ; the spectrum's shape is the filters', its
    level the record's scale (reported: ``record.scale``). A flight longer than its record (a vehicle that
    flies on after its mission, a real-time vehicle's steps before it) flies on through the filters, free,
    from where the record ends (:meth:`Turbulence.rescale`: continuous), at one step's cost a step: no new
    record is worked out while a real-time vehicle flies."""

    def __init__(self, free: Turbulence, steps: int) -> None:
        self.free = free  # the filters: their σ, scales and step are the record's
        self.steps = max(int(steps), 2)
        raw = [(0.0, 0.0, 0.0)] * self.steps
        for k in range(self.steps):
            raw[k] = free.now()
            free.advance()
        x = np.array(raw, dtype=np.float64)
        mean = x.mean(axis=0)
        dev = x - mean
        std = np.sqrt((dev * dev).mean(axis=0))
        scale = np.array([free.sigma_u, free.sigma_v, free.sigma_w]) / std  # (a filter's output is never constant)
        self._rows = (dev * scale).tolist()
        self.first = {"mean": mean.tolist(), "std": std.tolist(), "scale": scale.tolist()}  # summary.json
        free.rescale(scale.tolist(), mean.tolist())  # its next sample continues the record's last
        self._k = 0  # the physics steps flown

    def now(self) -> list[float] | tuple[float, float, float]:
        """This physics step's (u, v, w), m/s: the record's, then the filters' (free) after it."""
        k = self._k
        return self._rows[k] if k < self.steps else self.free.now()

    def advance(self) -> None:
        if self._k >= self.steps:
            self.free.advance()
        self._k += 1

    @property
    def free_after_s(self) -> float:
        """How long the flight has flown past its record (s): through the filters, free."""
        return max(self._k - self.steps, 0) * self.free.h


class Wind:
    """The wind the plant flies through: :meth:`now` at a physics step's start (held over it), then
    :meth:`advance`. Its statistics (along, across the initial mean wind, up) accumulate at every step."""

    def __init__(self, config: WindConfig, seed: int, h: float) -> None:
        self.config = config
        self.steady = blowing(config.speed_mps, config.from_deg)
        self.gusts = list(config.gusts)
        b = math.radians(config.from_deg) if config.speed_mps > 0.0 else math.pi  # no wind: u points north
        self.along = (-math.cos(b), math.sin(b))  # unit vector the mean wind blows toward (x, y)
        self.across = (-self.along[1], self.along[0])  # 90° to the left of it (z up)
        self.turbulence: Turbulence | TurbulenceRecord | None = None
        if config.turbulence != "none":
            free = Turbulence(config.turbulence, config.altitude_m or 0.0, config.speed_mps, seed, h)
            self.turbulence = (TurbulenceRecord(free, round(config.record_s / h)) if config.scaling == "exact"
                               else free)
        self.h = h
        self._n = 0
        self._sum = [0.0] * 6  # Σ along, across, up, Σ of their squares
        self._sum_t = [0.0] * 6  # the same of the turbulence alone
        self.peak_mps = 0.0

    def set_steady(self, speed_mps: float, from_deg: float) -> None:
        """A change of the steady wind (an event): from the next physics step."""
        self.steady = blowing(speed_mps, from_deg)

    def add_gust(self, gust: Gust) -> None:
        self.gusts.append(gust)

    def now(self, t: float) -> Vec3:
        """The wind at t (m/s, NWU): steady + turbulence + gusts; counted in the statistics."""
        wx, wy, wz = self.steady
        tx = ty = tz = 0.0
        if self.turbulence is not None:
            tx, ty, tz = self.turbulence_now()
            wx, wy, wz = wx + tx, wy + ty, wz + tz
        for g in self.gusts:
            gx, gy, gz = g.velocity(t)
            wx, wy, wz = wx + gx, wy + gy, wz + gz
        self._count(wx, wy, wz, self._sum)
        self._count(tx, ty, tz, self._sum_t)
        self._n += 1
        speed = math.sqrt(wx * wx + wy * wy + wz * wz)
        if speed > self.peak_mps:
            self.peak_mps = speed
        return (wx, wy, wz)

    def turbulence_now(self) -> Vec3:
        """The turbulence's part of :meth:`now` (m/s, NWU): u along the initial mean wind, v across it, w up."""
        tu = self.turbulence
        if tu is None:
            return (0.0, 0.0, 0.0)
        (ax, ay), (cx, cy) = self.along, self.across
        u, v, w = tu.now()
        return (u * ax + v * cx, u * ay + v * cy, w)

    def _count(self, wx: float, wy: float, wz: float, s: list[float]) -> None:
        (ax, ay), (cx, cy) = self.along, self.across
        a, c = wx * ax + wy * ay, wx * cx + wy * cy
        s[0] += a
        s[1] += c
        s[2] += wz
        s[3] += a * a
        s[4] += c * c
        s[5] += wz * wz

    def advance(self) -> None:
        if self.turbulence is not None:
            self.turbulence.advance()

    def summary(self) -> dict:
        """The ``wind`` block: the configuration, the mean wind and the turbulence's std per axis over the
        flight (m/s, along / across the mean wind, up) with MIL-HDBK-1797's σ at the turbulence's altitude."""
        n = max(self._n, 1)
        mean = [s / n for s in self._sum[:3]]
        # the turbulence's mean is 0 by construction: its std is its RMS about 0 (unbiased for σ², where the
        # deviation about a sample mean loses the slow part of a process whose correlation time is seconds)
        std_t = [math.sqrt(self._sum_t[3 + i] / n) for i in range(3)]
        c = self.config
        out: dict = {**c.as_table(), "samples": self._n, "mean_mps": {"along": mean[0], "across": mean[1],
                                                                      "up": mean[2]},
                     "mean_speed_mps": math.hypot(mean[0], mean[1]), "peak_mps": self.peak_mps}
        if c.start is not None:  # the steady wind flown from the start: a t = 0 wind event's
            out["steady_at_start"] = {"speed_mps": c.start[0], "from_deg": c.start[1], "by": c.start[2]}
        rec = self.turbulence
        if rec is not None:
            tu = rec.free if isinstance(rec, TurbulenceRecord) else rec  # the filters: what was asked of them
            out["turbulence_std_mps"] = {"u": std_t[0], "v": std_t[1], "w": std_t[2]}
            out["dryden"] = {"sigma_mps": {"u": tu.sigma_u, "v": tu.sigma_v, "w": tu.sigma_w},
                             "scale_m": {"u": tu.l_u, "v": tu.l_v, "w": tu.l_w}, "pass_speed_mps": tu.speed,
                             "model_altitude_m": tu.l_w,  # L_w = h: the altitude in the model's range
                             "source": "MIL-F-8785C / MIL-HDBK-1797 low altitude"}
            if isinstance(rec, TurbulenceRecord):  # what was scaled: the free-running sample's own figures
                r = rec.first
                out["record"] = {"length_s": rec.steps * tu.h, "free_after_s": rec.free_after_s,
                                 "scale": dict(zip("uvw", r["scale"])),
                                 "removed_mean_mps": dict(zip("uvw", r["mean"]))}
                out["sampling"] = sampling_errors(tu, rec.steps * tu.h, r["std"], r["mean"][0])
            else:
                out["sampling"] = sampling_errors(tu, self._n * self.h, std_t, self._sum_t[0] / n)
        return out


def sampling_errors(tu: Turbulence, duration_s: float, std: list[float], mean_u: float) -> dict:
    """How far one flight's sample of the turbulence is expected to stray from the σ it was generated with.

    Over T seconds, a zero-mean Gaussian process of autocorrelation R has a sample mean of variance
    (1/T) ∫R dτ and a mean square (1/T ∫x²) of variance (2/T) ∫R² dτ (integrals over the whole line, T ≫ the
    correlation time L/V). Dryden's u (R = σ² e^{−Vτ/L}): std error of the mean σ √(2L/VT), relative std
    error of the sample σ √(L/2VT); v and w (R = σ² (1 − Vτ/2L) e^{−Vτ/L}): σ √(L/VT) and √(5L/16VT).
    ``z`` is (sample − asked) / its std error: beyond ±2 the generator, not the sample, would be suspect."""
    t = max(duration_s, 1e-9)
    v = tu.speed
    rel = {"u": math.sqrt(tu.l_u / (2.0 * v * t)), "v": math.sqrt(5.0 * tu.l_v / (16.0 * v * t)),
           "w": math.sqrt(5.0 * tu.l_w / (16.0 * v * t))}
    sig = {"u": tu.sigma_u, "v": tu.sigma_v, "w": tu.sigma_w}
    se_mean = tu.sigma_u * math.sqrt(2.0 * tu.l_u / (v * t))
    return {"duration_s": duration_s, "correlation_times": {k: t * v / ln for k, ln in
                                                            (("u", tu.l_u), ("v", tu.l_v), ("w", tu.l_w))},
            "mean_along_se_mps": se_mean, "mean_along_z": mean_u / se_mean,
            "std_rel_se": rel, "std_z": {k: (std[i] / sig[k] - 1.0) / rel[k] for i, k in enumerate("uvw")}}


def turbulence_series(config: WindConfig, seed: int, h: float, steps: int) -> np.ndarray:
    """[steps, 3]: the turbulence (m/s, NWU) :meth:`Wind.now` adds at each of a flight's first ``steps`` physics
    steps of ``h`` s, from this very generator (:class:`Wind`, the configuration and seed's stream), so that the
    batch engine flies the scalar plant's air sample for sample; zeros without turbulence."""
    wind = Wind(replace(config, gusts=()), seed, h)
    out = [(0.0, 0.0, 0.0)] * steps
    now, advance = wind.turbulence_now, wind.advance
    for k in range(steps):
        out[k] = now()
        advance()
    return np.array(out, dtype=np.float64).reshape(steps, 3)


def long_run(config: WindConfig, seed: int, duration_s: float = 3600.0, h: float = 0.02) -> dict:
    """The same filters (:class:`Wind`, the same configuration and seed's stream), free-running (a record scaled
    to σ would show σ by construction), over a long series: its mean wind along the mean direction and the
    turbulence's std per axis (m/s), with MIL-HDBK-1797's σ and the expected sampling errors over ``duration_s``.
    The exact discretization makes the statistics the same for any step h, so a coarser step than the flight's
    suffices; gusts are left out (they are not turbulence)."""
    wind = Wind(replace(config, gusts=(), scaling="none"), seed, h)
    for k in range(int(round(duration_s / h))):
        wind.now(k * h)
        wind.advance()
    s = wind.summary()
    return {"duration_s": duration_s, "step_s": h, "mean_along_mps": s["mean_mps"]["along"],
            "turbulence_std_mps": s.get("turbulence_std_mps"), "sigma_mps": s.get("dryden", {}).get("sigma_mps"),
            "sampling": s.get("sampling")}
