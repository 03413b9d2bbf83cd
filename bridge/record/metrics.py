"""The numbers of a run: tracking error, settling, the finite-time bound, input smoothness.

In:  trace arrays by column (:data:`~bridge.record.columns.TRACE_COLUMNS`: s, m, m/s, rad, N), the
     mission, the law's gains, and the run's clock, outcome, events and link statistics
Out: ``summary.json`` as a dict (errors m or rad, times s, inputs N and N/s); p50 / p95 / p99 / max
     of a sample

All computed from the trace arrays (the same ones ``trace.csv`` holds), so the summary can
always be rebuilt from the trace.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controller.gains import Gains
from missions import Mission

AXES = ("x", "y", "z", "psi")
BANDS = {"x": 0.01, "y": 0.01, "z": 0.01, "psi": 0.01}  # m, m, m, rad
RMS_FROM_S = 10.0


def percentiles(values: Any, scale: float = 1.0, empty: float | None = 0.0) -> dict[str, float | None]:
    """p50 / p95 / p99 / max of a sample times ``scale`` (``empty`` for each when there is none)."""
    a = np.asarray(values, dtype=float)
    if not a.size:
        return {"p50": empty, "p95": empty, "p99": empty, "max": empty}
    a = a * scale
    p50, p95, p99 = np.percentile(a, (50.0, 95.0, 99.0))
    return {"p50": float(p50), "p95": float(p95), "p99": float(p99), "max": float(a.max())}


def errors(trace: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Tracking error per axis (psi wrapped to (-pi, pi])."""
    out = {a: trace[a] - trace[a + "_ref"] for a in ("x", "y", "z")}
    d = trace["psi"] - trace["psi_ref"]
    out["psi"] = (d + np.pi) % (2 * np.pi) - np.pi
    return out


def rms_3d(trace: dict[str, np.ndarray], t_from: float = RMS_FROM_S) -> float:
    """3-D position RMS error over t >= t_from (the issue's headline figure)."""
    e = errors(trace)
    m = trace["t"] >= t_from
    if not m.any():
        return float("nan")
    return float(np.sqrt(np.mean(e["x"][m] ** 2 + e["y"][m] ** 2 + e["z"][m] ** 2)))


def settling_time(t: np.ndarray, e: np.ndarray, start: float, end: float, band: float) -> float:
    """Time after ``start`` when |e| last leaves ``band`` before ``end`` (0 if never out)."""
    m = (t >= start) & (t < end)
    tt, ee = t[m], np.abs(e[m])
    out = np.nonzero(ee > band)[0]
    if len(out) == 0:
        return 0.0
    i = out[-1]
    return float((tt[i + 1] if i + 1 < len(tt) else tt[i] + (tt[1] - tt[0] if len(tt) > 1 else 0.0)) - start)


def finite_time_bound(e0: float, c: float, alpha: float) -> float:
    """Eq. (11)/(19): T <= V0^(1-alpha) / (c (1-alpha)), V0 = e0^2 / 2 (outer step)."""
    return (0.5 * e0 * e0) ** (1.0 - alpha) / (c * (1.0 - alpha))


def summarise(
    trace: dict[str, np.ndarray],
    mission: Mission,
    gains: Gains,
    *,
    clock: str,
    outcome: str,
    events: list[dict[str, Any]] | None = None,
    link: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The ``summary.json`` of docs/design.md, "Files of a run" (fixed keys, plus a few extras)."""
    t = trace["t"]
    n = len(t)
    dur = float(t[-1] - t[0] + 1.0 / mission.rate_hz) if n else 0.0
    err = errors(trace) if n else {a: np.zeros(0) for a in AXES}
    changes = [c for c in mission.trajectory.change_times() if n and c <= t[-1]]
    ends = changes[1:] + [float("inf")] if changes else []  # each change's segment end
    outer = {"x": gains.position, "y": gains.position, "z": gains.z, "psi": gains.yaw}
    rms_from = min(RMS_FROM_S, 0.5 * mission.duration_s)
    late = t >= rms_from if n else np.zeros(0, bool)
    axes: dict[str, Any] = {}
    for a in AXES:
        e = err[a]
        settle = [settling_time(t, e, c, end, BANDS[a]) for c, end in zip(changes, ends, strict=True)]
        bounds = []
        for c in changes:
            i = int(np.searchsorted(t, c))
            e0 = float(e[i]) if i < n else 0.0
            bounds.append(finite_time_bound(e0, outer[a].c, outer[a].alpha))
        axes[a] = {
            "rms": _num(np.sqrt(np.mean(e[late] ** 2))) if late.any() else None,
            "max": _num(np.max(np.abs(e[late]))) if late.any() else None,
            "rms_all": _num(np.sqrt(np.mean(e**2))) if n else None,
            "settling_s": _num(max(settle)) if settle else None,
            "bound_s": _num(max(bounds)) if bounds else None,
            "settling_per_change_s": [_num(s) for s in settle],
            "bound_per_change_s": [_num(b) for b in bounds],
        }
    inputs = {}
    for u in ("u1", "u2", "u3", "u4"):
        v = trace[u]
        inputs[u] = {
            "min": _num(v.min()) if n else None,
            "max": _num(v.max()) if n else None,
            "tv_per_s": _num(np.abs(np.diff(v)).sum() / dur) if n > 1 else 0.0,
        }
    return {
        "mission": mission.name,
        "clock": clock,
        "controller": mission.controller,
        "profile": mission.profile,
        "seed": mission.seed,
        "rate_hz": mission.rate_hz,
        "duration_s": _num(dur),
        "rms_from_s": float(rms_from),
        "rms_3d": _num(rms_3d(trace, rms_from)) if n else None,
        "axes": axes,
        "inputs": inputs,
        "link": link or empty_link(),
        "events": events or [],
        "outcome": outcome,
    }


def empty_link() -> dict[str, Any]:
    """The ``link`` block of a run that carried no packets (each direction its own dicts)."""

    def side() -> dict[str, Any]:
        return {"sent": 0, "delivered": 0, "lost": 0, "duplicated": 0, "reordered": 0,
                "delay_ms": {"p50": 0.0, "p95": 0.0, "p99": 0.0, "max": 0.0}}

    return {"up": side(), "down": side(), "rejected": {}}


def _num(v: Any) -> float | None:
    f = float(v)
    return f if math.isfinite(f) else None
