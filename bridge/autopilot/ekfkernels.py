"""The error-state EKF's arithmetic, compiled: propagation, updates, the estimate and its covariances.

In:  the filter's arrays, owned by :class:`bridge.autopilot.estimator.Ekf`: ``x`` the nominal state and its
     bookkeeping (float64, layout ``X_*`` of :mod:`bridge.autopilot.ekfstate`, re-exported here: m, m/s,
     rad, rad/s, m/s², s), ``c`` its constants (``C_*``: gravity m/s², noise variances, gates), ``P`` the
     15×15 error covariance, ``hist``/``hs`` the ring buffer of past nominal states and its (start, count),
     ``counts`` the refusals per kind; per call one measurement's values (paper frame NWU, SI units) and
     its noise variances
Out: the same arrays, changed in place; ``estimate`` the 12-state of eq. (7); the covariances and the
     NEES on request, into arrays the caller gives

The filter is described in :mod:`bridge.autopilot.estimator`; this module and
:mod:`bridge.autopilot.ekfstate` (the state's layout, its buffer, P carried in time) are its arithmetic,
nothing else, compiled with numba so that a flight with the EKF pays about a microsecond of call per
measurement rather than the tens that the same work costs in small numpy calls. Each kernel is cached on
disk (``cache=True``): the first flight with the EKF on a machine compiles them (~7 s on a 2-core VM),
later ones load them.
"""

from __future__ import annotations

import math

import numpy as np

# the layout and the state's kernels, re-exported: Ekf and the tests read them here
from bridge.autopilot.ekfstate import (  # noqa: F401 - re-exported
    C_G,
    C_GATE1,
    C_GATE3,
    C_NA2,
    C_NG2,
    C_RESET,
    C_SIZE,
    C_STEPMAX,
    C_WA2,
    C_WG2,
    HIST_COLS,
    K_BARO,
    K_GNSS,
    K_HEADING,
    K_POSE,
    N_REJ,
    N_ROW,
    X_ACC,
    X_AF,
    X_BA,
    X_BG,
    X_CORR,
    X_EOK,
    X_EUL,
    X_FUSED,
    X_GVAR,
    X_M,
    X_OM,
    X_P,
    X_PEND,
    X_PRED,
    X_PSI,
    X_R,
    X_SIZE,
    X_T,
    X_V,
    _attitude,
    _euler_rates,
    _matmul,
    _rotation_of,
    _state_at,
    _weighted_square,
    _wrap_angle,
    carry,
    current_P,
    euler_now,
    flush,
    remember,
)
from bridge.autopilot.kernelcache import njit


@njit(cache=True)
def propagate(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray, f0: float,
              f1: float, f2: float, w0: float, w1: float, w2: float, T: float, t_valid: float) -> None:
    """One IMU sample: mean specific force (f0, f1, f2) m/s² and body rate (w0, w1, w2) rad/s over T s."""
    wx, wy, wz = w0 - x[X_BG], w1 - x[X_BG + 1], w2 - x[X_BG + 2]
    fx, fy, fz = f0 - x[X_BA], f1 - x[X_BA + 1], f2 - x[X_BA + 2]
    H = _rotation_of(0.5 * wx * T, 0.5 * wy * T, 0.5 * wz * T)  # Exp(ωT/2)
    M = _matmul(_attitude(x), H)  # the attitude at mid-interval
    afx = M[0] * fx + M[1] * fy + M[2] * fz
    afy = M[3] * fx + M[4] * fy + M[5] * fz
    afz = M[6] * fx + M[7] * fy + M[8] * fz
    ax, ay, az = afx, afy, afz - c[C_G]
    hT2 = 0.5 * T * T
    x[X_P] += x[X_V] * T + ax * hT2
    x[X_P + 1] += x[X_V + 1] * T + ay * hT2
    x[X_P + 2] += x[X_V + 2] * T + az * hT2
    x[X_V] += ax * T
    x[X_V + 1] += ay * T
    x[X_V + 2] += az * T
    R = _matmul(M, H)
    for k in range(9):
        x[X_R + k] = R[k]
        x[X_M + k] = M[k]
    x[X_EOK] = 0.0
    x[X_T] = t_valid
    x[X_OM], x[X_OM + 1], x[X_OM + 2] = wx, wy, wz
    x[X_GVAR] = c[C_NG2] / T  # white variance of this sample's mean rate
    x[X_ACC], x[X_ACC + 1], x[X_ACC + 2] = ax, ay, az
    x[X_AF], x[X_AF + 1], x[X_AF + 2] = afx, afy, afz
    x[X_PEND] += T
    if x[X_PEND] >= c[C_STEPMAX]:
        flush(x, c, P)
    remember(x, hist, hs)


