"""The BS-ST, SMC and PID laws and the actuation for N cells at once: compiled loops over the cell axis.

In:  per cell a built-in law name (``bsst``, ``smc``, ``pid``) and discretization (``explicit``, ``implicit``:
     how ``bsst`` steps its super-twisting step), the nominal model, the gains and the control
     rate (Hz) they all share; each step the states [12, N] (eq. 7: m, m/s, rad, rad/s), the reference
     sample (x, y, z, psi, each value and 4 derivatives: [5] shared or [5, N]), which cells command and
     which hold their integrators
Out: the wrench demanded and realisable [4, N] (N), the normalised command [4, N], the saturation flags,
     the signed rotor-speed sum omega_d [N] (rad/s) the actuation allocated

Each cell runs the scalar engine's own functions, compiled (bridge.batch.kernels):
:func:`controller.bsst.backstepping` and :func:`controller.supertwisting.advance_xi` (explicit) or
:func:`controller.supertwisting.advance_xi_implicit` (implicit),
:func:`controller.pid.pid` and :func:`controller.pid.pid_integrals`,
:func:`controller.actuation.allocate_wrench` or :func:`controller.actuation.allocate_motors`. ``smc`` cells
fly the BS-ST arithmetic with the sign reaching law in the last step, as ``make_law("smc")`` does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from bridge.batch import kernels as K
from controller.bsst import law_constants, law_tables
from controller.gains import Gains
from controller.nominal import Nominal
from controller.pid import pid_constants

BACKSTEPPING = ("bsst", "smc")  # the laws of controller.bsst (super-twisting or sign reaching)
BATCH_LAWS = (*BACKSTEPPING, "pid")


class BatchBacksteppingLaw:
    """:class:`~controller.bsst.BacksteppingSuperTwisting` for n cells; per cell super-twisting (``bsst``)
    or sign (``smc``) reaching in the last step, the super-twisting stepped explicitly or (``implicit``)
    implicitly: the cell's law constants carry the implicit step's period, or 0."""

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, sign: np.ndarray,
                 implicit: np.ndarray | None = None) -> None:
        n = len(sign)
        self.n = n
        self.dt = 1.0 / rate_hz
        self.constants = law_constants(nominal, gains)
        self.constants_implicit = law_constants(nominal, gains, self.dt)
        self.tables = law_tables(gains)
        st = (gains.z_st, gains.attitude_st, gains.attitude_st, gains.yaw_st)  # z, phi (u2), theta (u3), yaw
        self.k2 = np.array([s.k2 for s in st])
        self.k1 = np.array([s.k1 for s in st])
        self.xi_max = np.array([s.xi_max for s in st])
        self.sign = np.asarray(sign, bool)
        self.implicit = np.zeros(n, bool) if implicit is None else np.asarray(implicit, bool) & ~self.sign
        self.xi = np.zeros((4, n))
        self.s = np.zeros((4, n))
        self.desired = np.zeros((2, n))

    def advance(self, saturated: np.ndarray, hold: np.ndarray) -> None:
        """Step the integrators (eq. 22) of the cells not holding, per channel not saturated and s != 0."""
        _advance(self.xi, self.s, self.k1, self.k2, self.dt, self.xi_max, np.ascontiguousarray(saturated),
                 np.ascontiguousarray(hold), self.sign, self.implicit)

    def update(self, X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray) -> np.ndarray:
        """The wrench (u1..u4) [4, n] for the states X [12, n]; ref [4, 5, 1] or [4, 5, n] (x, y, z, psi)."""
        u = np.empty((4, X.shape[1]))
        _backstepping(np.ascontiguousarray(X), np.ascontiguousarray(ref), np.ascontiguousarray(omega_d), self.xi,
                      self.sign, self.implicit, self.constants, self.constants_implicit, self.tables, self.s,
                      self.desired, u)
        return u


class BatchPid:
    """:class:`~controller.pid.CascadedPid` for n cells."""

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, n: int) -> None:
        self.constants = pid_constants(nominal, gains)
        self.i_max = gains.pid["i_max"]
        self.dt = 1.0 / rate_hz
        self.integral = np.zeros((3, n))
        self._err = np.zeros((3, n))
        self.desired = np.zeros((2, n))

    def advance(self, saturated: np.ndarray, hold: np.ndarray) -> None:
        _pid_advance(self.integral, self._err, self.dt, self.i_max, np.ascontiguousarray(saturated),
                     np.ascontiguousarray(hold))

    def update(self, X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray) -> np.ndarray:
        u = np.empty((4, X.shape[1]))
        _pid(np.ascontiguousarray(X), np.ascontiguousarray(ref), self.integral, self.constants, self._err,
             self.desired, u)
        return u


class BatchActuation:
    """:func:`controller.actuation.make_actuation` for n cells: clamp (``wrench``) or rotor allocation
    (``motors``), with the realisable wrench, the normalised command, the saturation flags and omega_d."""

    def __init__(self, nominal: Nominal, n: int) -> None:
        self.motors = nominal.actuation == "motors"
        self.u_max = tuple(float(v) for v in nominal.u_max)
        self.b = nominal.thrust_coeff
        self.d = nominal.drag_coeff
        self.omega_max = nominal.omega_max
        self.w2_max = nominal.omega_max**2
        self.omega_d = np.zeros(n)

    def allocate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(realisable [4, k], normalised [4, k], saturated [4, k] bool, omega_d [k]) for the wrench u [4, k]."""
        k = u.shape[1]
        r, c, sat, od = np.empty((4, k)), np.empty((4, k)), np.empty((4, k), bool), np.empty(k)
        _allocate(np.ascontiguousarray(u), self.motors, self.u_max, self.b, self.d, self.omega_max, self.w2_max,
                  r, c, sat, od)
        return r, c, sat, od


