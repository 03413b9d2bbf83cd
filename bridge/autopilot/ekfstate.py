"""The error-state EKF's compiled state: its layout, the buffer of past states, and P carried in time.

In:  the filter's arrays, owned by :class:`bridge.autopilot.estimator.Ekf`: ``x`` the nominal state and its
     bookkeeping (float64, layout ``X_*`` below: m, m/s, rad, rad/s, m/s², s), ``c`` its constants
     (``C_*``: gravity m/s², noise variances, gates), ``P`` the 15×15 error covariance, ``hist``/``hs``
     the ring buffer of past nominal states and its (start, count); an elapsed IMU time T (s)
Out: the same arrays, changed in place (the buffer appended, P carried over T); the Euler angles of
     R̂ (rad); the state at a past time (m, m/s, rad); P carried to now into an array the caller gives

The first half of the EKF's arithmetic (:mod:`bridge.autopilot.ekfkernels` is the rest: propagation,
updates, the estimate), compiled with numba (``cache=True``). The 3-vector and 3×3 helpers are
:mod:`plant.sensors`' own functions compiled (one source for both), and the NEES's quadratic form is
:func:`bridge.autopilot.cholesky.weighted_square` compiled.
"""

from __future__ import annotations

import numpy as np

from bridge.autopilot.cholesky import weighted_square
from bridge.autopilot.kernelcache import njit
from plant import sensors as _s

# the nominal state x: position, velocity, attitude R (row-major, body FLU -> NWU), biases, the output's
# continuous heading, the time of the last IMU sample, and what that sample left (bias-corrected rate,
# inertial acceleration, specific force M f, mid-interval attitude M); then the corrections injected so
# far to (p, v, phi, theta, psi), the white variance of one gyro sample, the IMU time P was not carried
# over yet, the Euler angles of R (valid if X_EOK is 1), and counts of covariance steps and fusions
X_P, X_V, X_R, X_BG, X_BA, X_PSI, X_T, X_OM, X_ACC, X_AF, X_M = 0, 3, 6, 15, 18, 21, 22, 23, 26, 29, 32
X_CORR, X_GVAR, X_PEND, X_EUL, X_EOK, X_PRED, X_FUSED, X_SIZE = 41, 50, 51, 52, 55, 56, 57, 58
# the constants c: gravity, the noise variances (densities squared), COVARIANCE_STEP_MAX_S, the chi2
# gates of 1 and 3 degrees of freedom, RESET_AFTER
C_G, C_NA2, C_NG2, C_WA2, C_WG2, C_STEPMAX, C_GATE1, C_GATE3, C_RESET, C_SIZE = range(10)
# the kinds of reading (rows of counts) and the columns of counts: refused in all, refused in a row
K_POSE, K_GNSS, K_BARO, K_HEADING = 0, 1, 2, 3
N_REJ, N_ROW = 0, 1
HIST_COLS = 19  # t, p, v, (phi, theta, psi), the nine corrections at that time



_rotation_of = njit(cache=True)(_s.rotation_of)
_matmul = njit(cache=True)(_s.matmul)
_euler = njit(cache=True)(_s.euler)
_euler_rates = njit(cache=True)(_s.euler_rates)
_wrap_angle = njit(cache=True)(_s.wrap_angle)
_weighted_square = njit(cache=True)(weighted_square)


@njit(cache=True)
def _attitude(x: np.ndarray) -> tuple:
    return (x[X_R], x[X_R + 1], x[X_R + 2], x[X_R + 3], x[X_R + 4], x[X_R + 5], x[X_R + 6], x[X_R + 7],
            x[X_R + 8])


@njit(cache=True)
def _mid_attitude(x: np.ndarray) -> tuple:
    return (x[X_M], x[X_M + 1], x[X_M + 2], x[X_M + 3], x[X_M + 4], x[X_M + 5], x[X_M + 6], x[X_M + 7],
            x[X_M + 8])


@njit(cache=True)
def euler_now(x: np.ndarray) -> tuple:
    """(φ, θ, ψ) of R̂ (rad), ψ continuous; kept in x until R̂ changes."""
    if x[X_EOK] == 0.0:
        phi, theta, psi = _euler(_attitude(x))
        x[X_PSI] = x[X_PSI] + _wrap_angle(psi - x[X_PSI])  # the angle equal to psi nearest the last one
        x[X_EUL] = phi
        x[X_EUL + 1] = theta
        x[X_EUL + 2] = x[X_PSI]
        x[X_EOK] = 1.0
    return x[X_EUL], x[X_EUL + 1], x[X_EUL + 2]


@njit(cache=True)
def remember(x: np.ndarray, hist: np.ndarray, hs: np.ndarray) -> None:
    """Append the nominal state now (and the corrections so far) to the buffer, dropping the oldest."""
    phi, theta, psi = euler_now(x)
    depth = hist.shape[0]
    start, n = hs[0], hs[1]
    if n < depth:
        slot = (start + n) % depth
        hs[1] = n + 1
    else:
        slot = start
        hs[0] = (start + 1) % depth
    row = hist[slot]
    row[0] = x[X_T]
    for k in range(3):
        row[1 + k] = x[X_P + k]
        row[4 + k] = x[X_V + k]
    row[7] = phi
    row[8] = theta
    row[9] = psi
    for k in range(9):
        row[10 + k] = x[X_CORR + k]


