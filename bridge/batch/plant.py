"""The plant of :class:`plant.quadrotor.Quadrotor` for the batch: N cells' start, and one cell's step, compiled.

In:  one profile and one set of effects for every cell, a seed per cell (the disturbance's phases), the
     physics rate (Hz), the start state (eq. 7: m, m/s, rad, rad/s); per cell and physics step its state, what
     its command holds (u1..u4 N and omega_d rad/s, or target rotor speeds rad/s), the time (s), its steady
     wind plus the turbulence's sample and gusts (m/s, s, rad), its rotors' effectiveness (0..1), its battery's
     charge (mAh, A s) and speed cap
Out: :class:`BatchPlant`: the start (states [12, N], rotor speeds, what a command at rest holds, the
     constants); per cell the state after a physics step, its disturbance, divergence

The same model as the scalar plant: eq. (6) corrected, RK4 with the inputs held over a physics step,
drag, motor lag, rotor faults, the battery's sag, the external disturbance, mass and inertia mismatch, steady
wind, Dryden turbulence (the scalar generator's samples: bridge.batch.weather) and 1 - cos gusts (drag on the
airspeed, rotor drag), and the ground plane. The step of
each cell is the scalar plant's own :func:`plant.model.rk4_held` and
:func:`plant.quadrotor.ground_contact`, and a ``wrench`` command is held through
:func:`plant.rotors.wrench_command` and eq. (4)/(5) as the scalar plant holds it, compiled
(bridge.batch.kernels).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.batch import kernels as K
from plant.battery import pack_constants
from plant.effects import Effects
from plant.model import RigidBody, rigid_body
from plant.profiles import Profile
from plant.quadrotor import CRASH_SPEED_MPS, CRASH_TILT_RAD


class BatchPlant:
    """N quadrotors of one profile and effects, each with its own start (``state`` [12, n]), command and disturbance
    phases."""

    def __init__(self, profile: Profile, effects: Effects | None, seeds: Sequence[int], *, physics_hz: float,
                 state: np.ndarray, ground: bool = True, faulty: bool = False) -> None:
        e = effects or Effects()
        self.profile = profile
        self.effects = e
        n = len(seeds)
        self.n = n
        def body(drag: tuple) -> RigidBody:
            return rigid_body(
                mass=profile.mass * e.mass_scale, ixx=profile.ixx * e.inertia_scale,
                iyy=profile.iyy * e.inertia_scale, izz=profile.izz * e.inertia_scale, arm=profile.arm,
                rotor_inertia=profile.rotor_inertia, gravity=profile.gravity, drag=drag)

        self.body = body(profile.drag if e.drag else (0.0,) * 6)
        self.body_air = body(profile.drag)  # a cell in a [wind]: the air acts through the drag (plant.Quadrotor)
        self.dt = 1.0 / physics_hz
        self.ground = ground
        self.t = 0.0
        self.X = np.array(state, float)  # [12, n]: each flight's own start
        self.motors = profile.actuation == "motors"
        self.lagged = self.motors and e.motor_lag
        # a command holds rotor speeds (not their wrench) under motor lag, or when a rotor may fail (``faulty``:
        # the wrench then comes from the speeds and each rotor's effectiveness at every physics step)
        self.faulty = self.motors and faulty
        battery = profile.battery if e.battery and self.motors else None  # (Quadrotor builds one so)
        self.battery = battery is not None
        # (battery?, plant.battery.pack_constants, the rotors' drag-torque factor N m s^2, the full pack's V)
        self.pack = (self.battery, pack_constants(battery) if battery else (1.0,) * 6,
                     profile.drag_coeff * profile.arm, battery.full_v if battery else 1.0)
        self.speeds = self.lagged or self.faulty or self.battery
        self._lag_k = 1.0 - math.exp(-self.dt / profile.motor_time_constant)
        d = e.disturbance
        self.disturbed = d.active
        if self.disturbed:
            self._phases = np.array([d.phases(s) for s in seeds]).T  # [6, N]
            self._const = np.array(d.force_const + d.torque_const)[:, None]
            self._amp = np.array(d.force_amp + d.torque_amp)[:, None]
            self._ext_t = math.nan  # the time of the disturbance in _ext[2]
        # the disturbance at a step's start, middle and end ([3, 6, N]; a stand-in [3, 6, 1] when there is none)
        self._ext = np.zeros((3, 6, n if self.disturbed else 1))
        hover = profile.hover_omega
        self.omega = np.full((4, n), hover if self.motors else 0.0)
        self.target = self.omega.copy()
        self._u = np.zeros((5, n))  # what the step integrates with: the realised u1..u4 (N) and omega_d (rad/s)
        self.realised = self._u[:4]
        self.omega_d = self._u[4]
        # what a command holds (see held): the target speeds (motor lag, faults), else the rows of _u
        self.holding = self.target if self.speeds else self._u
        self._u_max = tuple(float(v) for v in profile.u_max)
        self.hold(self.held(np.zeros((4, n))))

    # -- actuation -------------------------------------------------------------------------------------
    def held(self, c: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """What :meth:`Quadrotor.command` holds for normalised commands c [4, k]: ``wrench`` and ``motors``
        without lag or faults the realised u1..u4 (N) and omega_d (rad/s), [5, k]; ``motors`` with lag or
        faults (:attr:`speeds`) the four target speeds (rad/s), [4, k]. Into ``out`` if given (and returned)."""
        p = self.profile
        if not self.motors:
            if out is None:
                out = np.empty((5, c.shape[1]))
            _held_wrench(np.ascontiguousarray(c), self._u_max, p.thrust_coeff, p.drag_coeff, out)
            return out
        target = np.minimum(np.maximum(c, 0.0), 1.0) * p.omega_max
        v = target if self.speeds else np.vstack(self._from_speeds(target))
        if out is None:
            return v
        out[...] = v
        return out

    def _from_speeds(self, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (4) and (5): rotor speeds [4, k] -> (realised u [4, k], omega_d [1, k])."""
        p = self.profile
        b, d = p.thrust_coeff, p.drag_coeff
        w = omega * omega
        u = np.stack((b * (w[0] + w[1] + w[2] + w[3]), b * (w[3] - w[1]), b * (w[2] - w[0]),
                      d * (w[1] + w[3] - w[0] - w[2])))
        return u, (omega[1] + omega[3] - omega[0] - omega[2])[None, :]

    def hold(self, values: np.ndarray, cols: np.ndarray | slice | None = None) -> None:
        """Hold what :meth:`held` gave for the cells ``cols`` (all by default) until their next command."""
        self.holding[:, slice(None) if cols is None else cols] = values