class BatchController:
    """The laws of n cells and their actuation, stepped at the control rate (:class:`controller.Controller`
    over the cell axis). ``laws`` must list the backstepping cells (``bsst``, ``smc``) before the ``pid``
    ones: each group is a contiguous block, so every array is a view, never a copy."""

    def __init__(self, laws: Sequence[str], nominal: Nominal, gains: Gains, rate_hz: float,
                 discretizations: Sequence[str] | None = None) -> None:
        """``discretizations``: per cell (in the order of ``laws``) ``explicit`` or ``implicit``; None: all
        explicit."""
        unknown = sorted(set(laws) - set(BATCH_LAWS))
        if unknown:
            raise ValueError(f"the batch flies only {', '.join(BATCH_LAWS)}; got {unknown[0]!r}")
        n_bs = sum(1 for name in laws if name in BACKSTEPPING)
        if any(name == "pid" for name in laws[:n_bs]):
            raise ValueError("BatchController: the bsst and smc cells must come before the pid ones")
        self.n = len(laws)
        self.bs = slice(0, n_bs)
        self.pid = slice(n_bs, self.n)
        sign = np.array([name == "smc" for name in laws[:n_bs]], bool)
        implicit = np.array([d == "implicit" for d in (discretizations or ["explicit"] * self.n)[:n_bs]], bool)
        self.backstepping = BatchBacksteppingLaw(nominal, gains, rate_hz, sign, implicit) if n_bs else None
        self.pid_law = BatchPid(nominal, gains, rate_hz, self.n - n_bs) if self.n > n_bs else None
        self.actuation = BatchActuation(nominal, self.n)

    @staticmethod
    def order(laws: Sequence[str]) -> list[int]:
        """A permutation of the cells that puts the backstepping ones first (stable)."""
        return sorted(range(len(laws)), key=lambda i: laws[i] == "pid")

    def step(self, X: np.ndarray, ref: np.ndarray, hold: np.ndarray,
             active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One control step for every cell on the states X [12, n]; only the ``active`` cells (those that
        command this step) advance their integrators and keep their omega_d, ``hold`` ones do not
        integrate. Returns (demanded, realisable, normalised), each [4, n]."""
        u = np.empty((4, self.n))
        omega_d = self.actuation.omega_d
        if ref.ndim == 2:
            ref = ref[:, :, None]  # one sample for every cell
        shared = ref.shape[2] == 1
        if self.backstepping is not None:
            refb = ref if shared else ref[:, :, self.bs]
            u[:, self.bs] = self.backstepping.update(X[:, self.bs], refb, omega_d[self.bs])
        if self.pid_law is not None:
            refp = ref if shared else ref[:, :, self.pid]
            u[:, self.pid] = self.pid_law.update(X[:, self.pid], refp, omega_d[self.pid])
        real, c, sat, od = self.actuation.allocate(u)
        np.copyto(omega_d, od, where=active)
        idle = ~active | hold
        if self.backstepping is not None:
            self.backstepping.advance(sat[:, self.bs], idle[self.bs])
        if self.pid_law is not None:
            self.pid_law.advance(sat[:, self.pid], idle[self.pid])
        return u, real, c


# -- the loops over the cells (each cell: the scalar engine's function, compiled) ---------------------------
@njit(cache=True)
def _backstepping(X, ref, omega_d, xi, sign, implicit, constants, constants_implicit, tables, s_out, desired,
                  u_out):  # pragma: no cover
    """:func:`controller.bsst.backstepping` of every cell (with ``constants_implicit`` where ``implicit``): the
    wrench into u_out [4, n], the sliding variables into s_out [4, n], (phi_d, theta_d) into desired [2, n];
    ref [4, 5, 1] or [4, 5, n]."""
    shared = ref.shape[2] == 1
    for j in range(X.shape[1]):
        r = K.backstepping(K.column(X, j), K.sample(ref, 0 if shared else j), omega_d[j],
                           (xi[0, j], xi[1, j], xi[2, j], xi[3, j]), sign[j],
                           constants_implicit if implicit[j] else constants, tables)
        for i in range(4):
            u_out[i, j] = r[i]
            s_out[i, j] = r[4 + i]
        desired[0, j] = r[8]
        desired[1, j] = r[9]


@njit(cache=True)
def _advance(xi, s, k1, k2, dt, xi_max, saturated, hold, sign, implicit):  # pragma: no cover
    """:func:`controller.supertwisting.advance_xi` (or ``advance_xi_implicit`` where ``implicit``) of every
    channel of every super-twisting cell, in place."""
    for j in range(xi.shape[1]):
        if sign[j]:
            continue
        for r in range(4):
            held = hold[j] or saturated[r, j]
            if implicit[j]:
                xi[r, j] = K.advance_xi_implicit(xi[r, j], s[r, j], k1[r], k2[r], dt, xi_max[r], held)
            else:
                xi[r, j] = K.advance_xi(xi[r, j], s[r, j], k2[r], dt, xi_max[r], held)


@njit(cache=True)
def _pid(X, ref, integral, constants, err, desired, u_out):  # pragma: no cover
    """:func:`controller.pid.pid` of every cell: the wrench, the position errors, (phi_d, theta_d)."""
    shared = ref.shape[2] == 1
    for j in range(X.shape[1]):
        r = K.pid_law(K.column(X, j), K.sample(ref, 0 if shared else j), (integral[0, j], integral[1, j],
                      integral[2, j]), constants)
        for i in range(4):
            u_out[i, j] = r[i]
        for i in range(3):
            err[i, j] = r[4 + i]
        desired[0, j] = r[7]
        desired[1, j] = r[8]


@njit(cache=True)
def _pid_advance(integral, err, dt, i_max, saturated, hold):  # pragma: no cover
    """:func:`controller.pid.pid_integrals` of every cell not holding and not saturated in thrust, in place."""
    for j in range(integral.shape[1]):
        if hold[j] or saturated[0, j]:
            continue
        v = K.pid_integrals((integral[0, j], integral[1, j], integral[2, j]), (err[0, j], err[1, j], err[2, j]),
                            dt, i_max)
        integral[0, j], integral[1, j], integral[2, j] = v


@njit(cache=True, inline="always")
def allocate_cell(u: tuple, motors: bool, u_max: tuple, b: float, d: float, omega_max: float,
                  w2_max: float) -> tuple:  # pragma: no cover
    """:func:`controller.actuation.allocate_motors` (``motors``) or ``allocate_wrench`` of one cell's wrench u:
    (realisable, normalised, saturated, omega_d)."""
    if motors:
        return K.allocate_motors(u, b, d, omega_max, w2_max)
    return K.allocate_wrench(u, u_max, b, d)


@njit(cache=True)
def _allocate(u, motors, u_max, b, d, omega_max, w2_max, real, c, sat, omega_d):  # pragma: no cover
    """:func:`allocate_cell` of every cell."""
    for j in range(u.shape[1]):
        rr, cc, ss, od = allocate_cell((u[0, j], u[1, j], u[2, j], u[3, j]), motors, u_max, b, d, omega_max, w2_max)
        for i in range(4):
            real[i, j] = rr[i]
            c[i, j] = cc[i]
            sat[i, j] = ss[i]
        omega_d[j] = od
