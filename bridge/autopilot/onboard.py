"""The vehicle's own position controller, which flies the failsafe's and the ground station's modes.

In:  a target (:class:`~bridge.autopilot.failsafe.Target`: its set-point), the vehicle's nominal model (the profile's
     numbers, never the effects), the gains (:class:`~bridge.autopilot.failsafe.OnboardGains`), the paper state
     (eq. 7, NWU: m, m/s, rad, rad/s), a physics step (s)
Out: the wrench demand (u1..u4, N) and the normalised paper-frame command the profile's actuation makes of it;
     the velocity integrals (m) advanced a step

Split out of :mod:`bridge.autopilot.failsafe` (the failsafe's settings, its targets and the gains): the law that flies
them is here.

The on-board controller is the vehicle's own, not the paper's law: a cascade on the vehicle's nominal model, run at
every physics step (1 kHz by default):

1. position P to a velocity set-point (each target makes its own,
   :meth:`~bridge.autopilot.failsafe.Target.setpoint`):
   v_sp,xy = clip_|.|(k_pos,xy (p_xy,d - p_xy), v_xy,max), v_sp,z = clip(k_pos,z (z_d - z), -v_down, v_up)
   (``Level``: v_sp,z = -descent_rate, no horizontal set-point at all; ``Land``: v_sp,z = -descent_rate, or
   with its ``slowdown`` PX4's landing speed at its height, bridge.autopilot.returnland.land_speed);
2. velocity PI to an acceleration: a = k_vel (v_sp - v) + k_i ∫(v_sp - v) dt, the integral clamped
   to |k_i ∫| <= a_i,max (anti-windup; it takes up a mass mismatch or a steady push: PX4's velocity
   loop has one too, MPC_XY_VEL_I_ACC, MPC_Z_VEL_I_ACC), a_xy clipped to g tan(tilt_max);
3. thrust along (a_x, a_y, g + a_z) (``controller.pid.tilt_from_acceleration``), roll and pitch
   clipped to tilt_max: u1 = m (g + a_z) / max(cos phi cos theta, 0.5);
4. attitude PD: u2 = (Ix/l)(100 (phi_d - phi) - 20 phi'), u3 = (Iy/l)(100 (theta_d - theta) - 20 theta')
   (10 rad/s, critically damped: a vehicle tilted when its failsafe begins turns its thrust where
   it wants it quickly, so that a small difference in that start, the float32 wire's, stays small);
   yaw: u4 = -(Iz/l) 4 psi' (stop turning; the heading stays where that leaves it), or, for a
   target with a heading psi_d, u4 = (Iz/l)(4 wrap(psi_d - psi) - 4 psi') (2 rad/s, critically
   damped). The failsafe's targets have none: the translation does not need one (the closed loop
   is the same about any heading), and turning back to the heading it began with would carry
   that heading's small difference between clocks into the path.
"""

from __future__ import annotations

from dataclasses import replace
from math import cos, hypot, tan

from bridge.autopilot.failsafe import DEFAULT_GAINS, OnboardGains, Target
from controller.actuation import make_actuation
from controller.bsst import wrap_angle
from controller.nominal import Nominal
from controller.pid import tilt_from_acceleration


def _clip(v: float, m: float) -> float:
    return m if v > m else -m if v < -m else v


def level_wrench(X: tuple[float, ...], v_z: float, m: float, g: float, kx: float, ky: float, kz: float,
                 k_vel: float, k_att: float, d_att: float, d_yaw: float) -> tuple[float, float, float, float]:
    """The ``descend`` landing law (:class:`Level`, module docstring): level at the heading it has, sink at
    v_z (m/s, z up, negative), no horizontal control. The wrench (u1 N; u2..u4 N) for state X (eq. 7) on
    the nominal model (m kg, g m/s^2, kx..kz = I/l kg m) with the gains k_vel (1/s), k_att (1/s^2), d_att,
    d_yaw (1/s): u1 = m (g + k_vel (v_z - z')) / max(cos phi cos theta, 0.5), u2 = (Ix/l)(k_att (0 - phi)
    - d_att phi'), likewise u3, u4 = -(Iz/l) d_yaw psi'. Plain floats: the batch engine compiles this same
    function."""
    vz, phi, dphi, th, dth, dpsi = X[5], X[6], X[7], X[8], X[9], X[11]
    az = k_vel * (v_z - vz)
    tilt = max(cos(phi) * cos(th), 0.5)
    return (m * (g + az) / tilt, kx * (k_att * (0.0 - phi) - d_att * dphi), ky * (k_att * (0.0 - th) - d_att * dth),
            kz * (-d_yaw * dpsi))


