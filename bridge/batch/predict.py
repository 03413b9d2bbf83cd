"""The prediction for N cells at once: :class:`controller.predict.Predictor` over the cell axis.

In:  per cell the command lag (s) and the commands sent (time s, realisable u1..u4 N, omega_d rad/s), the
     nominal model, the largest step (s); each control step the states to carry (eq. 7: m, m/s, rad, rad/s),
     their stamps and the times to carry them to (s)
Out: the predicted states [12, k]

Each step is the scalar predictor's own :func:`controller.predict.nominal_rk4`, compiled
(bridge.batch.kernels).
"""

from __future__ import annotations

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.batch import kernels as K
from controller.nominal import Coefficients, Nominal


class BatchPredictor:
    """:class:`controller.predict.Predictor` for n cells: the newest state carried from its stamp to the
    aim time (s) through the nominal model with the commands sent since, in the same RK4 steps.

    Commands are kept in a ring by their number (``depth`` of them: enough to cover the longest a state
    may be used, plus the command lag). Each call advances every cell through its segments between command
    times (a cell with fewer segments takes steps of length 0, which leave its state exactly as it is),
    continuing from the last prediction while the state is the same one, as the scalar predictor does.
    """

    def __init__(self, nominal: Nominal, dt_max: float, lag_s: np.ndarray, depth: int) -> None:
        n = len(lag_s)
        self.n = n
        self.m = nominal.mass
        self.g = nominal.gravity
        c = Coefficients.of(nominal)
        self.dt_max = dt_max
        self.lag = lag_s
        self.depth = depth
        self.cmd_t = np.full((depth, n), np.inf)  # when each command counts from (send time + lag)
        self.cmd_u = np.zeros((depth, 5, n))  # u1..u4 realisable, omega_d
        self.total = np.zeros(n, np.int64)  # commands recorded so far
        self.from_t = np.full(n, np.nan)  # the state stamp the cache starts from
        self.cache_t = np.zeros(n)
        self.cache_X = np.zeros((12, n))
        self._coefficients = np.array((c.i1, c.i2, c.i3, c.jr_x, c.jr_y, c.l_x, c.l_y, c.l_z))  # for the kernel

    def sent(self, t: float, u: np.ndarray, omega_d: np.ndarray, which: np.ndarray) -> None:
        """Record the command sent at t (s) by the cells ``which`` (index array): u [4, len(which)] N, omega_d."""
        if not len(which):
            return
        slot = self.total[which] % self.depth
        self.cmd_t[slot, which] = t + self.lag[which]
        self.cmd_u[slot, :4, which] = u.T
        self.cmd_u[slot, 4, which] = omega_d
        self.total[which] += 1

    def predict(self, t_state: np.ndarray, X: np.ndarray, aim: np.ndarray, which: np.ndarray) -> np.ndarray:
        """X [12, len(which)] (measured at ``t_state``) carried to ``aim`` (s) for the cells ``which``."""
        if not len(which):
            return X
        out = np.empty_like(X)
        _predict_cells(t_state, X, aim, which, self.from_t, self.cache_t, self.cache_X, self.cmd_t, self.cmd_u,
                       self.total, self.dt_max, self.m, self.g, self._coefficients, out)
        return out


@njit(cache=True)
def _predict_cells(t_state: np.ndarray, X: np.ndarray, aim: np.ndarray, which: np.ndarray, from_t: np.ndarray,
                   cache_t: np.ndarray, cache_X: np.ndarray, cmd_t: np.ndarray, cmd_u: np.ndarray,
                   total: np.ndarray, dt_max: float, m: float, g: float, c: np.ndarray,
                   out: np.ndarray) -> None:  # pragma: no cover
    """:func:`carry` of each cell ``which[i]``: X[:, i] (measured at t_state[i] s) carried to aim[i] s, into
    out [12, len(which)]."""
    for i in range(len(which)):
        y = carry(which[i], t_state[i], K.column(X, i), aim[i], from_t, cache_t, cache_X, cmd_t, cmd_u, total,
                  dt_max, m, g, c)
        K.put_column(out, i, y)


@njit(cache=True)
def carry(j: int, ts: float, x: tuple, to: float, from_t: np.ndarray, cache_t: np.ndarray, cache_X: np.ndarray,
          cmd_t: np.ndarray, cmd_u: np.ndarray, total: np.ndarray, dt_max: float, m: float, g: float,
          c: np.ndarray) -> tuple:  # pragma: no cover
    """:meth:`controller.predict.Predictor.predict` of cell j: its state x (measured at ts s) carried to ``to``
    (s) in steps of at most dt_max s, through the segments between the times its commands count from
    (cmd_t [depth, n], a ring by number; cmd_u [depth, 5, n]: u1..u4 and omega_d), continuing the cached
    prediction (from_t, cache_t, cache_X [12, n], updated here) while the state is the same one."""
    depth = cmd_t.shape[0]
    i1, i2, i3, jr_x, jr_y, l_x, l_y, l_z = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]
    cont = from_t[j] == ts and cache_t[j] <= to
    Xp = K.column(cache_X, j) if cont else x
    tau = cache_t[j] if cont else ts
    n = total[j]
    used = min(n, depth)
    after = 0  # the command in effect at tau: the newest numbered with its time <= tau (-1: none)
    for k in range(used):
        if cmd_t[k, j] > tau:
            after += 1
    cur = n - 1 - after
    while tau < to:
        has_next = cur + 1 < n
        nxt = cmd_t[(cur + 1) % depth, j] if has_next else to
        end = nxt if nxt < to else to
        if cur >= 0:
            slot = cur % depth
            u0, u1, u2, u3, od = cmd_u[slot, 0, j], cmd_u[slot, 1, j], cmd_u[slot, 2, j], cmd_u[slot, 3, j], \
                cmd_u[slot, 4, j]
        else:
            u0 = u1 = u2 = u3 = od = 0.0
        span = end - tau
        kk = max(1, int(span / dt_max + 0.999999))
        h = span / kk
        for _ in range(kk):
            Xp = K.nominal_rk4(Xp, u0 / m, g, i1, i2, i3, jr_x, jr_y, l_x * u1, l_y * u2, l_z * u3, od, h)
        tau = end
        if end == nxt and has_next:
            cur += 1
    from_t[j] = ts
    cache_t[j] = to
    K.put_column(cache_X, j, Xp)
    return Xp


@njit(cache=True)
def record(j: int, t: float, lag: float, u: tuple, omega_d: float, cmd_t: np.ndarray, cmd_u: np.ndarray,
           total: np.ndarray) -> None:  # pragma: no cover
    """:meth:`BatchPredictor.sent` of cell j: the command sent at t (s), realisable u1..u4 (N) and omega_d (rad/s),
    counting from t + lag."""
    depth = cmd_t.shape[0]
    slot = total[j] % depth
    cmd_t[slot, j] = t + lag
    for i in range(4):
        cmd_u[slot, i, j] = u[i]
    cmd_u[slot, 4, j] = omega_d
    total[j] += 1