@njit(cache=True)
def _state_at(x: np.ndarray, hist: np.ndarray, hs: np.ndarray, t: float, s: np.ndarray) -> None:
    """s = (x, y, z, vx, vy, vz, φ, θ, ψ) at time t as known now: the buffer, interpolated, plus the
    corrections injected since (after the newest sample: carried at its velocity)."""
    depth = hist.shape[0]
    start, n = hs[0], hs[1]
    newest = hist[(start + n - 1) % depth]
    if t >= newest[0]:
        dt = t - newest[0]
        for k in range(3):
            s[k] = newest[1 + k] + newest[4 + k] * dt + x[X_CORR + k] - newest[10 + k]
        for k in range(3, 9):
            s[k] = newest[1 + k] + x[X_CORR + k] - newest[10 + k]
        return
    for i in range(n - 1, 0, -1):
        a = hist[(start + i - 1) % depth]
        if a[0] <= t:
            b = hist[(start + i) % depth]
            w = (t - a[0]) / (b[0] - a[0])  # the state, and the corrections it had then, both interpolated
            for k in range(9):
                s[k] = (a[1 + k] + w * (b[1 + k] - a[1 + k]) + x[X_CORR + k]
                        - (a[10 + k] + w * (b[10 + k] - a[10 + k])))
            return
    older = hist[start]
    for k in range(9):
        s[k] = older[1 + k] + x[X_CORR + k] - older[10 + k]


@njit(cache=True)
def carry(x: np.ndarray, c: np.ndarray, P: np.ndarray, T: float, out: np.ndarray) -> None:
    """out = Φ P Φᵀ + Q over T (s), Φ = I + A at the newest IMU sample's specific force and attitude
    (``out`` may be ``P``). A's blocks: T I at (p, v), −T²/2 [Mf]× at (p, θ), −T²/2 M at (p, b_a),
    −T [Mf]× at (v, θ), T²/2 [Mf]× M at (v, b_g), −T M at (v, b_a), −T M at (θ, b_g)."""
    ax, ay, az = x[X_AF], x[X_AF + 1], x[X_AF + 2]
    Sk = (0.0, -az, ay, az, 0.0, -ax, -ay, ax, 0.0)
    M = _mid_attitude(x)
    SkM = _matmul(Sk, M)
    A = np.zeros((9, 15))  # A's rows of p, v and theta (the rest of A is zero)
    hn = -0.5 * T * T
    hp = 0.5 * T * T
    for i in range(3):
        A[i, 3 + i] = T
        for j in range(3):
            A[i, 6 + j] = Sk[3 * i + j] * hn
            A[i, 12 + j] = M[3 * i + j] * hn
            A[3 + i, 6 + j] = Sk[3 * i + j] * -T
            A[3 + i, 9 + j] = SkM[3 * i + j] * hp
            A[3 + i, 12 + j] = M[3 * i + j] * -T
            A[6 + i, 9 + j] = M[3 * i + j] * -T
    B = np.empty((15, 15))  # Φ P: only the rows of p, v and theta change
    for i in range(15):
        for j in range(15):
            s = P[i, j]
            if i < 9:
                for k in range(3, 15):
                    s += A[i, k] * P[k, j]
            B[i, j] = s
    for i in range(15):  # (Φ P) Φᵀ: only the columns of p, v and theta change
        for j in range(15):
            if j < 9:
                s = B[i, j]
                for k in range(3, 15):
                    s += B[i, k] * A[j, k]
                out[i, j] = s
            else:
                out[i, j] = B[i, j]
    na2, T2 = c[C_NA2], T * T
    for i in range(3):
        out[i, i] += na2 * T2 * T / 3.0
        out[i, 3 + i] += 0.5 * na2 * T2
        out[3 + i, i] += 0.5 * na2 * T2
        out[3 + i, 3 + i] += na2 * T
        out[6 + i, 6 + i] += c[C_NG2] * T
        out[9 + i, 9 + i] += c[C_WG2] * T
        out[12 + i, 12 + i] += c[C_WA2] * T


@njit(cache=True)
def flush(x: np.ndarray, c: np.ndarray, P: np.ndarray) -> None:
    """Carry P over the IMU time not carried yet (before each update, and at least every C_STEPMAX)."""
    T = x[X_PEND]
    if T > 0.0:
        x[X_PEND] = 0.0
        carry(x, c, P, T, P)
        x[X_PRED] += 1.0
        if int(x[X_PRED]) % 64 == 0:  # rounding makes P drift from symmetric, slowly
            for i in range(15):
                for j in range(i + 1, 15):
                    m = 0.5 * (P[i, j] + P[j, i])
                    P[i, j] = m
                    P[j, i] = m


@njit(cache=True)
def current_P(x: np.ndarray, c: np.ndarray, P: np.ndarray, out: np.ndarray) -> None:
    """out = P carried to now, without storing it (reading the covariance changes nothing)."""
    T = x[X_PEND]
    if T > 0.0:
        carry(x, c, P, T, out)
    else:
        for i in range(15):
            for j in range(15):
                out[i, j] = P[i, j]