@njit(cache=True)
def _gate(c: np.ndarray, counts: np.ndarray, kind: int, nis: float, gate: float) -> bool:
    """Whether to fuse a reading of this normalised innovation squared (counts refusals)."""
    if nis <= gate:
        counts[kind, N_ROW] = 0
        return True
    n = counts[kind, N_ROW] + 1
    counts[kind, N_ROW] = n
    counts[kind, N_REJ] += 1
    if n > c[C_RESET]:
        counts[kind, N_ROW] = 0
        return True
    return False


@njit(cache=True)
def _update_block(c: np.ndarray, P: np.ndarray, counts: np.ndarray, kind: int, i0: int, r0: float, r1: float,
                  r2: float, Rm: tuple, dx: np.ndarray, have_dx: bool) -> bool:
    """One 3-value reading of the error states i0..i0+2 (H selects them), noise covariance ``Rm`` (3×3
    row-major), after the correction ``dx`` of an earlier block of the same reading if ``have_dx``
    (sequential blocks: exact, their noises being independent). Adds its correction to ``dx`` (or sets
    it) and returns True; False, changing nothing but the counts, if refused."""
    s00 = P[i0, i0] + Rm[0]
    s01 = P[i0, i0 + 1] + Rm[1]
    s02 = P[i0, i0 + 2] + Rm[2]
    s10 = P[i0 + 1, i0] + Rm[3]
    s11 = P[i0 + 1, i0 + 1] + Rm[4]
    s12 = P[i0 + 1, i0 + 2] + Rm[5]
    s20 = P[i0 + 2, i0] + Rm[6]
    s21 = P[i0 + 2, i0 + 1] + Rm[7]
    s22 = P[i0 + 2, i0 + 2] + Rm[8]
    c00 = s11 * s22 - s12 * s21
    c01 = s02 * s21 - s01 * s22
    c02 = s01 * s12 - s02 * s11
    det = s00 * c00 + s10 * c01 + s20 * c02
    if not det > 0.0:
        counts[kind, N_REJ] += 1
        return False
    k = 1.0 / det
    i00, i01, i02 = c00 * k, c01 * k, c02 * k
    i10, i11, i12 = (s12 * s20 - s10 * s22) * k, (s00 * s22 - s02 * s20) * k, (s02 * s10 - s00 * s12) * k
    i20, i21, i22 = (s10 * s21 - s11 * s20) * k, (s01 * s20 - s00 * s21) * k, (s00 * s11 - s01 * s10) * k
    if have_dx:
        r0, r1, r2 = r0 - dx[i0], r1 - dx[i0 + 1], r2 - dx[i0 + 2]
    y0 = i00 * r0 + i01 * r1 + i02 * r2
    y1 = i10 * r0 + i11 * r1 + i12 * r2
    y2 = i20 * r0 + i21 * r1 + i22 * r2
    if not _gate(c, counts, kind, r0 * y0 + r1 * y1 + r2 * y2, c[C_GATE3]):
        return False
    PHt = np.empty((15, 3))
    K = np.empty((15, 3))  # K = P Hᵀ S⁻¹
    for i in range(15):
        a0, a1, a2 = P[i, i0], P[i, i0 + 1], P[i, i0 + 2]
        PHt[i, 0], PHt[i, 1], PHt[i, 2] = a0, a1, a2
        K[i, 0] = a0 * i00 + a1 * i10 + a2 * i20
        K[i, 1] = a0 * i01 + a1 * i11 + a2 * i21
        K[i, 2] = a0 * i02 + a1 * i12 + a2 * i22
        step = a0 * y0 + a1 * y1 + a2 * y2  # P Hᵀ S⁻¹ r
        dx[i] = dx[i] + step if have_dx else step
    for i in range(15):  # P -= K (P Hᵀ)ᵀ
        k0, k1, k2 = K[i, 0], K[i, 1], K[i, 2]
        for j in range(15):
            P[i, j] -= k0 * PHt[j, 0] + k1 * PHt[j, 1] + k2 * PHt[j, 2]
    return True


