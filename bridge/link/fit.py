"""The link model's table that best fits a trace, with a goodness-of-fit figure for each part, and
traces the model makes from a table (docs/links.md, "Fitting a trace").

In:  a trace's records per direction (:class:`bridge.link.trace.Records`: send times s, delays s,
     nan lost); the length (s) above which a loss run is a blackout; or a ``[link]`` direction
     (:class:`bridge.link.model.LinkConfig`) and a packet rate (Hz) to make a trace from
Out: :class:`DirectionFit` per direction: the delay (mean ms) and jitter (ms) with its distribution
     (uniform or normal: the one with the smaller Kolmogorov–Smirnov statistic D against the model's
     own truncated distribution), the loss (%) as Bernoulli or Gilbert–Elliott (mean burst, packets:
     the one with the lower BIC, with the KS distance of the loss-run lengths to the model's
     geometric ones), and the blackouts (start s, duration s); :func:`fit_toml`, the table as a link
     profile (``--link-profile FILE``) with the figures as comments and a ``[fit]`` table

The fit is the model's, nothing richer: a mean delay with symmetric jitter (no long tails), losses
independent or in bursts of a geometric length (every packet lost in the bad state), outages as
scheduled blackouts at the trace's own times. The figures say how well that holds.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np

from bridge.link.config import NORMAL_BOUND_SIGMAS as _NORMAL_BOUND_SIGMAS  # the model's truncation of normal jitter
from bridge.link.model import (
    BLACKOUT_DURATION_RANGE_S,
    BLACKOUT_START_RANGE_S,
    NUMBER_RANGES,
    LinkConfig,
    LinkImpairment,
    link_from_table,
)
from bridge.link.trace import Records, TraceFile, make_records
from params import ConfigError

BLACKOUT_AFTER_S = 1.0  # a loss run at least this long is an outage, listed as a blackout, not a burst


@dataclass(frozen=True)
class DelayFit:
    delay_ms: float
    jitter_ms: float
    jitter: str  # "uniform" | "normal"; "none" without jitter
    ks: dict[str, float]  # D of each candidate distribution against the delivered delays
    delivered: int

    @property
    def ks_critical_5pct(self) -> float:
        """The KS statistic a sample this large exceeds with 5 % chance if the model held exactly."""
        return 1.358 / math.sqrt(self.delivered) if self.delivered else math.nan


@dataclass(frozen=True)
class LossFit:
    loss_pct: float
    burst_len: float  # 0: Bernoulli
    model: str  # "none" | "bernoulli" | "gilbert-elliott"
    mean_run: float  # mean length of a loss run in the trace (packets), outside blackouts
    runs: int
    bic: dict[str, float]
    run_ks: float  # KS distance between the loss-run lengths and the chosen model's geometric law


@dataclass(frozen=True)
class DirectionFit:
    records: int
    length_s: float
    delay: DelayFit | None  # None: nothing delivered
    loss: LossFit
    blackouts: tuple[tuple[float, float], ...]
    blackout_after_s: float

    def table(self) -> dict[str, Any]:
        """This direction's ``[link]`` keys, each within what the link model takes (:meth:`clamped` says
        what had to be changed to get there)."""
        return self._table()[0]

    def clamped(self) -> list[str]:
        """What the fit found that the model's ranges do not take, and what :meth:`table` gives instead."""
        return self._table()[1]

    def _table(self) -> tuple[dict[str, Any], list[str]]:
        out: dict[str, Any] = {}
        notes: list[str] = []
        if self.delay is not None:
            out["delay_ms"] = _within("delay_ms", round(self.delay.delay_ms, 3), notes)
            if self.delay.jitter != "none":
                out["jitter_ms"] = _within("jitter_ms", round(self.delay.jitter_ms, 3), notes)
                out["jitter"] = self.delay.jitter
        loss = round(self.loss.loss_pct, 4)
        if self.loss.burst_len and loss >= 100.0:  # bursts need loss_pct < 100: the nearest the table can say
            loss = 99.9999
        out["loss_pct"] = loss
        if self.loss.burst_len:
            need = loss / (100.0 - loss)  # the chain's shortest mean burst at this loss (burst_problem)
            burst = math.ceil(max(self.loss.burst_len, need * (1.0 + 1e-9)) * 1000.0) / 1000.0
            out["burst_len"] = _within("burst_len", burst, notes)
        windows = []
        (s_lo, s_hi), (_, d_hi) = BLACKOUT_START_RANGE_S, BLACKOUT_DURATION_RANGE_S
        for start, dur in self.blackouts:
            if not s_lo <= round(start, 3) <= s_hi:
                notes.append(f"an outage at {start:g} s left out: a blackout starts by {s_hi:g} s")
                continue
            d = math.ceil(dur * 1000.0) / 1000.0  # never rounded to 0: a blackout lasts
            if d > d_hi:
                notes.append(f"the outage at {start:g} s lasts {dur:g} s: its blackout is cut to {d_hi:g} s")
                d = d_hi
            windows.append([round(start, 3), d])
        if windows:
            out["blackouts"] = windows
        return out, notes


