"""Each packet's fate for N cells at once: the link model's counter-based draws over whole arrays.

In:  per cell a :class:`~bridge.link.model.LinkConfig` (loss %, burst length, delays and jitter ms, dup and
     reorder %), a direction (``up``/``down``) and the number of packets
Out: :class:`Fates`: per cell and packet whether it is lost, its delay (s), whether it is duplicated and
     its duplicate's delay (s), drawn bit for bit as :class:`~bridge.link.impairment.LinkImpairment` draws
     them one packet at a time (SplitMix64 of the stream key, direction and packet number)

Split out of :mod:`bridge.link.plan`, which plans every cell's traffic from these fates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

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


# -- the draws -------------------------------------------------------------------------------------
def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser (:func:`bridge.link.impairment._mix`) in place on a uint64 array (wrapping)."""
    z += _C1
    z ^= z >> _U30
    z *= _C2
    z ^= z >> _U27
    z *= _C3
    z ^= z >> _U31
    return z


def uniforms(keys: np.ndarray, count: int, draw: int) -> np.ndarray:
    """``link.uniform(key, n, draw)`` for every key (rows) and n = 0..count-1 (columns): [len(keys), count]."""
    n = np.arange(count, dtype=np.uint64)
    inner = _mix(((n & np.uint64(0xFFFFFFFFFFFF)) << _U8) | np.uint64(draw))
    z = keys[:, None] ^ inner[None, :]
    _mix(z)
    out = (z >> _U11).astype(np.float64)
    out += 0.5
    out *= 1.0 / 9007199254740992.0
    return out


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


def _poly(c: tuple[float, ...], r: np.ndarray) -> np.ndarray:
    """Horner's rule in the order of statistics' AS241: (((c0 r + c1) r + c2) ... ) + c7."""
    v = c[0] * r + c[1]
    for k in c[2:]:
        v = v * r + k
    return v


def normal_inv_cdf(p: np.ndarray, sigma: float) -> np.ndarray:
    """``NormalDist(0, sigma).inv_cdf(p)`` elementwise, the same operations (Wichura's AS241) in the
    same order; the tail's log is :func:`math.log` (numpy's differs in the last bit now and then)."""
    q = p - 0.5
    x = np.empty_like(p)
    mid = np.abs(q) <= 0.425
    qm = q[mid]
    r = 0.180625 - qm * qm
    x[mid] = (_poly(_A, r) * qm) / _poly(_B, r)
    tail = ~mid
    if tail.any():
        qt = q[tail]
        pt = p[tail]
        r = np.where(qt <= 0.0, pt, 1.0 - pt)
        r = np.sqrt(-np.array([math.log(v) for v in r.tolist()]))
        xt = np.empty_like(r)
        near = r <= 5.0
        rn = r[near] - 1.6
        xt[near] = _poly(_C, rn) / _poly(_D, rn)
        rf = r[~near] - 5.0
        xt[~near] = _poly(_E, rf) / _poly(_F, rf)
        xt = np.where(qt < 0.0, -xt, xt)
        x[tail] = xt
    return 0.0 + x * sigma


@dataclass
class Fates:
    """The random part of the fates of packets 0..count-1 of one direction of each cell ([cells, count])."""

    lost: np.ndarray  # bool: Bernoulli or Gilbert–Elliott loss
    jitter: np.ndarray  # s
    held: np.ndarray  # bool: held back past its successor
    dup: np.ndarray  # bool: a duplicate follows
    dup_jitter: np.ndarray  # s, the duplicate's
    jittered: bool = True  # some cell's packets have jitter (else ``jitter`` is all zero)
    reordered: bool = True  # some cell holds packets back (else ``held`` is all false)
    duplicated: bool = True  # some cell duplicates (else ``dup`` is all false)


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


def _jitters(cfg: LinkConfig, u: np.ndarray, bound: float, lo: float, hi: float) -> np.ndarray:
    if cfg.jitter == "uniform":
        return (2.0 * u - 1.0) * bound
    x = normal_inv_cdf(lo + u * (hi - lo), cfg.jitter_ms / 1000.0)
    return np.clip(x, -bound, bound)


def draw_fates(cfgs: Sequence[LinkConfig], direction: str, count: int) -> Fates:
    """The fates :class:`~bridge.link.model.FateStream` gives packets 0..count-1 of ``direction``, per cell."""
    n = len(cfgs)
    lost = np.zeros((n, count), bool)
    jitter = np.zeros((n, count))
    held = np.zeros((n, count), bool)
    dup = np.zeros((n, count), bool)
    dup_jitter = np.zeros((n, count))
    if count == 0:
        return Fates(lost, jitter, held, dup, dup_jitter, False, False, False)
    keys = np.array([stream_key(c.seed, direction) for c in cfgs], dtype=np.uint64)
    ge = [i for i, c in enumerate(cfgs) if c.burst_len >= 1.0 and 0.0 < c.loss_pct / 100.0 < 1.0]
    bern = [i for i, c in enumerate(cfgs) if c.loss_pct > 0.0 and i not in set(ge)]
    if bern:
        loss = np.array([cfgs[i].loss_pct / 100.0 for i in bern])
        lost[bern] = uniforms(keys[bern], count, _D_LOSS) < loss[:, None]
    if ge:
        L = np.array([cfgs[i].loss_pct / 100.0 for i in ge])
        r = np.array([1.0 / cfgs[i].burst_len for i in ge])
        p = np.array([min(1.0, (cfgs[i].loss_pct / 100.0) * (1.0 / cfgs[i].burst_len)
                          / (1.0 - cfgs[i].loss_pct / 100.0)) for i in ge])
        u = uniforms(keys[ge], count, _D_LOSS)
        bad = uniforms(keys[ge], 1, _D_GE_START)[:, 0] < L  # the chain starts in its stationary distribution
        out = np.empty((len(ge), count), bool)
        for k in range(count):  # a Markov chain: sequential in the packet number, vectorised over cells
            uk = u[:, k]
            bad = np.where(bad, uk >= r, uk < p)
            out[:, k] = bad
        lost[ge] = out
    hold = [i for i, c in enumerate(cfgs) if c.reorder_pct > 0.0]
    if hold:
        h = np.array([cfgs[i].reorder_pct / 100.0 for i in hold])
        held[hold] = uniforms(keys[hold], count, _D_HOLD) < h[:, None]
    dups = [i for i, c in enumerate(cfgs) if c.dup_pct > 0.0]
    if dups:
        d = np.array([cfgs[i].dup_pct / 100.0 for i in dups])
        dup[dups] = uniforms(keys[dups], count, _D_DUP) < d[:, None]
    jittered = False
    for i, c in enumerate(cfgs):
        bound, lo, hi = _jitter_params(c)
        if bound == 0.0:
            continue
        jittered = True
        jitter[i] = _jitters(c, uniforms(keys[i:i + 1], count, _D_JITTER)[0], bound, lo, hi)
        if dup[i].any():
            dup_jitter[i] = _jitters(c, uniforms(keys[i:i + 1], count, _D_DUP_JITTER)[0], bound, lo, hi)
    return Fates(lost, jitter, held, dup, dup_jitter, jittered, bool(hold), bool(dups))
