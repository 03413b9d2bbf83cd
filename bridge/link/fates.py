"""Each packet's fate, cell by cell and compiled: the link model's counter-based draws.

In:  per cell a :class:`~bridge.link.model.LinkConfig` (loss %, burst length, delays and jitter ms, dup and
     reorder %), a direction (``up``/``down``) and the number of packets
Out: :class:`Fates`: per cell and packet whether it is lost, its delay (s), whether it is duplicated and
     its duplicate's delay (s), drawn bit for bit as :class:`~bridge.link.impairment.LinkImpairment` draws
     them one packet at a time (SplitMix64 of the stream key, direction and packet number)

:func:`draw_cell` draws one direction of one cell (the planner, :mod:`bridge.link.plan_cell`, calls it per
cell); :func:`draw_fates` lays many cells' out as arrays (tests/test_batch.py checks them draw for draw).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.link.impairment import (  # the draw numbers and bound are the model's: one definition of a fate
    _D_DUP,
    _D_DUP_JITTER,
    _D_GE_START,
    _D_HOLD,
    _D_JITTER,
    _D_LOSS,
    _NORMAL_BOUND_SIGMAS,
    stream_key,
)
from bridge.link.model import LinkConfig

_C1, _C2, _C3 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_U30, _U27, _U31, _U11, _U8 = (np.uint64(v) for v in (30, 27, 31, 11, 8))
_M48 = np.uint64(0xFFFFFFFFFFFF)
_NO_LOSS, _BERNOULLI, _GILBERT = 0, 1, 2  # a direction's loss (ints[0])
_UNIFORM, _NORMAL = 1, 2  # its jitter (ints[1]; 0: none)
# the columns of a direction's float parameters (fate_params)
_LOSS, _GE_R, _GE_P, HOLD_P, DUP_P, _SIGMA, BOUND_S, _LO, _HI, DELAY_S = range(10)
N_PARAMS = 10


# -- the draws -------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:  # pragma: no cover
    """SplitMix64's finaliser (:func:`bridge.link.impairment._mix`), wrapping."""
    z = z + _C1
    z = z ^ (z >> _U30)
    z = z * _C2
    z = z ^ (z >> _U27)
    z = z * _C3
    return z ^ (z >> _U31)


@njit(cache=True, inline="always")
def _uniform(key: np.uint64, n: int, draw: int) -> float:  # pragma: no cover
    """``link.uniform(key, n, draw)``: draw number ``draw`` of packet ``n``."""
    z = _mix(key ^ _mix(((np.uint64(n) & _M48) << _U8) | np.uint64(draw)))
    return (float(z >> _U11) + 0.5) * (1.0 / 9007199254740992.0)


_A = (2.5090809287301226727e+3, 3.3430575583588128105e+4, 6.7265770927008700853e+4, 4.5921953931549871457e+4,
      1.3731693765509461125e+4, 1.9715909503065514427e+3, 1.3314166789178437745e+2, 3.3871328727963666080e+0)
_B = (5.2264952788528545610e+3, 2.8729085735721942674e+4, 3.9307895800092710610e+4, 2.1213794301586595867e+4,
      5.3941960214247511077e+3, 6.8718700749205790830e+2, 4.2313330701600911252e+1, 1.0)
_C = (7.7454501427834140764e-4, 2.2723844989269184583e-2, 2.4178072517745061177e-1, 1.2704582524523683826e+0,
      3.6478483247632046050e+0, 5.7694972214606914055e+0, 4.6303378461565452959e+0, 1.4234371107496835773e+0)
_D = (1.05075007164441684324e-9, 5.4759380849953449460e-4, 1.5198666563616457197e-2, 1.4810397642748007459e-1,
      6.8976733498510000455e-1, 1.6763848301838038494e+0, 2.0531916266377588219e+0, 1.0)