class OnboardController:
    """The vehicle's own position controller (module docstring): one target at a time.

    :meth:`demand` and :meth:`command` read the current integrals without changing them (a row
    may ask what the loop demands); :meth:`step` commands and advances them by one physics step.
    """

    def __init__(self, nominal: Nominal, gains: OnboardGains = DEFAULT_GAINS) -> None:
        self.n = nominal
        self.gains = gains  # as built; :attr:`g` the ones flown now (a DO_CHANGE_SPEED's horizontal speed: cruise)
        self.g = gains
        self.actuation = make_actuation(nominal)
        self.target: Target | None = None
        self.integral = (0.0, 0.0, 0.0)  # of the velocity error, m/s * s = m

    def engage(self, target: Target) -> None:
        """Fly ``target`` from now on; the integrals start from zero for a new flight (from
        nothing), and carry over from one target to the next (hold, then land: no thrust step). A new target flies
        at the gains' horizontal speed: a :meth:`cruise` speed holds until then (PX4's navigator resets its cruising
        speed as each mode begins)."""
        if self.target is None:
            self.integral = (0.0, 0.0, 0.0)
        self.target = target
        self.g = self.gains

    def cruise(self, speed: float | None) -> float:
        """DO_CHANGE_SPEED: the horizontal speed (m/s) the current target flies at, held to the gains' ``v_xy_max``
        (None: that default again); the speed it flies at now."""
        top = self.gains.v_xy_max if speed is None else min(speed, self.gains.v_xy_max)
        self.g = replace(self.gains, v_xy_max=top)
        return top

    def disengage(self) -> None:
        self.target = None
        self.integral = (0.0, 0.0, 0.0)

    def _law(self, X: tuple[float, ...]) -> tuple[tuple[float, float, float, float], tuple[float, float, float]]:
        """The wrench demand in state X and the velocity error (m/s) the integrals take in."""
        n, g = self.n, self.g
        if self.target is None:
            return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        sp = self.target.setpoint(X, g)
        if sp.level:
            return level_wrench(X, sp.v_z, n.mass, n.gravity, n.ixx / n.arm, n.iyy / n.arm, n.izz / n.arm,
                                g.k_vel_level, g.k_att_level, g.d_att_level, g.d_yaw), (0.0, 0.0, 0.0)
        _, vx, _, vy, _, vz, phi, dphi, th, dth, psi, dpsi = X
        ix, iy, iz = self.integral
        ez = sp.v_z - vz
        az = g.k_vel * ez + _clip(g.k_i_z * iz, g.a_i_max)
        if sp.v_xy is None:
            phi_d = th_d = 0.0
            err = (0.0, 0.0, ez)
        else:
            ex, ey = sp.v_xy[0] - vx, sp.v_xy[1] - vy
            ax = g.k_vel * ex + _clip(g.k_i_xy * ix, g.a_i_max)
            ay = g.k_vel * ey + _clip(g.k_i_xy * iy, g.a_i_max)
            a_max = n.gravity * tan(g.tilt_max)
            a = hypot(ax, ay)
            if a > a_max:
                ax, ay = ax * a_max / a, ay * a_max / a
            phi_d, th_d = tilt_from_acceleration(ax, ay, max(n.gravity + az, 0.2 * n.gravity), psi)
            phi_d, th_d = _clip(phi_d, g.tilt_max), _clip(th_d, g.tilt_max)
            err = (ex, ey, ez)
        tilt = max(cos(phi) * cos(th), 0.5)
        u1 = n.mass * (n.gravity + az) / tilt
        u2 = n.ixx / n.arm * (g.k_att * (phi_d - phi) - g.d_att * dphi)
        u3 = n.iyy / n.arm * (g.k_att * (th_d - th) - g.d_att * dth)
        yaw = g.k_yaw * wrap_angle(sp.psi - psi) - g.d_yaw * dpsi if sp.psi is not None else -g.d_yaw * dpsi
        u4 = n.izz / n.arm * yaw
        return (u1, u2, u3, u4), err

    def demand(self, X: tuple[float, ...]) -> tuple[float, float, float, float]:
        """The wrench (u1..u4, N) this loop asks for in state X, before the actuation's limits."""
        return self._law(X)[0]

    def command(self, X: tuple[float, ...]) -> tuple[float, float, float, float]:
        """Normalised paper-frame command for state X."""
        return self.actuation.allocate(self.demand(X))[1]

    def step(self, X: tuple[float, ...], dt: float) -> tuple[float, float, float, float]:
        """The command for state X, then the integrals advanced by ``dt`` s (each clamped so that
        it adds at most ``a_i_max``)."""
        u, err = self._law(X)
        g = self.g
        lim = (g.a_i_max / g.k_i_xy, g.a_i_max / g.k_i_xy, g.a_i_max / g.k_i_z)
        self.integral = tuple(_clip(i + e * dt, m) for i, e, m in zip(self.integral, err, lim, strict=True))  # type: ignore[assignment]
        return self.actuation.allocate(u)[1]