def _within(key: str, value: float, notes: list[str]) -> float:
    """``value`` of ``key`` clamped into the model's range (:data:`NUMBER_RANGES`), noted when it was not in it."""
    lo, hi = NUMBER_RANGES[key]
    if lo <= value <= hi:
        return value
    clamped = min(max(value, lo), hi)
    notes.append(f"{key} {value:g} is outside the model's [{lo:g}, {hi:g}]: {clamped:g}")
    return clamped


def loadable(fits: dict[str, DirectionFit], name: str) -> dict[str, Any]:
    """The fitted ``[link]`` table, checked by the link model's own loader (a ``ConfigError`` if it refused
    it: what the fit writes is always a profile bsst flies)."""
    table = fit_link_table(fits)
    try:
        link_from_table(table, name)
    except ConfigError as exc:
        raise ConfigError.at("bsst link fit", None, f"the fitted table is not one the link model takes: {exc}") \
            from None
    return table


# -- delay ------------------------------------------------------------------------------------------
def _normal_cdf(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.frompyfunc(math.erf, 1, 1)(z / math.sqrt(2.0)).astype(float))


def _ks(sorted_x: np.ndarray, cdf: np.ndarray) -> float:
    n = len(sorted_x)
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - cdf), np.max(cdf - (i - 1) / n)))


def _truncated_sd(sigma: float, bound: float) -> float:
    """The standard deviation of N(0, sigma) truncated to [-bound, bound]."""
    a = bound / sigma
    nd = NormalDist()
    z = 2.0 * nd.cdf(a) - 1.0
    return sigma * math.sqrt(max(0.0, 1.0 - 2.0 * a * nd.pdf(a) / z))


def _normal_sigma(mean: float, sd: float) -> float:
    """The model's sigma whose truncation at +-min(mean, 5 sigma) has standard deviation ``sd``."""
    if mean >= _NORMAL_BOUND_SIGMAS * sd:
        return sd  # truncated at 5 sigma: the sd is sigma's to 3e-5
    if sd * math.sqrt(3.0) >= mean:  # wider than any normal truncated at the mean: the flattest one
        return 10.0 * mean
    lo, hi = sd, 10.0 * mean
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _truncated_sd(mid, min(mean, _NORMAL_BOUND_SIGMAS * mid)) < sd:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def fit_delay(delays_ms: np.ndarray) -> DelayFit | None:
    """Mean delay and the jitter distribution that fits the delivered delays (ms) best (KS D)."""
    x = np.sort(np.asarray(delays_ms, dtype=float))
    n = len(x)
    if n == 0:
        return None
    mean = float(x.mean())
    sd = float(x.std())
    if sd <= 1e-9 * max(1.0, mean) or mean <= 0.0:
        return DelayFit(mean, 0.0, "none", {}, n)
    j_u = math.sqrt(3.0) * sd
    b_u = min(j_u, mean)
    cdf_u = np.clip((x - (mean - b_u)) / (2.0 * b_u), 0.0, 1.0)
    sigma = _normal_sigma(mean, sd)
    b_n = min(mean, _NORMAL_BOUND_SIGMAS * sigma)
    nd = NormalDist()
    lo, hi = nd.cdf(-b_n / sigma), nd.cdf(b_n / sigma)
    cdf_n = np.clip((_normal_cdf((np.clip(x, mean - b_n, mean + b_n) - mean) / sigma) - lo) / (hi - lo), 0.0, 1.0)
    ks = {"uniform": _ks(x, cdf_u), "normal": _ks(x, cdf_n)}
    best = min(ks, key=lambda k: ks[k])
    return DelayFit(mean, j_u if best == "uniform" else sigma, best, ks, n)


