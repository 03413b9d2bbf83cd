"""The numbers of a run: tracking error, settling, the finite-time bound, input smoothness.

In:  trace arrays by column (:data:`~bridge.record.columns.TRACE_COLUMNS`: s, m, m/s, rad, N), the
     mission, the law's gains, and the run's clock, outcome, events and link statistics
Out: ``summary.json`` as a dict (errors m or rad, times s, inputs N and N/s); p50 / p95 / p99 / max
     of a sample; the printed summary's ``air:`` line (:func:`air_text`, m/s, deg)

Each of u1..u4 has its total variation per second ``tv_per_s`` (N/s, the whole flight) and its
``period2`` component (N, :func:`period2`, over t >= ``rms_from_s``: the alternation at half the
control rate an explicitly stepped sliding mode leaves, issue 24); each of u2..u4 its ``ripple``
(N, :func:`ripple_rms`); a run whose vehicle flew on an
estimate (not ``truth``) has an ``estimation`` block: the RMS over the whole flight of the
estimate's errors (truth − ``*_est`` columns) in position (3-D, m), velocity (3-D, m/s) and
attitude (φ, θ, ψ together, rad, ψ wrapped) and, from the ``nees`` column, the mean NEES over
position, velocity and attitude (9 degrees of freedom: about 9 when the reported covariance is right).

All computed from the trace arrays (the same ones ``trace.csv`` holds), so the summary can
always be rebuilt from the trace.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from controller.gains import Gains
from controller.law import DISCRETIZED
from missions import Mission

AXES = ("x", "y", "z", "psi")
BANDS = {"x": 0.01, "y": 0.01, "z": 0.01, "psi": 0.01}  # m, m, m, rad
RMS_FROM_S = 10.0
RIPPLE_WINDOW_S = 0.2  # moving-average window of the u2 ripple: content above ~5 Hz counts


def after_faults(outcome: str, events: list[dict[str, Any]]) -> dict[str, Any]:
    """``ended_by``'s ``after_faults``: the timeline's faults before a flight that did not complete (why it ended)."""
    faults = [f"t={e['t']:.3f} s: {e['text']}" for e in events if e["kind"] == "fault"]
    return {"after_faults": faults} if outcome != "completed" and faults else {}


def not_reached(outcome: str, timeline: Sequence[Any], trace_t: np.ndarray, wind: Any = None) -> dict[str, Any]:
    """``ended_by``'s ``not_reached``: the timeline's events (``[[events]]``, ``--at``) and the ``[wind]`` gusts
    (``wind``, a :class:`plant.wind.WindConfig`, or None) scheduled after a flight that did not complete had ended
    (its last row's time, s), so never flown: said, as the run did not fly as asked."""
    said = sorted([*((e.t_s, e.text()) for e in timeline), *(wind.gust_notes() if wind else ())],
                  key=lambda n: n[0])
    if outcome == "completed" or not said:
        return {}
    end = float(trace_t[-1]) if len(trace_t) else 0.0
    late = [f"t={t:.3f} s: {text}" for t, text in said if t > end]
    return {"not_reached": late} if late else {}


def air_text(wind: Mapping[str, Any]) -> str:
    """The summary's line naming the air flown (``summary.json``'s ``wind`` block: the ``[wind]`` table with
    ``--wind``/``--turbulence`` laid over it): the steady wind at the start, the turbulence and its scaling, how many
    ``[wind]`` gusts; the wind and gust events, ``[wind]``'s too, are the summary's event lines. A wind event at the
    flight's first control step (``steady_at_start``) sets the steady wind flown from the start: that one is named,
    with the event and the ``[wind]`` steady wind it replaced (still the turbulence's pass speed and axes)."""
    level = wind.get("turbulence", "none")
    turbulence = f"turbulence {level}" + (f" (scaling {wind.get('turbulence_scaling')})" if level != "none" else "")
    n = len(wind.get("gusts") or ())
    gusts = f", {n} [wind] gust{'' if n == 1 else 's'}" if n else ""
    given = f"{wind.get('speed_mps', 0.0):g} m/s from {wind.get('from_deg', 0.0):g} deg"
    start = wind.get("steady_at_start")
    steady = given if start is None else (
        f"{start['speed_mps']:g} m/s from {start['from_deg']:g} deg from t = 0 ({start['by']}; in place of [wind]'s "
        f"{given}" + (", the turbulence's pass speed and axes)" if level != "none" else ")"))
    return f"air: wind {steady}, {turbulence}{gusts}; drag on the airspeed"


def plant_summary(blocks: Mapping[str, Any], trace: Mapping[str, np.ndarray],
                  events: list[dict[str, Any]]) -> dict[str, Any]:
    """``summary.json``'s plant blocks: ``gps_outages`` (:func:`gps_outages`, from the trace and the events on
    one clock), then the plant's own ``blocks`` (:func:`plant_blocks`; a SITL vehicle reports them in its
    stats); only those the flight had."""
    outages = gps_outages(trace, events)
    return {**({"gps_outages": outages} if outages else {}), **blocks}


def plant_blocks(plant: Any) -> dict[str, Any]:
    """The blocks the plant itself (:class:`plant.Quadrotor`) holds: ``wind`` (the configuration, the mean wind
    and the turbulence's std per axis over the flight, with MIL-HDBK-1797's σ: plant/wind.py), ``battery``
    (volts, amperes, mAh), ``impact`` (a hard touchdown: t s, speed m/s, tilt deg), ``rotor_effectiveness``;
    JSON as they are."""
    out: dict[str, Any] = {}
    if plant.wind is not None:
        out["wind"] = plant.wind.summary()
    if plant.battery is not None:
        out["battery"] = plant.battery.summary()
    if plant.impact is not None:
        t, speed, tilt = plant.impact
        out["impact"] = {"t": round(t, 6), "speed_mps": speed, "tilt_deg": math.degrees(tilt)}
    if plant.effectiveness != (1.0, 1.0, 1.0, 1.0):
        out["rotor_effectiveness"] = list(plant.effectiveness)
    return out


def gps_outages(trace: Mapping[str, np.ndarray], events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each GPS outage of the timeline (``fault`` events ``gps off`` .. ``gps on``, told by their typed ``gps``, or to
    the end): the estimate's 3-D position drift (m, truth − estimate) during it, at its max and at its end, and the
    mean NEES after it (to the next outage or the end; 9 degrees of freedom), from the trace arrays."""
    if "x_est" not in trace:
        return []
    t = trace["t"]
    err = np.sqrt(sum((trace[a] - trace[a + "_est"]) ** 2 for a in ("x", "y", "z")))
    # (the GPS each fault leaves on or off: its typed field, never its text)
    marks = [(e["t"], e["gps"]) for e in events if e["kind"] == "fault" and isinstance(e.get("gps"), bool)]
    out = []
    for i, (t_off, on) in enumerate(marks):
        if on:
            continue
        t_on = next((tm for tm, now in marks[i + 1:] if now), None)
        during = (t >= t_off) & (t <= (t[-1] if t_on is None else t_on))
        row: dict[str, Any] = {"off_s": t_off, "on_s": t_on,
                               "drift_max_m": float(err[during].max()) if during.any() else None,
                               "drift_at_end_m": float(err[during][-1]) if during.any() else None}
        if t_on is not None:
            t_next = next((tm for tm, now in marks[i + 1:] if not now and tm > t_on), t[-1] + 1.0)
            after = (t >= t_on) & (t < t_next) & np.isfinite(trace["nees"])
            row["nees_mean_after"] = float(trace["nees"][after].mean()) if after.any() else None
            row["drift_rms_after_m"] = float(np.sqrt(np.mean(err[(t >= t_on) & (t < t_next)] ** 2)))
        out.append(row)
    return out


def ripple_rms(t: np.ndarray, u: np.ndarray, rate_hz: float, window_s: float = RIPPLE_WINDOW_S) -> float:
    """High-frequency RMS of a signal over the second half of its time span (same unit as u).

    The signal minus its centred moving average over ``window_s`` (so content above about
    1/window_s Hz), over t >= half the span, half a window away from both ends. This is the
    limit-cycle detector: a chattering or oscillating attitude input has a large ripple.
    """
    n = 2 * int(round(0.5 * window_s * rate_hz)) + 1  # odd: the average is centred exactly
    if len(u) < 3 * n:
        return 0.0
    mean = np.convolve(u, np.ones(n) / n, mode="same")
    sel = t >= t[0] + 0.5 * (t[-1] - t[0])
    sel[: n // 2 + 1] = False
    sel[len(sel) - n // 2 - 1:] = False
    dev = u - mean
    sel &= np.isfinite(dev)  # a window over an unknown demand (NaN) says nothing
    if not sel.any():
        return 0.0
    return float(np.sqrt(np.mean(dev[sel] ** 2)))


def period2(u: np.ndarray) -> float:
    """The period-2 component of a sampled signal (same unit as u): the mean of |u[k] - 2 u[k+1] + u[k+2]| / 4.

    For u alternating +-a around a slow mean it is a; for a signal smooth at the sample rate it is about
    |u''| T^2 / 4, so almost 0. Samples next to an unknown demand (NaN) are left out; 0 for fewer than 3."""
    if len(u) < 3:
        return 0.0
    d = np.abs(u[:-2] - 2.0 * u[1:-1] + u[2:]) / 4.0
    d = d[np.isfinite(d)]
    return float(d.mean()) if d.size else 0.0


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
    estimator: str = "truth",
    sensors: str = "ideal",
) -> dict[str, Any]:
    """The ``summary.json`` of docs/design.md, "Files of a run" (fixed keys, plus a few extras). Its
    callers add how the run ended and its safety verdicts (``ended_by``, ``policies``:
    :mod:`bridge.record.policies`); a session also ``timing``, ``sitl`` and, in lockstep, ``lockstep``."""
    t = trace["t"]
    n = len(t)
    dur = float(t[-1] - t[0] + 1.0 / mission.rate_hz) if n else 0.0  # s: the rows' span (per second figures)
    # s: the mission's time flown, from its time 0 to its last recorded step's end; a real-time trace's first row is
    # step 1's (step 0 flew on a target that came mid-period), so rows x period said one period short
    flown = float(t[-1] + 1.0 / mission.rate_hz) if n else 0.0
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
        known = np.isfinite(v)  # NaN: a demand never recorded (a controller killed before its row)
        m = int(known.sum())
        inputs[u] = {
            "min": _num(v[known].min()) if m else None,
            "max": _num(v[known].max()) if m else None,
            "tv_per_s": _num(np.nansum(np.abs(np.diff(v))) / dur) if n > 1 else 0.0,
            "period2": _num(period2(v[late])) if n else None,
        }
        if u != "u1":
            inputs[u]["ripple"] = _num(ripple_rms(t, v, mission.rate_hz)) if n else None
    out = {
        "mission": mission.name,
        "clock": clock,
        "controller": mission.controller,
        "discretization": mission.discretization if mission.controller in DISCRETIZED else None,  # bsst's alone
        "profile": mission.profile,
        "seed": mission.seed,
        "rate_hz": mission.rate_hz,
        "duration_s": _num(flown),
        "mission_duration_s": float(mission.duration_s),  # as asked: a flight cut short flew less (duration_s)
        "rms_from_s": float(rms_from),
        "rms_3d": _num(rms_3d(trace, rms_from)) if n else None,
        "axes": axes,
        "inputs": inputs,
        "link": link or empty_link(),
        "events": events or [],
        "outcome": outcome,
    }
    if estimator != "truth":
        out["estimation"] = estimation(trace, estimator, sensors)
    return out


NEES_DOF = 9  # position, velocity, attitude: bridge.autopilot.estimator.nees


def estimation(trace: dict[str, np.ndarray], estimator: str, sensors: str) -> dict[str, Any]:
    """The ``estimation`` block (see the module docstring) over every row of the trace."""
    n = len(trace["t"])

    def rms(cols: tuple[str, ...], wrap: tuple[str, ...] = ()) -> float | None:
        if not n:
            return None
        sq = np.zeros(n)
        for c in cols:
            d = trace[c] - trace[c + "_est"]
            if c in wrap:
                d = (d + np.pi) % (2 * np.pi) - np.pi
            sq += d**2
        return _num(np.sqrt(np.mean(sq)))

    ne = trace["nees"][np.isfinite(trace["nees"])] if n else np.zeros(0)
    return {
        "estimator": estimator,
        "sensors": sensors,
        "position_rms_m": rms(("x", "y", "z")),
        "velocity_rms_mps": rms(("vx", "vy", "vz")),
        "attitude_rms_rad": rms(("phi", "theta", "psi"), wrap=("psi",)),
        "nees_mean": _num(ne.mean()) if ne.size else None,
        "nees_dof": NEES_DOF,
        "nees_samples": int(ne.size),
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