# -- one cell (what the whole flight's kernel, bridge.batch.flight, runs per cell) ------
@njit(cache=True, inline="always")
def rk4_cell(x: tuple, u: tuple, ext: tuple, disturbed: bool, constants: tuple, h: float, ground: bool,
             air: tuple, windy: bool) -> tuple:  # pragma: no cover
    """:func:`plant.model.rk4_held` of one cell's state x (eq. 7) with u = (u1..u4 N, omega_d rad/s) held and the
    external force and torque ext at the step's start, middle and end (read only when ``disturbed``), in the
    air ``air`` = (wind m/s NWU, rotor drag s/m) where ``windy`` (else still air: the paper's eq. 6), then
    :func:`plant.quadrotor.ground_contact` where ``ground`` and below it. (The state, and whether this step
    touched the ground hard: faster than CRASH_SPEED_MPS or tilted more than CRASH_TILT_RAD, as
    :meth:`plant.quadrotor.Quadrotor._touchdown` judges it on the state below the ground.)"""
    if windy:
        if disturbed:
            y = K.rk4_held(x, u[0], u[1], u[2], u[3], u[4], constants, h, ext, air)
        else:
            y = K.rk4_held(x, u[0], u[1], u[2], u[3], u[4], constants, h, None, air)
    elif disturbed:
        y = K.rk4_held(x, u[0], u[1], u[2], u[3], u[4], constants, h, ext)
    else:
        y = K.rk4_held(x, u[0], u[1], u[2], u[3], u[4], constants, h, None)
    hard = False
    if ground and y[4] < 0.0:
        speed = math.sqrt(y[1] * y[1] + y[3] * y[3] + y[5] * y[5])
        tilt = math.acos(max(-1.0, min(1.0, math.cos(y[6]) * math.cos(y[8]))))
        hard = speed > CRASH_SPEED_MPS or tilt > CRASH_TILT_RAD
        y = K.ground_contact(y)
    return y, hard


