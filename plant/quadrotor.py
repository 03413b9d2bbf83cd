"""The stateful plant: a profile, its effects, rotors and the RK4 integrator.

The ground is the plane z = 0 (paper frame, z up; missions start there at rest); pass
``ground=False`` for free flight.

In:  a profile and its effects, the physics rate (Hz), a start state (eq. 7: m, m/s, rad, rad/s), the wind
     (:class:`plant.wind.WindConfig`, or None: still air); then a normalised command (held) per control
     period, faults (a rotor's effectiveness 0..1), and the disturbance's time 0 (plant time s,
     :attr:`Quadrotor.disturbance_t0`: 0 unless a real-time flight has not started yet, None)
Out: the state after each physics step, the realised wrench (N), the rotor speeds (rad/s), ground contact and
     a hard touchdown (impact speed m/s, tilt rad), the wind (m/s) and battery (V, A, mAh) statistics

One object with a small interface, in the RotorPy manner: :meth:`Quadrotor.command` sets
the actuator command (held until the next call: zero-order hold) and :meth:`Quadrotor.step`
advances one physics step. Commands are normalised and in the paper's frame:

- ``wrench`` profiles: (u1/u1_max, u2/u2_max, u3/u3_max, u4/u4_max), u1 part in [0, 1],
  the others in [-1, 1]; the plant applies them directly.
- ``motors`` profiles: c_i = omega_i / omega_max in [0, 1]; the plant clips, passes the
  speeds through the optional motor lag and realises eq. (4).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

from plant.battery import Battery
from plant.effects import Effects, disturbance_at
from plant.model import RigidBody, State, rigid_body, rk4_held, rk4_held_steps, state_derivative
from plant.profiles import Profile
from plant.rotors import (
    clip,
    motor_lag_step,
    motor_speeds_from_wrench,
    signed_speed_sum,
    wrench_command,
    wrench_from_degraded_rotors,
    wrench_from_motor_speeds,
)
from plant.wind import Wind, WindConfig

AT_REST: State = (0.0,) * 12  # type: ignore[assignment]
_STATE_BITS = struct.Struct("12d")  # a state's bits: -0.0 is not 0.0 here, as it is not in a trace's repr
_HELD_BITS = struct.Struct("6d")  # the inputs a step holds: the realised wrench, the rotors' speed sum, h


CRASH_SPEED_MPS = 2.0  # m/s: a touchdown faster than this breaks the vehicle (docs/weather.md "Outcomes")
CRASH_TILT_RAD = math.radians(30.0)  # rad: a touchdown tilted more than this lands on a rotor, not the legs
ENVELOPE_M = 100.0  # m from the origin (home): farther, the flight has diverged (the paper's missions stay within 10 m)


def ground_contact(X: tuple[float, ...]) -> State:
    """Contact with the ground plane z = 0 (the start height): the vehicle rests on its legs,
    level, keeping its heading; any upward velocity is kept so it can take off again."""
    return (X[0], 0.0, X[2], 0.0, 0.0, max(X[5], 0.0), 0.0, 0.0, 0.0, 0.0, X[10], 0.0)


class Quadrotor:
    """The simulated vehicle of eq. (6) with its actuation, at a fixed physics step."""

    def __init__(
        self,
        profile: Profile,
        effects: Effects | None = None,
        *,
        seed: int = 0,
        physics_hz: float = 1000.0,
        state: State = AT_REST,
        ground: bool = True,
        wind: WindConfig | None = None,
    ) -> None:
        self.profile = profile
        self.effects = effects or Effects()
        e = self.effects
        # in wind the air acts through the drag: a wind turns the profile's drag on, on the airspeed
        self.wind = Wind(wind, seed, 1.0 / physics_hz) if wind is not None else None
        self.body: RigidBody = rigid_body(
            mass=profile.mass * e.mass_scale,
            ixx=profile.ixx * e.inertia_scale,
            iyy=profile.iyy * e.inertia_scale,
            izz=profile.izz * e.inertia_scale,
            arm=profile.arm,
            rotor_inertia=profile.rotor_inertia,
            gravity=profile.gravity,
            drag=profile.drag if e.drag or wind is not None else (0.0,) * 6,
        )
        self.dt = 1.0 / physics_hz
        # one RK4 step with the inputs held: the plain function, or its compiled twin (bit for bit the same;
        # bridge.core.scalarkernels.compile_scalar)
        self.rk4: Callable[..., tuple[float, ...]] = rk4_held
        self.rk4_steps: Callable[..., tuple[tuple[float, ...], int]] = rk4_held_steps  # several steps, one call
        self.ground = ground
        self.t = 0.0
        self.state: State = tuple(float(v) for v in state)  # type: ignore[assignment]
        self._phases = e.disturbance.phases(seed)
        self._disturbed = e.disturbance.active
        # plant time (s) of the disturbance's time 0: the flight's (0 offline); None: it does not act yet (a real-time
        # vehicle's plant runs on the ground before its flight, whose time 0 is its first target: SimVehicle)
        self.disturbance_t0: float | None = 0.0
        self._lagged = profile.actuation == "motors" and e.motor_lag
        hover = profile.hover_omega
        self.omega: tuple[float, float, float, float] = (hover,) * 4 if profile.actuation == "motors" else (0.0,) * 4
        self._omega_target = self.omega
        self.realised: tuple[float, float, float, float] = (0.0,) * 4
        self._omega_d = 0.0
        self.effectiveness: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)  # each rotor's, 0..1
        self.battery = (Battery(profile.battery, e.battery_start_pct) if e.battery and profile.battery is not None
                        else None)
        self._speed_cap = 1.0  # the rotors' top speed now, a fraction of omega_max (the battery's sag)
        self.impact: tuple[float, float, float] | None = None  # the first hard touchdown: (t s, speed m/s, tilt rad)
        # a state that is its own step with the inputs held (at rest on the ground: :meth:`step`), and those inputs
        self._still: tuple[State, tuple[float, ...], Callable[..., tuple[float, ...]], bytes, bool] | None = None
        self._commanded: tuple[object, float, object] = (None, 0.0, None)  # the last command, speed cap, effectiveness
        self.command((0.0, 0.0, 0.0, 0.0))

    # -- actuation -----------------------------------------------------------------
    def command(self, c: tuple[float, float, float, float]) -> None:
        """Set the normalised actuator command (see module docstring); held until the next. The very command (the same
        tuple) given again with the rotors' speed cap and effectiveness unchanged changes nothing: not computed again
        (a vehicle on the ground is given its motors-off command each physics step of its disarm wait); a list or
        array, which its caller may fill again, is computed each time."""
        last = self._commanded
        if last[0] is c and type(c) is tuple and last[1] == self._speed_cap and last[2] is self.effectiveness:
            return
        self._commanded = (c, self._speed_cap, self.effectiveness)
        p = self.profile
        if p.actuation == "wrench":
            u = wrench_command(c, p.u_max)
            self.realised = u
            self.omega = motor_speeds_from_wrench(u, p.thrust_coeff, p.drag_coeff)
            self._omega_d = signed_speed_sum(self.omega)
        else:
            w = p.omega_max
            cap = self._speed_cap
            self._omega_target = tuple(clip(ci, 0.0, cap) * w for ci in c)  # type: ignore[assignment]
            if not self.effects.motor_lag:
                self._set_omega(self._omega_target)

    def _set_omega(self, omega: tuple[float, float, float, float]) -> None:
        p = self.profile
        self.omega = omega
        if self.effectiveness == (1.0, 1.0, 1.0, 1.0):
            self.realised = wrench_from_motor_speeds(omega, p.thrust_coeff, p.drag_coeff)
        else:
            self.realised = wrench_from_degraded_rotors(omega, self.effectiveness, p.thrust_coeff, p.drag_coeff)
        self._omega_d = signed_speed_sum(omega)

    def set_effectiveness(self, rotor: int, value: float) -> None:
        """Rotor ``rotor`` (1-4, eq. 4's numbering) gives ``value`` (0..1) of its thrust from now on (a fault)."""
        e = list(self.effectiveness)
        e[rotor - 1] = value
        self.effectiveness = tuple(e)  # type: ignore[assignment]
        if self.profile.actuation == "motors":
            self._set_omega(self.omega)

    # -- dynamics ------------------------------------------------------------------
    def derivative(self, t: float, X: State) -> State:
        """dX/dt at time t with the command held (eq. 6 plus the switched-on effects)."""
        u1, u2, u3, u4 = self.realised
        ext = None
        if self._disturbed and self.disturbance_t0 is not None:  # on the flight's time (:meth:`step`)
            ext = disturbance_at(self.effects.disturbance, self._phases, t - self.disturbance_t0)
        return state_derivative(X, u1, u2, u3, u4, self._omega_d, self.body, ext)

    def step(self) -> None:
        """Advance one physics step (RK4 of eq. 6, command and rotor speeds held over the step).

        The same step as ``plant.integrate.rk4_step(self.derivative, ...)``, specialised
        (:func:`plant.model.rk4_held`, or its compiled twin: :attr:`rk4`). A state whose last step, with the same
        inputs held, gave it back bit for bit (at rest on the ground, motors off: a landing's disarm wait, a vehicle
        waiting to take off) is its own next step too: not computed again, the clock advanced as by the step (a step
        is a function of the state and the inputs alone where no battery, motor lag, disturbance or wind acts)."""
        t, h = self.t, self.dt
        still = self._still
        if still is not None and still[0] is self.state and still[1] is self.body.constants and still[2] is self.rk4 \
                and still[4] == self.ground and self._pure() and still[3] == _HELD_BITS.pack(*self.realised,
                                                                                            self._omega_d, h):
            self.t = t + h
            return
        if self.battery is not None:
            self._draw_battery(h)
        if self._lagged:
            self._set_omega(motor_lag_step(self.omega, self._omega_target, h, self.profile.motor_time_constant))
        ext = None
        if self._disturbed and self.disturbance_t0 is not None:  # on the flight's time (t - 0.0: t's bits offline)
            d, ph, s = self.effects.disturbance, self._phases, t - self.disturbance_t0
            mid = disturbance_at(d, ph, s + 0.5 * h)
            ext = (disturbance_at(d, ph, s), mid, disturbance_at(d, ph, s + h))
        u1, u2, u3, u4 = self.realised
        if self.wind is None:
            X = self.rk4(self.state, u1, u2, u3, u4, self._omega_d, self.body.constants, h, ext)
        else:  # the wind at the step's start, held over it; the turbulence then advances to the next step
            wx, wy, wz = self.wind.now(t)
            X = self.rk4(self.state, u1, u2, u3, u4, self._omega_d, self.body.constants, h, ext,
                         (wx, wy, wz, self.profile.rotor_drag))
            self.wind.advance()
        if self.ground and X[4] < 0.0:
            if self.impact is None:
                self._touchdown(t + h, X)
            X = ground_contact(X)
        self._still = None
        # (== first: in flight it is false at once, without packing two states a step)
        if X == self.state and self._pure() and _STATE_BITS.pack(*X) == _STATE_BITS.pack(*self.state):
            X = self.state  # (kept: the next step knows it by identity)
            self._still = (X, self.body.constants, self.rk4, _HELD_BITS.pack(*self.realised, self._omega_d, h),
                           self.ground)
        self.state = X  # type: ignore[assignment]
        self.t = t + h

    def _pure(self) -> bool:
        """Whether a step is a function of the state and the inputs held alone (no battery, motor lag, disturbance or
        wind: each of those has a state or a time of its own)."""
        return self.battery is None and not self._lagged and not self._disturbed and self.wind is None

    def steps(self, n: int) -> None:
        """Advance n physics steps, the command held: the bits of n calls of :meth:`step`, in one kernel call
        (:func:`plant.model.rk4_held_steps`) when nothing changes between the steps but the state (still air, no
        disturbance, no battery, no motor lag)."""
        if self.battery is not None or self._lagged or self._disturbed or self.wind is not None:
            for _ in range(n):
                self.step()
            return
        u1, u2, u3, u4 = self.realised
        h = self.dt
        X, taken = self.rk4_steps(self.state, u1, u2, u3, u4, self._omega_d, self.body.constants, h, n, self.ground)
        t = self.t
        for _ in range(taken):
            t += h  # the clock as step() keeps it: a sum of physics steps
        if self.ground and X[4] < 0.0:  # the last step taken ended below the ground (step's own resolution)
            if self.impact is None:
                self._touchdown(t, X)
            X = ground_contact(X)
        self.state = X  # type: ignore[assignment]
        self.t = t
        if taken < n:
            self.steps(n - taken)

    def _touchdown(self, t: float, X: tuple[float, ...]) -> None:
        """Record a touchdown too fast (over CRASH_SPEED_MPS) or too tilted (over CRASH_TILT_RAD) as the impact."""
        speed = math.sqrt(X[1] * X[1] + X[3] * X[3] + X[5] * X[5])
        tilt = math.acos(max(-1.0, min(1.0, math.cos(X[6]) * math.cos(X[8]))))
        if speed > CRASH_SPEED_MPS or tilt > CRASH_TILT_RAD:
            self.impact = (t, speed, tilt)

    def _draw_battery(self, h: float) -> None:
        """The battery over this step: its sag caps the rotors' top speed (the command's clip and the speeds now)."""
        p = self.profile
        assert self.battery is not None
        self._speed_cap = min(self.battery.step(self.omega, p.drag_coeff * p.arm, h), 1.0)
        top = self._speed_cap * p.omega_max
        if any(o > top for o in self._omega_target):
            self._omega_target = tuple(min(o, top) for o in self._omega_target)  # type: ignore[assignment]
            if not self._lagged:
                self._set_omega(self._omega_target)

    @property
    def on_ground(self) -> bool:
        return self.ground and self.state[4] <= 0.0 and self.state[5] <= 0.0

    def diverged(self) -> str | None:
        """Why the vehicle is lost (NaN, |position| > 100 m, tilt > 90 deg), or None."""
        X = self.state
        if not math.isfinite(sum(X)) and not all(math.isfinite(v) for v in X):  # the sum: one cheap test
            return "state is not finite"
        if X[0] * X[0] + X[2] * X[2] + X[4] * X[4] > ENVELOPE_M * ENVELOPE_M:
            return f"position beyond {ENVELOPE_M:g} m"
        if math.cos(X[6]) * math.cos(X[8]) < 0.0:
            return "tilt beyond 90 degrees"
        return None