@njit(cache=True)
def _update_scalar(x: np.ndarray, c: np.ndarray, P: np.ndarray, counts: np.ndarray, kind: int, h: np.ndarray,
                   r: float, var: float) -> None:
    """One scalar reading with H = h (a 15-row of the error states): fused and injected, or refused."""
    PHt = np.empty(15)
    for i in range(15):
        s = 0.0
        for j in range(15):
            if h[j] != 0.0:
                s += P[i, j] * h[j]
        PHt[i] = s
    s = var
    for j in range(15):
        s += h[j] * PHt[j]
    if not s > 0.0 or not _gate(c, counts, kind, r * r / s, c[C_GATE1]):
        return
    dx = np.empty(15)
    for i in range(15):
        ki = PHt[i] / s
        dx[i] = ki * r
        for j in range(15):
            P[i, j] -= ki * PHt[j]
    _fused(x, dx)


@njit(cache=True)
def _fused(x: np.ndarray, dx: np.ndarray) -> None:
    """A reading's correction, fused: injected and counted."""
    _inject(x, dx)
    x[X_FUSED] += 1.0


@njit(cache=True)
def _inject(x: np.ndarray, dx: np.ndarray) -> None:
    """Add a correction to the nominal state, and to the corrections applied so far (the attitude's as
    Euler-angle changes, E⁻¹ δθ); R̂ ← Exp(δθ)·R̂."""
    for k in range(3):
        x[X_P + k] += dx[k]
        x[X_V + k] += dx[3 + k]
        x[X_BG + k] += dx[9 + k]
        x[X_BA + k] += dx[12 + k]
    for k in range(6):
        x[X_CORR + k] += dx[k]
    w0, w1, w2 = dx[6], dx[7], dx[8]
    R = _attitude(x)
    cp, sp = math.cos(x[X_PSI]), math.sin(x[X_PSI])
    ct = math.sqrt(max(1e-12, 1.0 - R[6] * R[6]))  # cos theta
    a = (cp * w0 + sp * w1) / ct
    x[X_CORR + 6] += a
    x[X_CORR + 7] += cp * w1 - sp * w0
    x[X_CORR + 8] += w2 - R[6] * a  # + tan(theta) cos(theta) a, sin(theta) = -R[6]
    R = _matmul(_rotation_of(w0, w1, w2), R)
    for k in range(9):
        x[X_R + k] = R[k]
    x[X_EOK] = 0.0