@njit(cache=True, inline="always")
def wind_cell(steady: tuple, gusts: np.ndarray, n_gusts: int, t: float) -> tuple:  # pragma: no cover
    """:meth:`plant.wind.Wind.now` of one cell: ``steady`` (m/s NWU: the steady wind, plus the turbulence's sample
    where the cell meets turbulence, as the scalar plant adds it) plus each gust
    (gusts[g] = t_s s, duration_s s, amplitude_mps m/s, from_deg in rad) at t (s), as
    :meth:`plant.wind.Gust.velocity` and :func:`plant.wind.blowing` compute it."""
    wx, wy, wz = steady
    for g in range(n_gusts):
        s = t - gusts[g, 0]
        if s <= 0.0 or s >= gusts[g, 1]:
            wx, wy, wz = wx + 0.0, wy + 0.0, wz + 0.0  # the gust's (0, 0, 0), added as the scalar plant adds it
            continue
        m = 0.5 * gusts[g, 2] * (1.0 - math.cos(2.0 * math.pi * s / gusts[g, 1]))
        b = gusts[g, 3]
        wx, wy, wz = wx + -m * math.cos(b), wy + m * math.sin(b), wz + 0.0
    return wx, wy, wz


@njit(cache=True, inline="always")
def disturbance_cell(freq_hz: float, const: tuple, amp: tuple, phases: tuple, t: float) -> tuple:  # pragma: no cover
    """:func:`plant.effects.disturbance_at` (fx, fy, fz N, tx, ty, tz N m) at t (s) for one cell's phases."""
    w = 2.0 * math.pi * freq_hz * t
    return (const[0] + amp[0] * math.sin(w + phases[0]), const[1] + amp[1] * math.sin(w + phases[1]),
            const[2] + amp[2] * math.sin(w + phases[2]), const[3] + amp[3] * math.sin(w + phases[3]),
            const[4] + amp[4] * math.sin(w + phases[4]), const[5] + amp[5] * math.sin(w + phases[5]))


@njit(cache=True, inline="always")
def from_speeds(o: tuple, b: float, d: float) -> tuple:  # pragma: no cover
    """Eq. (4) and (5) of one cell: rotor speeds (rad/s) -> (u1..u4 N, omega_d rad/s), as
    :meth:`BatchPlant._from_speeds` computes them."""
    w0, w1, w2, w3 = o[0] * o[0], o[1] * o[1], o[2] * o[2], o[3] * o[3]
    return (b * (w0 + w1 + w2 + w3), b * (w3 - w1), b * (w2 - w0), d * (w1 + w3 - w0 - w2), o[1] + o[3] - o[0] - o[2])


@njit(cache=True, inline="always")
def realised_cell(om: tuple, eff: tuple, faulty: bool, b: float, d: float) -> tuple:  # pragma: no cover
    """(u1..u4 N, omega_d rad/s) of rotor speeds om (rad/s): eq. (4)/(5), with each rotor's effectiveness ``eff``
    where the batch is ``faulty`` (:func:`plant.rotors.wrench_from_degraded_rotors`, as Quadrotor._set_omega)."""
    if faulty:
        r = K.wrench_from_degraded_rotors(om, eff, b, d)
        return (r[0], r[1], r[2], r[3], K.signed_speed_sum(om))
    return from_speeds(om, b, d)


@njit(cache=True, inline="always")
def events_cell(j: int, k: int, steady: tuple, eff: tuple, next_event: np.ndarray, event_step: np.ndarray,
                events: np.ndarray) -> tuple:  # pragma: no cover
    """Cell j's events that act at control step k (bridge.batch.weather: SimVehicle.inject's ``motor`` and
    ``wind``; the arrays of bridge.batch.flight.Cells): (the steady wind m/s NWU, the rotors' effectiveness 0..1)
    after them."""
    e = next_event[j]
    while e < event_step.shape[1] and event_step[j, e] <= k:
        v = events[j, e]
        if v[0] == 0.0:  # EV_MOTOR: rotor v[1] (0-3) at effectiveness v[2]
            r, x = int(v[1]), v[2]
            eff = (x if r == 0 else eff[0], x if r == 1 else eff[1], x if r == 2 else eff[2], x if r == 3 else eff[3])
        else:  # EV_WIND: the steady wind from now (Wind.set_steady)
            steady = (v[1], v[2], v[3])
        e += 1
    next_event[j] = e
    return steady, eff