_E = (2.01033439929228813265e-7, 2.71155556874348757815e-5, 1.24266094738807843860e-3, 2.65321895265761230930e-2,
      2.96560571828504891230e-1, 1.78482653991729133580e+0, 5.46378491116411436990e+0, 6.65790464350110377720e+0)
_F = (2.04426310338993978564e-15, 1.42151175831644588870e-7, 1.84631831751005468180e-5, 7.86869131145613259100e-4,
      1.48753612908506148525e-2, 1.36929880922735805310e-1, 5.99832206555887937690e-1, 1.0)


@njit(cache=True, inline="always")
def _poly(c: tuple, r: float) -> float:  # pragma: no cover
    """Horner's rule in the order of statistics' AS241: (((c0 r + c1) r + c2) ... ) + c7."""
    v = c[0] * r + c[1]
    for k in c[2:]:
        v = v * r + k
    return v


@njit(cache=True, inline="always")
def _normal_inv_cdf(p: float, sigma: float) -> float:  # pragma: no cover
    """``NormalDist(0, sigma).inv_cdf(p)``: the same operations (Wichura's AS241) in the same order."""
    q = p - 0.5
    if abs(q) <= 0.425:
        r = 0.180625 - q * q
        x = (_poly(_A, r) * q) / _poly(_B, r)
    else:
        r = math.sqrt(-math.log(p if q <= 0.0 else 1.0 - p))
        x = _poly(_C, r - 1.6) / _poly(_D, r - 1.6) if r <= 5.0 else _poly(_E, r - 5.0) / _poly(_F, r - 5.0)
        x = -x if q < 0.0 else x
    return 0.0 + x * sigma


@njit(cache=True, inline="always")
def _jitter(kind: int, u: float, fp: np.ndarray) -> float:  # pragma: no cover
    """A packet's jitter (s) from its uniform draw u: uniform in +-bound, or the bounded normal's inverse CDF."""
    if kind == _UNIFORM:
        return (2.0 * u - 1.0) * fp[BOUND_S]
    x = _normal_inv_cdf(fp[_LO] + u * (fp[_HI] - fp[_LO]), fp[_SIGMA])
    return min(max(x, -fp[BOUND_S]), fp[BOUND_S])


@njit(cache=True, nogil=True)
def draw_cell(key: np.uint64, ints: np.ndarray, fp: np.ndarray, count: int, lost: np.ndarray, jitter: np.ndarray,
              held: np.ndarray, dup: np.ndarray, dup_jitter: np.ndarray) -> None:  # pragma: no cover
    """The fates of packets 0..count-1 of one direction of one cell (:func:`fate_params`) into the first
    ``count`` places of lost, jitter (s), held, dup and dup_jitter (s; 0 where no duplicate)."""
    loss, jk = ints[0], ints[1]
    bad = loss == _GILBERT and _uniform(key, 0, _D_GE_START) < fp[_LOSS]  # the chain starts stationary
    for k in range(count):
        if loss == _BERNOULLI:
            lost[k] = _uniform(key, k, _D_LOSS) < fp[_LOSS]
        elif loss == _GILBERT:  # a Markov chain, sequential in the packet number
            u = _uniform(key, k, _D_LOSS)
            bad = u >= fp[_GE_R] if bad else u < fp[_GE_P]
            lost[k] = bad
        else:
            lost[k] = False
        held[k] = fp[HOLD_P] > 0.0 and _uniform(key, k, _D_HOLD) < fp[HOLD_P]
        dup[k] = fp[DUP_P] > 0.0 and _uniform(key, k, _D_DUP) < fp[DUP_P]
        jitter[k] = _jitter(jk, _uniform(key, k, _D_JITTER), fp) if jk else 0.0
        dup_jitter[k] = _jitter(jk, _uniform(key, k, _D_DUP_JITTER), fp) if jk and dup[k] else 0.0