@njit(cache=True)
def _position_first(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray,
                    counts: np.ndarray, kind: int, t_valid: float, z0: float, z1: float, z2: float, vp0: float,
                    vp1: float, vp2: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """The start of a pose or GNSS fix (``kind``): P carried to now, the state at t_valid (s), and the
    position (z0, z1, z2) m with variances vp (m²) fused into a new error dx; (that state, dx, fused?)."""
    flush(x, c, P)
    s = np.empty(9)
    _state_at(x, hist, hs, t_valid, s)
    dx = np.zeros(15)
    have = _update_block(c, P, counts, kind, np.int64(0), z0 - s[0], z1 - s[1], z2 - s[2],
                         (vp0, 0.0, 0.0, 0.0, vp1, 0.0, 0.0, 0.0, vp2), dx, np.bool_(False))
    return s, dx, have


@njit(cache=True)
def fuse_pose(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray, counts: np.ndarray,
              t_valid: float, z0: float, z1: float, z2: float, z3: float, z4: float, z5: float, vp0: float,
              vp1: float, vp2: float, v0: float, v1: float, v2: float) -> None:
    """A motion-capture pose: position (z0, z1, z2) m with variances vp, Euler angles (z3, z4, z5) rad with
    variances v, valid at t_valid s; fused as two 3-value blocks, the attitude's as the small rotation
    E·r of its residual r with noise E·diag(v)·Eᵀ."""
    # kinds and offsets as np.int64, not literals: numba compiles a callee once per literal value it is given
    # (four _gate, four _update_block: ~2 s of a fresh machine's first EKF)
    s, dx, have = _position_first(x, c, P, hist, hs, counts, np.int64(K_POSE), t_valid, z0, z1, z2, vp0, vp1,
                                  vp2)
    e0, e1, e2 = _wrap_angle(z3 - s[6]), _wrap_angle(z4 - s[7]), _wrap_angle(z5 - s[8])
    cp, sp, ct, st = math.cos(s[8]), math.sin(s[8]), math.cos(s[7]), math.sin(s[7])
    a, b = cp * ct, sp * ct  # E = [[a, -sp, 0], [b, cp, 0], [-st, 0, 1]]
    r01 = a * b * v0 - sp * cp * v1
    r02 = -a * st * v0
    r12 = -b * st * v0
    Rm = (a * a * v0 + sp * sp * v1, r01, r02, r01, b * b * v0 + cp * cp * v1, r12, r02, r12, st * st * v0 + v2)
    have |= _update_block(c, P, counts, np.int64(K_POSE), np.int64(6), a * e0 - sp * e1, b * e0 + cp * e1,
                          e2 - st * e0, Rm, dx, have)
    if have:
        _fused(x, dx)


@njit(cache=True)
def fuse_gnss(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray, counts: np.ndarray,
              t_valid: float, z0: float, z1: float, z2: float, z3: float, z4: float, z5: float, vp0: float,
              vp1: float, vp2: float, vv0: float, vv1: float, vv2: float) -> None:
    """A GNSS fix: position (z0, z1, z2) m and velocity (z3, z4, z5) m/s with their variances, valid at t_valid."""
    s, dx, have = _position_first(x, c, P, hist, hs, counts, np.int64(K_GNSS), t_valid, z0, z1, z2, vp0, vp1,
                                  vp2)
    have |= _update_block(c, P, counts, np.int64(K_GNSS), np.int64(3), z3 - s[3], z4 - s[4], z5 - s[5],
                          (vv0, 0.0, 0.0, 0.0, vv1, 0.0, 0.0, 0.0, vv2), dx, have)
    if have:
        _fused(x, dx)


@njit(cache=True)
def fuse_baro(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray, counts: np.ndarray,
              t_valid: float, z: float, var: float) -> None:
    """A barometric altitude z (m above the start's datum, variance var m²), valid at t_valid: H = e_z on δp."""
    flush(x, c, P)
    s = np.empty(9)
    _state_at(x, hist, hs, t_valid, s)
    h = np.zeros(15)
    h[2] = 1.0
    _update_scalar(x, c, P, counts, np.int64(K_BARO), h, z - s[2], var)


@njit(cache=True)
def fuse_heading(x: np.ndarray, c: np.ndarray, P: np.ndarray, hist: np.ndarray, hs: np.ndarray,
                 counts: np.ndarray, t_valid: float, z: float, var: float) -> None:
    """A heading z (rad, variance var rad²), valid at t_valid: H = (cψ tθ, sψ tθ, 1) on δθ."""
    flush(x, c, P)
    s = np.empty(9)
    _state_at(x, hist, hs, t_valid, s)
    h = np.zeros(15)
    tt = math.tan(s[7])
    h[6] = math.cos(s[8]) * tt
    h[7] = math.sin(s[8]) * tt
    h[8] = 1.0
    _update_scalar(x, c, P, counts, np.int64(K_HEADING), h, _wrap_angle(z - s[8]), var)


@njit(cache=True)
def estimate(x: np.ndarray, t: float) -> tuple:
    """The 12-state of eq. (7) at t (s): the nominal state, carried from the last IMU sample at constant
    velocity and rates; the Euler rates of the bias-corrected gyro."""
    phi, theta, psi = euler_now(x)
    dphi, dtheta, dpsi = _euler_rates(phi, theta, x[X_OM], x[X_OM + 1], x[X_OM + 2])
    dt = t - x[X_T]
    if dt > 0.0:
        return (x[X_P] + x[X_V] * dt, x[X_V] + x[X_ACC] * dt, x[X_P + 1] + x[X_V + 1] * dt,
                x[X_V + 1] + x[X_ACC + 1] * dt, x[X_P + 2] + x[X_V + 2] * dt, x[X_V + 2] + x[X_ACC + 2] * dt,
                phi + dphi * dt, dphi, theta + dtheta * dt, dtheta, psi + dpsi * dt, dpsi)
    return (x[X_P], x[X_V], x[X_P + 1], x[X_V + 1], x[X_P + 2], x[X_V + 2], phi, dphi, theta, dtheta, psi, dpsi)


@njit(cache=True)
def state_covariance(x: np.ndarray, c: np.ndarray, P: np.ndarray, out: np.ndarray, Pn: np.ndarray) -> None:
    """out (9×9) = J Pn Jᵀ over (x, y, z, ẋ, ẏ, ż, φ, θ, ψ), Pn (15×15, written here) P carried to now,
    J = diag(I₆, E⁻¹) on (δp, δv, δθ): the attitude's rows and columns as Euler-angle errors."""
    current_P(x, c, P, Pn)
    _, theta, psi = euler_now(x)
    cp, sp, ct, tt = math.cos(psi), math.sin(psi), math.cos(theta), math.tan(theta)
    J = ((cp / ct, sp / ct, 0.0), (-sp, cp, 0.0), (cp * tt, sp * tt, 1.0))
    for i in range(9):
        for j in range(9):
            out[i, j] = Pn[i, j]
    for j in range(9):  # rows 6..8 ← J · rows 6..8
        a0, a1, a2 = out[6, j], out[7, j], out[8, j]
        for i in range(3):
            out[6 + i, j] = J[i][0] * a0 + J[i][1] * a1 + J[i][2] * a2
    for i in range(9):  # columns 6..8 ← columns 6..8 · Jᵀ
        a0, a1, a2 = out[i, 6], out[i, 7], out[i, 8]
        for j in range(3):
            out[i, 6 + j] = a0 * J[j][0] + a1 * J[j][1] + a2 * J[j][2]


@njit(cache=True)
def nees(x: np.ndarray, c: np.ndarray, P: np.ndarray, e: tuple) -> float:
    """eᵀ C⁻¹ e of an estimation error e (the order of :func:`state_covariance`) against the state
    covariance C now; NaN if C is not positive definite."""
    C = np.empty(81)
    state_covariance(x, c, P, C.reshape((9, 9)), np.empty((15, 15)))
    return _weighted_square(C, e)


_ready = False


def ready() -> None:
    """Compile (or load from the cache) every kernel now, once per process: an EKF built in the middle
    of a real-time session must not stop to compile at its first measurement."""
    global _ready
    if _ready:
        return
    x = np.zeros(X_SIZE)
    x[X_R] = x[X_R + 4] = x[X_R + 8] = x[X_M] = x[X_M + 4] = x[X_M + 8] = 1.0
    c = np.ones(C_SIZE)
    P = np.eye(15)
    hist = np.zeros((4, HIST_COLS))
    hs = np.zeros(2, np.int64)
    counts = np.zeros((4, 2), np.int64)
    remember(x, hist, hs)
    propagate(x, c, P, hist, hs, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, 0.01)
    fuse_pose(x, c, P, hist, hs, counts, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    fuse_gnss(x, c, P, hist, hs, counts, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    fuse_baro(x, c, P, hist, hs, counts, 0.0, 0.0, 1.0)
    fuse_heading(x, c, P, hist, hs, counts, 0.0, 0.0, 1.0)
    estimate(x, 0.0)
    current_P(x, c, P, np.empty((15, 15)))
    state_covariance(x, c, P, np.empty((9, 9)), np.empty((15, 15)))
    nees(x, c, P, (0.0,) * 9)
    _ready = True