@njit(cache=True, inline="always")
def targets_cell(q: tuple, cap: float, omega_max: float) -> tuple:  # pragma: no cover
    """:meth:`Quadrotor.command`'s target speeds (rad/s) under a battery: clip(c_i, 0, cap) * omega_max for the
    normalised command q (its first four), and a 0."""
    return (K.clip(q[0], 0.0, cap) * omega_max, K.clip(q[1], 0.0, cap) * omega_max,
            K.clip(q[2], 0.0, cap) * omega_max, K.clip(q[3], 0.0, cap) * omega_max, 0.0)


@njit(cache=True, inline="always")
def battery_cell(hold: tuple, om: tuple, pk: tuple, lagged: bool, pack: tuple, torque_factor: float, h: float,
                 full_v: float, omega_max: float) -> tuple:  # pragma: no cover
    """:meth:`Quadrotor._draw_battery` of one cell: the pack (pk: used mAh, drawn A s, cap) feeds the rotors at
    their speeds now (om under motor lag, else the held targets) over h (:func:`plant.battery.pack_step`); the
    targets ``hold`` above the new cap come down to it. (hold, pk) after it."""
    speeds = om if lagged else (hold[0], hold[1], hold[2], hold[3])
    v, _, drawn, used = K.pack_step(pack, pk[0], pk[1], speeds, torque_factor, h)
    cap = min(v / full_v, 1.0)
    top = cap * omega_max
    hold = (top if hold[0] > top else hold[0], top if hold[1] > top else hold[1], top if hold[2] > top else hold[2],
            top if hold[3] > top else hold[3], hold[4])
    return hold, (used, drawn, cap)


@njit(cache=True, inline="always")
def held_cell(c: tuple, motors: bool, speeds: bool, u_max: tuple, b: float, d: float,
              omega_max: float) -> tuple:  # pragma: no cover
    """:meth:`BatchPlant.held` of one cell's normalised command c: (u1..u4, omega_d), or where the plant holds
    ``speeds`` (motor lag, faults) the four target speeds (rad/s) and a 0."""
    if not motors:
        u = K.wrench_command(c, u_max)
        return (u[0], u[1], u[2], u[3], K.signed_speed_sum(K.motor_speeds_from_wrench(u, b, d)))
    o = (_unit(c[0]) * omega_max, _unit(c[1]) * omega_max, _unit(c[2]) * omega_max, _unit(c[3]) * omega_max)
    if speeds:
        return (o[0], o[1], o[2], o[3], 0.0)
    return from_speeds(o, b, d)


@njit(cache=True, inline="always")
def _unit(v: float) -> float:  # pragma: no cover
    """np.minimum(np.maximum(v, 0), 1): a nan stays a nan."""
    v = 0.0 if v < 0.0 else v
    return 1.0 if v > 1.0 else v


@njit(cache=True, inline="always")
def diverged_cell(x: tuple) -> bool:  # pragma: no cover
    """:meth:`Quadrotor.diverged` of one cell's state: not finite, |position| > 100 m, or tilt beyond 90 degrees."""
    for i in range(12):
        if not math.isfinite(x[i]):
            return True
    if x[0] * x[0] + x[2] * x[2] + x[4] * x[4] > 1e4:
        return True
    # cos > 0.07 within 1.5 rad (< pi/2): the product is positive there without its two cos calls a step
    return not (abs(x[6]) < 1.5 and abs(x[8]) < 1.5) and math.cos(x[6]) * math.cos(x[8]) < 0.0


# -- the compiled loops (each cell: the scalar plant's own functions, compiled) ----------------------------
@njit(cache=True)
def _held_wrench(c, u_max, b, d, out):  # pragma: no cover
    """The ``wrench`` profile's :meth:`BatchPlant.held` per cell (c [4, k] -> out [5, k]): :func:`held_cell`."""
    for j in range(c.shape[1]):
        v = held_cell((c[0, j], c[1, j], c[2, j], c[3, j]), False, False, u_max, b, d, 0.0)
        for i in range(5):
            out[i, j] = v[i]