def fate_params(cfgs: Sequence[LinkConfig],
                direction: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`draw_cell` and the planner (bridge.link.plan_cell) take of one direction of each cell:
    the stream keys [n] uint64, the loss and jitter kinds [n, 2], the float parameters [n, N_PARAMS] (loss
    fraction, Gilbert-Elliott r and p, reorder and dup fractions, jitter sigma and bound s and the normal's
    CDF at -+bound, delay s), the blackout windows [n, B, 2] (start, duration s) and their numbers [n]."""
    n = len(cfgs)
    keys = np.array([stream_key(c.seed, direction) for c in cfgs], dtype=np.uint64)
    ints = np.zeros((n, 2), np.int64)
    fp = np.zeros((n, N_PARAMS))
    nb = np.array([len(c.blackouts) for c in cfgs], np.int64)
    bo = np.zeros((n, max(1, int(nb.max()) if n else 1), 2))
    for i, c in enumerate(cfgs):
        L = c.loss_pct / 100.0
        if c.burst_len >= 1.0 and 0.0 < L < 1.0:
            ints[i, 0] = _GILBERT
            fp[i, _GE_R] = 1.0 / c.burst_len
            fp[i, _GE_P] = min(1.0, L * (1.0 / c.burst_len) / (1.0 - L))
        elif c.loss_pct > 0.0:
            ints[i, 0] = _BERNOULLI
        fp[i, _LOSS] = L
        fp[i, HOLD_P] = c.reorder_pct / 100.0
        fp[i, DUP_P] = c.dup_pct / 100.0
        bound, lo, hi = _jitter_params(c)
        if bound > 0.0:
            ints[i, 1] = _UNIFORM if c.jitter == "uniform" else _NORMAL
            fp[i, _SIGMA], fp[i, BOUND_S], fp[i, _LO], fp[i, _HI] = c.jitter_ms / 1000.0, bound, lo, hi
        fp[i, DELAY_S] = c.delay_ms / 1000.0
        for w, (start, dur) in enumerate(c.blackouts):
            bo[i, w] = start, dur
    return keys, ints, fp, bo, nb


@dataclass
class Fates:
    """The random part of the fates of packets 0..count-1 of one direction of each cell ([cells, count])."""

    lost: np.ndarray  # bool: Bernoulli or Gilbert–Elliott loss
    jitter: np.ndarray  # s
    held: np.ndarray  # bool: held back past its successor
    dup: np.ndarray  # bool: a duplicate follows
    dup_jitter: np.ndarray  # s, the duplicate's


def _jitter_params(cfg: LinkConfig) -> tuple[float, float, float]:
    """(bound s, lo, hi) of :class:`~bridge.link.model.FateStream`'s jitter (bound 0: none; lo = hi = 0: uniform)."""
    delay = cfg.delay_ms / 1000.0
    j = cfg.jitter_ms / 1000.0
    if not (j > 0.0 and delay > 0.0):
        return 0.0, 0.0, 0.0
    if cfg.jitter == "uniform":
        return min(j, delay), 0.0, 0.0
    b = min(delay, _NORMAL_BOUND_SIGMAS * j)
    nd = NormalDist(0.0, j)
    return b, nd.cdf(-b), nd.cdf(b)


def draw_fates(cfgs: Sequence[LinkConfig], direction: str, count: int) -> Fates:
    """The fates :class:`~bridge.link.model.FateStream` gives packets 0..count-1 of ``direction``, per cell
    (:func:`draw_cell`, cell by cell)."""
    n = len(cfgs)
    out = Fates(np.zeros((n, count), bool), np.zeros((n, count)), np.zeros((n, count), bool),
                np.zeros((n, count), bool), np.zeros((n, count)))
    keys, ints, fp, _, _ = fate_params(cfgs, direction)
    for i in range(n):
        draw_cell(keys[i], ints[i], fp[i], count, out.lost[i], out.jitter[i], out.held[i], out.dup[i],
                  out.dup_jitter[i])
    return out
