"""The batch engine's figures: running sums and maxima per cell as the flight goes, and the cells.csv row.

In:  per control step the states [12, n] (eq. 7: m), the reference sample (m), u2 [n] (N); per cell the
     steps flown, the outcome, the packet counts
Out: per cell ``rms``/``max`` m, ``settling_s``/``flown_s`` s, ``tv_u2`` N/s, ``ripple_u2`` N, the same numbers
     bridge.sweep.cells.row_from_run takes from the scalar loop's run
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bridge.autopilot.kernelcache import njit

RIPPLE_WINDOW_S = 0.2  # bridge.sweep.cells.RIPPLE_WINDOW_S (that layer is above this one)


@dataclass
class Metrics:
    """Running figures of every cell, updated once per control step (the trace row of that step) by the
    flight's kernel (bridge.batch.flight)."""

    sq_sum: np.ndarray  # sum over t >= rms_from of |3-D error|^2
    sq_max: np.ndarray
    last_out: np.ndarray  # [segments, 3, n]: last step outside the settling band, per change and axis (-1)
    tv: np.ndarray  # sum of |u2_k - u2_{k-1}|
    u2: np.ndarray  # [steps, n]: u2 as recorded, for the ripple



def measured_rows(met: Metrics, flown: np.ndarray, outcome: np.ndarray, counts: dict[str, np.ndarray],
                  changes: list[float], rms_from: float, t_all: np.ndarray, rate: float) -> list[dict[str, Any]]:
    """The measured columns of each cell's row from its running figures."""
    first_late = int(np.searchsorted(t_all, rms_from, side="left"))
    ripple = _ripples(met.u2, flown, t_all, rate)
    rows = []
    for i in range(len(flown)):
        L = int(flown[i])
        n_late = max(0, L - first_late)
        dur = float(t_all[L - 1] - t_all[0] + 1.0 / rate)
        rms = _num(math.sqrt(met.sq_sum[i] / n_late)) if n_late else None
        mx = _num(math.sqrt(met.sq_max[i])) if n_late else None
        settle = [s for s in (_settling(met.last_out[:, a, i], changes, t_all, L) for a in range(3))
                  if s is not None]
        rows.append({
            "rms": rms, "max": mx,
            "settling_s": max(settle) if settle else None,
            "tv_u2": _num(met.tv[i] / dur) if L > 1 else 0.0,
            "ripple_u2": ripple[i],
            "outcome": str(outcome[i]),
            "up_sent": int(counts["up_sent"][i]), "up_lost": int(counts["up_lost"][i]),
            "down_sent": int(counts["down_sent"][i]), "down_lost": int(counts["down_lost"][i]),
            "flown_s": _num(dur), "error": "",
            "policies": "",  # not judged: the batch keeps no trace or events (scope.flights_problem: no geofence)
        })
    return rows


def _settling(last_out: np.ndarray, changes: list[float], t: np.ndarray, L: int) -> float | None:
    """metrics.settling_time's worst over the set-point changes flown, from the last step outside the band."""
    if L == 0:
        return None
    flown_changes = [c for c in changes if c <= t[L - 1]]
    if not flown_changes:
        return None
    ends = flown_changes[1:] + [math.inf]
    worst = None
    for s, (c, end) in enumerate(zip(flown_changes, ends, strict=True)):
        lo = int(np.searchsorted(t[:L], c, side="left"))
        hi = int(np.searchsorted(t[:L], end, side="left"))
        i = int(last_out[s])
        if hi <= lo or i < lo:
            v = 0.0
        elif i + 1 < hi:
            v = float(t[i + 1] - c)
        else:
            v = float(t[i] + (t[lo + 1] - t[lo] if hi - lo > 1 else 0.0) - c)
        worst = v if worst is None else max(worst, v)
    return _num(worst) if worst is not None else None


def _ripples(u2: np.ndarray, flown: np.ndarray, t: np.ndarray, rate_hz: float) -> list[float | None]:
    """bridge.sweep.cells.ripple_rms of each cell's u2 over its own flight ([steps, n] history).

    Cells that flew the same number of steps go together; a group of two or more goes through the compiled
    :func:`_ripple_cells`, which does numpy's arithmetic of the one-cell path below (u2 minus its first value,
    its running sum, the centred mean, the mean square summed in step order as numpy's axis-0 mean sums it)
    with one running-sum buffer: the numpy way made four fresh [steps, n] temporaries (240 MB for 1000 cells
    of the 30 s sine), whose first touch alone cost ~2 s on this VM. A lone cell keeps numpy's own path
    (its axis-0 mean of one column sums pairwise, not in step order)."""
    n_win = 2 * int(round(0.5 * RIPPLE_WINDOW_S * rate_hz)) + 1
    h = n_win // 2
    groups: dict[int, list[int]] = {}
    for i, L in enumerate(flown):
        groups.setdefault(int(L), []).append(i)
    res = np.zeros(len(flown))
    by_cell = np.ascontiguousarray(u2.T)  # [n, steps]: the flight's own array, no copy
    for L, cells in groups.items():
        if L < 3 * n_win:
            continue
        tt = t[:L]
        sel = tt >= tt[0] + 0.5 * (tt[-1] - tt[0])
        sel[: h + 1] = False
        sel[L - h - 1:] = False
        idx = np.nonzero(sel)[0]
        if not len(idx):
            continue
        if len(cells) > 1:
            _ripple_cells(by_cell, np.array(cells, np.int64), L, idx, n_win, h, res)
            continue
        u = u2[:L, cells] - u2[0, cells]  # shifted: the running sum stays small
        csum = np.zeros((L + 1, len(cells)))
        np.cumsum(u, axis=0, out=csum[1:])
        mean = (csum[idx + h + 1] - csum[idx - h]) / n_win
        dev = u[idx] - mean
        res[cells] = np.sqrt(np.mean(dev * dev, axis=0))
    return [_num(v) for v in res]


@njit(cache=True)
def _ripple_cells(u2: np.ndarray, cells: np.ndarray, L: int, idx: np.ndarray, n_win: int, h: int,
                  out: np.ndarray) -> None:  # pragma: no cover
    """The ripple (N) of each cell c of ``cells`` (all flew L steps) from u2 [n, steps] (N) into out[c]: the
    RMS over the steps ``idx`` of u2 minus its centred running mean over n_win steps (h either side)."""
    csum = np.empty(L + 1)
    for c in cells:
        u0 = u2[c, 0]
        csum[0] = 0.0
        for k in range(L):  # np.cumsum's order: out[k] = out[k - 1] + u[k] (u[0] = 0.0: out[0] is 0.0 + 0.0)
            csum[k + 1] = csum[k] + (u2[c, k] - u0)
        s = 0.0
        for i in idx:
            d = (u2[c, i] - u0) - (csum[i + h + 1] - csum[i - h]) / n_win
            s += d * d
        out[c] = math.sqrt(s / len(idx))


def _num(v: Any) -> float | None:
    f = float(v)
    return f if math.isfinite(f) else None