# -- loss ---------------------------------------------------------------------------------------------
def _runs(lost: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in ``lost``."""
    if not len(lost):
        return np.zeros(0, dtype=int)
    padded = np.concatenate(([False], lost, [False])).astype(np.int8)
    edges = np.diff(padded)
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


def _xlogy(n: float, p: float) -> float:
    return n * math.log(p) if n else 0.0


def _geometric_ks(runs: np.ndarray, r: float) -> float:
    """KS distance between run lengths and the geometric law P(len = k) = (1 - r)^(k-1) r."""
    if not len(runs) or not 0.0 < r <= 1.0:
        return math.nan
    k = np.arange(1, int(runs.max()) + 1)
    emp = np.searchsorted(np.sort(runs), k, side="right") / len(runs)
    return float(np.max(np.abs(emp - (1.0 - (1.0 - r) ** k))))


def fit_loss(segments: list[np.ndarray]) -> LossFit:
    """Bernoulli or Gilbert–Elliott loss of the records outside blackouts (``segments``: the lost
    flags of the runs of records between blackouts, in order), chosen by BIC."""
    n = sum(len(s) for s in segments)
    n_lost = int(sum(int(s.sum()) for s in segments))
    runs = np.concatenate([_runs(s) for s in segments]) if segments else np.zeros(0, dtype=int)
    if n == 0 or n_lost == 0:
        return LossFit(0.0, 0.0, "none", 0.0, 0, {}, math.nan)
    L = n_lost / n
    mean_run = n_lost / len(runs)
    if n_lost == n:
        return LossFit(100.0, 0.0, "bernoulli", mean_run, len(runs), {}, math.nan)
    counts = {"gg": 0, "gb": 0, "bg": 0, "bb": 0}
    for s in segments:
        a, b = s[:-1], s[1:]
        counts["gg"] += int(np.sum(~a & ~b))
        counts["gb"] += int(np.sum(~a & b))
        counts["bg"] += int(np.sum(a & ~b))
        counts["bb"] += int(np.sum(a & b))
    ll_b = _xlogy(n_lost, L) + _xlogy(n - n_lost, 1.0 - L)
    g, bad = counts["gg"] + counts["gb"], counts["bg"] + counts["bb"]
    p = counts["gb"] / g if g else 0.0
    r = counts["bg"] / bad if bad else 1.0
    ll_ge = (_xlogy(counts["gb"], p) + _xlogy(counts["gg"], 1.0 - p) + _xlogy(counts["bg"], r)
             + _xlogy(counts["bb"], 1.0 - r))
    bic = {"bernoulli": 1.0 * math.log(n) - 2.0 * ll_b, "gilbert-elliott": 2.0 * math.log(n) - 2.0 * ll_ge}
    if bic["gilbert-elliott"] < bic["bernoulli"] and r > 0.0:
        burst = max(1.0 / r, 1.0, L / (1.0 - L))  # the model's chain needs burst >= L / (1 - L)
        return LossFit(100.0 * L, burst, "gilbert-elliott", mean_run, len(runs), bic, _geometric_ks(runs, 1.0 / burst))
    return LossFit(100.0 * L, 0.0, "bernoulli", mean_run, len(runs), bic, _geometric_ks(runs, 1.0 - L))


# -- one direction, a whole trace -----------------------------------------------------------------------
def split_blackouts(rec: Records, after_s: float) -> tuple[list[np.ndarray], tuple[tuple[float, float], ...],
                                                             np.ndarray]:
    """The loss flags of the records between outages, the outages (start s, duration s: from the first
    record lost to the next delivered, or the trace's end) of at least ``after_s``, and a mask of the
    records inside them."""
    t = np.asarray(rec.t_s, dtype=float)
    lost = np.isnan(np.asarray(rec.delay_s, dtype=float))
    inside = np.zeros(len(t), dtype=bool)
    windows = []
    padded = np.concatenate(([False], lost, [False])).astype(np.int8)
    edges = np.diff(padded)
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        end = t[b] if b < len(t) else rec.length_s
        if end - t[a] >= after_s:
            windows.append((float(t[a]), float(end - t[a])))
            inside[a:b] = True
    segments, start = [], 0
    for i in [*(np.flatnonzero(np.diff(inside.astype(np.int8)) != 0) + 1), len(t)]:
        if start < i and not inside[start]:
            segments.append(lost[start:i])
        start = i
    return segments, tuple(windows), inside


def fit_records(rec: Records, blackout_after_s: float = BLACKOUT_AFTER_S) -> DirectionFit:
    """The fit of one direction's records."""
    segments, windows, inside = split_blackouts(rec, blackout_after_s)
    d = np.asarray(rec.delay_s, dtype=float) * 1000.0
    delivered = d[~np.isnan(d) & ~inside]
    return DirectionFit(rec.n, rec.length_s, fit_delay(delivered), fit_loss(segments), windows, blackout_after_s)


def fit_trace(tf: TraceFile, blackout_after_s: float = BLACKOUT_AFTER_S) -> dict[str, DirectionFit]:
    """``{"both": fit}`` for a trace without a direction column, else ``{"up": ..., "down": ...}``
    (the directions it has rows for)."""
    if tf.both is not None:
        return {"both": fit_records(tf.both, blackout_after_s)}
    return {d: fit_records(r, blackout_after_s) for d, r in (("up", tf.up), ("down", tf.down)) if r is not None}


def fit_link_table(fits: dict[str, DirectionFit]) -> dict[str, Any]:
    """The ``[link]`` table of the fits: ``both`` at its top level, else ``up`` / ``down`` sub-tables."""
    if "both" in fits:
        return fits["both"].table()
    return {d: f.table() for d, f in fits.items()}


def _figures(f: DirectionFit) -> dict[str, Any]:
    out: dict[str, Any] = {"records": f.records, "length_s": round(f.length_s, 6),
                           "blackout_after_s": f.blackout_after_s, "loss_model": f.loss.model,
                           "loss_runs": f.loss.runs, "mean_loss_run": round(f.loss.mean_run, 4)}
    if not math.isnan(f.loss.run_ks):
        out["loss_run_ks"] = round(f.loss.run_ks, 5)
    out.update({f"bic_{k.replace('-', '_')}": round(v, 2) for k, v in f.loss.bic.items()})
    if f.delay is not None:
        out["delivered"] = f.delay.delivered
        out.update({f"delay_ks_{k}": round(v, 5) for k, v in f.delay.ks.items()})
        if f.delay.ks:
            out["delay_ks_critical_5pct"] = round(f.delay.ks_critical_5pct, 5)
    return out


def _comment(key: str, f: DirectionFit) -> str:
    """The goodness-of-fit words that go beside a key of the fitted table."""
    dl, ls = f.delay, f.loss
    if key == "delay_ms" and dl is not None:
        return f"mean one-way delay of the {dl.delivered} records delivered (outside blackouts)"
    if key == "jitter" and dl is not None:
        other = ", ".join(f"{k} {v:.4f}" for k, v in dl.ks.items() if k != dl.jitter)
        return (f"KS D = {dl.ks[dl.jitter]:.4f} ({other}); an exact fit stays under {dl.ks_critical_5pct:.4f} "
                f"95 % of the time")
    if key == "loss_pct":
        return f"{ls.model}: {ls.runs} loss runs, mean {ls.mean_run:.3g} packets" + (
            f"; run-length KS D = {ls.run_ks:.4f}" if not math.isnan(ls.run_ks) else "")
    if key == "burst_len":
        return f"Gilbert-Elliott mean burst, chosen by BIC ({ls.bic['gilbert-elliott']:.1f} vs Bernoulli " \
               f"{ls.bic['bernoulli']:.1f})"
    if key == "blackouts":
        return f"loss runs of {f.blackout_after_s:g} s or more, at the trace's times (s)"
    return ""


def fit_toml(fits: dict[str, DirectionFit], trace_path: str) -> str:
    """The fitted table as a link profile (TOML): use it with ``--link-profile FILE`` or
    ``[link] profile = "FILE"``, or paste its ``[link]`` tables into a mission."""
    name = Path(trace_path).stem
    loadable(fits, f"bsst link fit {trace_path}")
    lines = [f"# bsst link fit {trace_path}",
             "# The link model's table that fits this trace best, with a goodness-of-fit figure for each part.",
             "# Fly it: bsst sim MISSION --link-profile THIS_FILE (or [link] profile = \"THIS_FILE\"), or paste",
             "# the [link] tables into a mission. The [fit] tables hold the figures; bsst reads only [link].",
             f"name = {json.dumps('fit-' + name)}",
             f"description = {json.dumps('fitted by bsst link fit to ' + Path(trace_path).name)}",
             f"sources = [{json.dumps(str(trace_path))}]", ""]
    for d, f in fits.items():
        lines.append("[link]" if d == "both" else f"[link.{d}]")
        for k, v in f.table().items():
            text = json.dumps(v) if isinstance(v, (str, list)) else repr(v)
            note = _comment(k, f)
            lines.append(f"{k} = {text}" + (f"  # {note}" if note else ""))
        if f.delay is None:
            lines.append("# no record delivered: no delay to fit")
        lines += [f"# clamped to the model's ranges: {n}" for n in f.clamped()]
        lines.append("")
    for d, f in fits.items():
        lines.append("[fit]" if d == "both" else f"[fit.{d}]")
        lines += [f"{k} = {json.dumps(v) if isinstance(v, str) else repr(v)}" for k, v in _figures(f).items()]
        lines.append("")
    return "\n".join(lines)


# -- a trace made by the model ------------------------------------------------------------------------------
def model_records(cfg: LinkConfig, direction: str, rate_hz: float, n: int, size: int = 242) -> Records:
    """What the link model does to ``n`` packets of ``size`` bytes sent at ``rate_hz``: a trace of it
    (each packet's first copy; lost: never delivered)."""
    link = LinkImpairment(cfg, direction)
    t = [k / rate_hz for k in range(n)]
    for tk in t:
        link.send(tk, size)
    delay = [math.nan] * n
    for dv in link.drain():
        if not dv.copy and delay[dv.seq] != delay[dv.seq]:
            delay[dv.seq] = dv.due_t - dv.sent_t
    return make_records(t, delay)
