"""Link impairment: one seeded model of a bad radio link, used by every clock (docs/design.md, "Link model").

In:  a ``[link]`` table (delays ms, loss %, burst length packets, ``rate_bps`` bytes/s, blackouts s),
     then packets: send time (s, on the driver's clock), size (bytes), any payload
Out: :class:`LinkSettings` (both directions and the guard's thresholds); the packets due by a time
     (s), each with its send and due times (s); :class:`LinkStats` (counts, one-way delay percentiles, ms)

A :class:`LinkImpairment` carries the packets of one direction (``up`` = controller ->
vehicle commands, ``down`` = vehicle -> controller state). The caller hands it each packet
as it crosses the socket, with its send time in seconds on whatever clock runs the loop
(simulation time offline and in lockstep, the wall clock in the relay), and asks which
packets are due by a later time. What can happen to a packet, in this order:

1. **blackout**: sent inside a scheduled window ``[start_s, start_s + duration_s)`` ⇒ lost;
2. **loss**: Bernoulli with ``loss_pct``, or Gilbert–Elliott bursts when ``burst_len`` ≥ 1
   (two states; every packet in the bad state is lost; the bad state lasts ``burst_len``
   packets on average and the long-run loss fraction is ``loss_pct``);
3. **bandwidth cap** (``rate_bps``, in **bytes per second**, 0 = none): packets queue behind
   each other at the sender, each occupying the link for size / rate; a packet that would
   wait longer than ``queue_ms`` is dropped (tail drop). Sizes are real MAVLink 2 frame
   sizes (:data:`FRAME_BYTES`) offline and the datagram's length in the relay;
4. **delay**: fixed ``delay_ms`` plus **jitter** ``jitter_ms`` — ``uniform`` on ±jitter_ms
   or ``normal`` with σ = jitter_ms, truncated symmetrically to ±min(delay_ms, bound) so
   that the total is never negative and its mean stays exactly ``delay_ms`` (bound =
   jitter_ms for uniform, 5σ for normal). Independent jitter may reorder packets, as
   netem's does;
5. **reordering** (``reorder_pct``): the packet is held back and released just after the
   next packet that is delivered normally, i.e. past its successor;
6. **duplication** (``dup_pct``): a second copy follows with its own jitter draw
   (duplication happens after the bottleneck: the copy costs no bandwidth).

**A measured trace** (``trace = FILE``, :mod:`bridge.link.trace`) takes the place of steps 2
and 4: a packet sent at time t (s of mission time; :meth:`LinkImpairment.shift_blackouts` puts the
relay's mission time 0) is lost or delayed as the trace's record with the largest ``t_s`` <= t
says. Blackouts, the bandwidth cap, reordering and duplication still apply on top; ``delay_ms``,
``jitter_ms``, ``loss_pct`` and ``burst_len`` in the same direction are refused. A named profile
(``profile = NAME``, :mod:`bridge.link.profile`) is a ``[link]`` table the mission's keys are
laid over.

Reproducibility: the random part of each packet's fate (loss, jitter, hold-back,
duplicate) is drawn from a counter-based generator keyed by ``(seed, direction, packet
number, draw)``, so the n-th packet's fate is a pure function of the seed and n, never of
the time or of what happened to the other packets' timing. Only the deterministic parts
(blackout windows, queueing) look at the send time.

Statistics (:class:`LinkStats`): sent, delivered (distinct packets), lost (by cause),
duplicated (extra copies delivered), reordered (delivered after a higher-numbered
packet), in flight, and the one-way delay of every delivered copy (p50/p95/p99/max, ms),
the keys of ``summary.json["link"]["up" | "down"]`` (docs/design.md, "Files of a run").
"""

from __future__ import annotations

import heapq
import math
from array import array
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from statistics import NormalDist
from typing import Any

from bridge.link.profile import load_link_profile
from bridge.link.trace import (
    LENGTH_SLACK_S,
    DirectionTrace,
    Replay,
    TraceFile,
    absolute_link_paths,
    own_figures,
    read_trace,
    records_problem,
)
from controller.link_guard import COMPENSATIONS, GuardConfig
from params import ConfigError, Table

__all__ = ["absolute_link_paths"]  # re-exported: the one place a [link] table's files are made absolute

# MAVLink 2 frame sizes in bytes (header 10 + payload with trailing zeros truncated + CRC 2,
# unsigned), measured once with pymavlink's encoder; tests/test_link.py re-measures them.
FRAME_BYTES = {
    "ODOMETRY": 242,  # covariances unknown (NaN first element), no extension fields
    "HIL_ACTUATOR_CONTROLS": 93,  # motors mode
    "SET_ACTUATOR_CONTROL_TARGET": 55,  # wrench mode
    "COMMAND_LONG": 44,  # ARM_DISARM
}

DIRECTIONS = ("up", "down")
JITTER_KINDS = ("uniform", "normal")
_DIRECTION_SALT = {"up": 0x5550, "down": 0x444F574E}
_M64 = (1 << 64) - 1
_NORMAL_BOUND_SIGMAS = 5.0


@dataclass(frozen=True)
class LinkConfig:
    """The impairment of one direction. Times in ms except blackouts (s); rates in bytes/s."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    jitter: str = "uniform"
    loss_pct: float = 0.0
    burst_len: float = 0.0  # 0: Bernoulli loss; >= 1: Gilbert–Elliott, mean burst length in packets
    blackouts: tuple[tuple[float, float], ...] = ()  # (start_s, duration_s)
    dup_pct: float = 0.0
    reorder_pct: float = 0.0
    rate_bps: float = 0.0  # bytes per second; 0 = unlimited
    queue_ms: float = 1000.0  # longest wait in the bandwidth queue before tail drop
    seed: int = 0
    trace: DirectionTrace | None = None  # a measured trace gives the delays and losses instead

    def __post_init__(self) -> None:
        if self.jitter not in JITTER_KINDS:
            raise ConfigError(f"link jitter: must be one of {', '.join(JITTER_KINDS)}; got {self.jitter!r}")
        why = burst_problem(self.loss_pct, self.burst_len)
        if why:
            raise ConfigError(f"link burst_len: {why}")
        clash = trace_clash(self)
        if self.trace is not None and clash:
            raise ConfigError(f"link trace: cannot be combined with {clash} in the same direction")

    @property
    def impaired(self) -> bool:
        """True when the link does anything at all to the packets."""
        return bool(self.delay_ms or self.jitter_ms or self.loss_pct or self.blackouts or self.dup_pct
                    or self.reorder_pct or self.rate_bps or self.trace is not None)

    def describe(self) -> str:
        """One line for logs: only what is switched on."""
        parts = [self.trace.describe()] if self.trace is not None else []
        if self.delay_ms or self.jitter_ms:
            parts.append(f"delay {self.delay_ms:g} ms" + (f" ± {self.jitter_ms:g} ms {self.jitter}"
                                                         if self.jitter_ms else ""))
        if self.loss_pct:
            parts.append(f"loss {self.loss_pct:g} %" + (f" in bursts of {self.burst_len:g}" if self.burst_len else ""))
        if self.blackouts:
            parts.append("blackouts " + ", ".join(f"{s:g}+{d:g} s" for s, d in self.blackouts))
        if self.dup_pct:
            parts.append(f"dup {self.dup_pct:g} %")
        if self.reorder_pct:
            parts.append(f"reorder {self.reorder_pct:g} %")
        if self.rate_bps:
            parts.append(f"{self.rate_bps:g} B/s")
        return ", ".join(parts) or "perfect"


TRACE_EXCLUSIVE = ("delay_ms", "jitter_ms", "loss_pct", "burst_len")  # what a trace gives instead


def trace_clash(values: Any) -> str:
    """The keys of :data:`TRACE_EXCLUSIVE` set (non-zero) in ``values`` (a mapping or a config), as
    ``key = value`` text; empty when none is."""
    get = values.get if isinstance(values, Mapping) else lambda k: getattr(values, k)
    return ", ".join(f"{k} = {get(k):g}" for k in TRACE_EXCLUSIVE if get(k))


def burst_problem(loss_pct: float, burst_len: float) -> str | None:
    """Why (loss_pct, burst_len) cannot be a Gilbert–Elliott chain, or None if it can.

    The chain needs p(good -> bad) = L / ((1 - L) b) <= 1, so b >= L / (1 - L), and L < 1.
    """
    if burst_len == 0.0:
        return None
    if burst_len < 1.0:
        return f"must be 0 (Bernoulli loss) or >= 1 packet, got {burst_len:g}"
    L = loss_pct / 100.0
    if L >= 1.0:
        return "bursts need loss_pct < 100"
    if L > 0.0 and burst_len < L / (1.0 - L) - 1e-12:
        return f"with loss_pct = {loss_pct:g} the mean burst must be >= {L / (1.0 - L):.4g} packets, got {burst_len:g}"
    return None


# -- reading the mission's [link] table ------------------------------------------------
# the allowed range [lo, hi] of each number of a direction's table (and of its CLI flag)
NUMBER_RANGES: dict[str, tuple[float, float]] = {
    "delay_ms": (0.0, 60_000.0),
    "jitter_ms": (0.0, 60_000.0),
    "loss_pct": (0.0, 100.0),
    "dup_pct": (0.0, 100.0),
    "reorder_pct": (0.0, 100.0),
    "rate_bps": (0.0, 1e10),
    "queue_ms": (1.0, 600_000.0),
    "burst_len": (0.0, 1e6),  # with loss_pct: checked together by burst_problem
}
# the numbers of [link] itself (the controller's guard and prediction); stale_ms and stop_ms exclude 0
GUARD_RANGES: dict[str, tuple[float, float]] = {
    "command_lag_ms": (0.0, 60_000.0),
    "stale_ms": (0.0, 60_000.0),
    "stop_ms": (0.0, 60_000.0),
}
LO_OPEN = frozenset({"stale_ms", "stop_ms"})
COMMAND_LAG_RANGE_MS = GUARD_RANGES["command_lag_ms"]
SEED_RANGE = (0, 2**31 - 1)
# every key a direction's table takes, and every key [link] itself takes (besides [link.up] and [link.down])
DIRECTION_KEYS = (*NUMBER_RANGES, "jitter", "seed", "blackouts", "trace", "trace_loop")
LINK_KEYS = (*DIRECTION_KEYS, "profile", "compensation", *GUARD_RANGES)
BLACKOUT_START_RANGE_S = (0.0, 1e6)  # a window's start, s of mission time
BLACKOUT_DURATION_RANGE_S = (0.0, 1e6)  # its duration, s (0 excluded)


def _defaults(seed: int) -> dict[str, Any]:
    """Every per-direction key at its default (the trace as its file name, "" for none)."""
    d = LinkConfig(seed=seed)
    return {name: getattr(d, name) for name in (*NUMBER_RANGES, "jitter", "seed", "blackouts")} | {
        "trace": "", "trace_loop": False}


def _direction(t: Table, base: Mapping[str, Any]) -> dict[str, Any]:
    """Read the per-direction keys of one table, defaults from ``base`` (the same keys)."""
    kw: dict[str, Any] = {}
    for name, (lo, hi) in NUMBER_RANGES.items():
        kw[name] = t.number(name, base[name], lo=lo, hi=hi)
    kw["jitter"] = t.string("jitter", base["jitter"], choices=JITTER_KINDS)
    why = burst_problem(kw["loss_pct"], kw["burst_len"])
    if why:
        raise t.error("burst_len", why)
    kw["seed"] = t.integer("seed", base["seed"], lo=SEED_RANGE[0], hi=SEED_RANGE[1])
    kw["blackouts"] = _blackouts(t, base["blackouts"])
    kw["trace"] = t.string("trace", base["trace"])
    kw["trace_loop"] = t.boolean("trace_loop", base["trace_loop"])
    return kw


def _config(kw: Mapping[str, Any], direction: str, source: str, duration_s: float | None,
            files: dict[str, TraceFile]) -> LinkConfig:
    """One direction's :class:`LinkConfig` from its keys: the trace file read (once per file) and checked
    against the other keys, its rows for this direction and, unless it loops, the mission's length."""
    kw = dict(kw)
    path, loop = kw.pop("trace"), kw.pop("trace_loop")
    if not path:
        return LinkConfig(**kw)
    where = f"{source}: link.{direction}"
    clash = trace_clash(kw)
    if clash:
        raise ConfigError(f"{where}: trace {path} cannot be combined with {clash} in the same direction: the "
                          f"trace gives the delays and the losses (set those to 0 or remove them; [link] sets "
                          f"both directions)")
    if path not in files:
        try:
            files[path] = read_trace(path)
        except ConfigError as exc:
            raise ConfigError(f"{where}.trace: {exc}") from None
    tf = files[path]
    why = records_problem(tf, direction)
    if why:
        raise ConfigError(f"{where}.trace: {path} {why}")
    rec = tf.records(direction)
    assert rec is not None
    if duration_s is not None and not loop and rec.length_s < duration_s - LENGTH_SLACK_S:
        raise ConfigError(f"{where}.trace: {path} lasts {rec.length_s:g} s ({rec.n} {direction} records), "
                          f"shorter than the mission ({duration_s:g} s); loop it with trace_loop = true "
                          f"(--link-trace-loop) or give a longer trace")
    return LinkConfig(**kw, trace=DirectionTrace(path, rec, loop))


def _blackouts(t: Table, default: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
    if not t.has("blackouts"):
        return default
    v = t.raw("blackouts")
    if not isinstance(v, (list, tuple)):
        raise t.error("blackouts", f"expected a list of [start_s, duration_s] pairs, got {v!r}"[:200])
    out = []
    for i, w in enumerate(v):
        ok = (isinstance(w, (list, tuple)) and len(w) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in w))
        if not ok:
            raise t.error("blackouts", f"element {i} must be a pair [start_s, duration_s] of numbers, got {w!r}"[:200])
        start, dur = float(w[0]), float(w[1])
        (s_lo, s_hi), (d_lo, d_hi) = BLACKOUT_START_RANGE_S, BLACKOUT_DURATION_RANGE_S
        if not s_lo <= start <= s_hi:
            raise t.error("blackouts", f"element {i}: start_s must be in [{s_lo:g}, {s_hi:g}], got {start:g}")
        if not d_lo < dur <= d_hi:
            raise t.error("blackouts", f"element {i}: duration_s must be in ({d_lo:g}, {d_hi:g}], got {dur:g}")
        out.append((start, dur))
    return tuple(sorted(out))


@dataclass(frozen=True)
class LinkSettings:
    """A mission's ``[link]`` table, validated: both directions and the controller's guard
    (``stale_ms``, ``stop_ms``, ``compensation``; its ``resume`` comes from ``[failsafe]``)."""

    up: LinkConfig = field(default_factory=LinkConfig)
    down: LinkConfig = field(default_factory=LinkConfig)
    guard: GuardConfig = field(default_factory=GuardConfig)

    @property
    def impaired(self) -> bool:
        return self.up.impaired or self.down.impaired

    def make(self) -> tuple[LinkImpairment, LinkImpairment]:
        """Fresh (up, down) models."""
        return LinkImpairment(self.up, "up"), LinkImpairment(self.down, "down")


def link_from_table(data: Mapping[str, Any], source: str, seed: int = 0,
                    duration_s: float | None = None) -> LinkSettings:
    """Validate a mission's ``[link]`` table.

    Keys of ``[link]`` itself: every per-direction key (a default for both directions), and
    the controller's: ``compensation = "none" | "predict"``, ``command_lag_ms`` (assumed
    up-link delay the prediction also covers), ``stale_ms``, ``stop_ms`` (thresholds on the
    age of the newest state), and ``profile`` (a named link profile the table is laid over).
    ``[link.up]`` and ``[link.down]`` override per direction. ``seed`` defaults to the mission's
    seed; the two directions always draw different streams. A ``trace`` file is read here; with
    ``duration_s`` (the mission's, s) one shorter than it is refused unless it loops.
    """
    t = Table(data, source, "link")
    profile = t.string("profile", "")
    if profile:
        return _with_profile(profile, data, source, seed, duration_s)
    both = _direction(t, _defaults(seed))
    g = GuardConfig()
    compensation = t.string("compensation", g.compensation, choices=COMPENSATIONS)
    r = GUARD_RANGES
    stale_ms = t.number("stale_ms", g.stale_s * 1000.0, lo=r["stale_ms"][0], lo_open=True, hi=r["stale_ms"][1])
    stop_ms = t.number("stop_ms", g.stop_s * 1000.0, lo=r["stop_ms"][0], lo_open=True, hi=r["stop_ms"][1])
    if stop_ms < stale_ms:
        raise t.error("stop_ms", f"must be >= stale_ms = {stale_ms:g}, got {stop_ms:g}")
    lag_ms = t.number("command_lag_ms", g.lag_s * 1000.0, lo=COMMAND_LAG_RANGE_MS[0], hi=COMMAND_LAG_RANGE_MS[1])
    if lag_ms and compensation != "predict":
        raise t.error("command_lag_ms", 'needs compensation = "predict"')
    dirs = {}
    files: dict[str, TraceFile] = {}
    for d in DIRECTIONS:
        sub = t.table(d)
        kw = _direction(sub, both)
        sub.done()
        dirs[d] = _config(kw, d, source, duration_s, files)
    t.done()
    guard = GuardConfig(stale_s=stale_ms / 1000.0, stop_s=stop_ms / 1000.0, compensation=compensation,
                        lag_s=lag_ms / 1000.0)
    return LinkSettings(dirs["up"], dirs["down"], guard)


def _with_profile(name: str, data: Mapping[str, Any], source: str, seed: int,
                  duration_s: float | None) -> LinkSettings:
    """``data`` laid over the ``[link]`` table of profile ``name``, validated (the profile alone first,
    so that a bad profile names its own file)."""
    try:
        prof = load_link_profile(name)
    except ConfigError as exc:
        raise ConfigError(f"{source}: link.profile: {exc}") from None
    link_from_table(prof.link, str(prof.path), seed)
    over = {k: v for k, v in data.items() if k != "profile"}
    return link_from_table(merge_link_tables(prof.link, over), source, seed, duration_s)


def merge_link_tables(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``[link]`` table ``base`` with ``over`` laid on top (sub-tables ``up``/``down`` merged key by key)."""
    out: dict[str, Any] = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in base.items()}
    for k, v in over.items():
        if k in DIRECTIONS and isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = {**out[k], **v}
        else:
            out[k] = dict(v) if isinstance(v, Mapping) else v
    return out


# -- the random part of a packet's fate ------------------------------------------------
def _mix(z: int) -> int:
    """SplitMix64 finaliser: a bijective 64-bit hash."""
    z = (z + 0x9E3779B97F4A7C15) & _M64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
    return z ^ (z >> 31)


def stream_key(seed: int, direction: str) -> int:
    """The generator key of one direction of one seed."""
    return _mix(_mix(seed & _M64) ^ _DIRECTION_SALT[direction])


def uniform(key: int, n: int, draw: int) -> float:
    """Draw number ``draw`` of packet ``n``: uniform in (0, 1), a pure function of its arguments."""
    z = _mix(key ^ _mix(((n & 0xFFFFFFFFFFFF) << 8) | draw))
    return ((z >> 11) + 0.5) * (1.0 / 9007199254740992.0)


_D_LOSS, _D_JITTER, _D_HOLD, _D_DUP, _D_DUP_JITTER, _D_GE_START = range(6)


@dataclass(frozen=True, slots=True)
class Fate:
    """What chance decides for one packet (blackouts and queueing come on top)."""

    lost: bool
    jitter_s: float
    held: bool  # held back past its successor (reordering)
    dup_jitter_s: float | None  # a duplicate follows with this jitter; None: no duplicate


class FateStream:
    """The fates of packets 0, 1, 2, … of one direction, in order (:meth:`next`).

    The n-th fate depends only on the seed, the direction and n: Bernoulli loss, jitter,
    hold-back and duplication are independent draws of packet n; the Gilbert–Elliott
    state of packet n is a function of the draws of packets 0..n.
    """

    def __init__(self, cfg: LinkConfig, direction: str) -> None:
        self.cfg = cfg
        self.key = stream_key(cfg.seed, direction)
        self.n = 0
        L = cfg.loss_pct / 100.0
        self._loss = L
        self._ge = cfg.burst_len >= 1.0 and 0.0 < L < 1.0
        if self._ge:
            self._r = 1.0 / cfg.burst_len  # bad -> good
            self._p = min(1.0, L * self._r / (1.0 - L))  # good -> bad, so that p / (p + r) = L
            self._bad = uniform(self.key, 0, _D_GE_START) < L  # start in the stationary distribution
        delay = cfg.delay_ms / 1000.0
        j = cfg.jitter_ms / 1000.0
        self._jit = 0.0
        if j > 0.0 and delay > 0.0:
            if cfg.jitter == "uniform":
                self._jit = min(j, delay)
                self._lo = self._hi = 0.0
            else:
                b = min(delay, _NORMAL_BOUND_SIGMAS * j)
                self._normal = NormalDist(0.0, j)
                self._lo = self._normal.cdf(-b)
                self._hi = self._normal.cdf(b)
                self._jit = b
        self._dup = cfg.dup_pct / 100.0
        self._hold = cfg.reorder_pct / 100.0

    def _jitter(self, n: int, draw: int) -> float:
        if self._jit == 0.0:
            return 0.0
        u = uniform(self.key, n, draw)
        if self.cfg.jitter == "uniform":
            return (2.0 * u - 1.0) * self._jit
        x = self._normal.inv_cdf(self._lo + u * (self._hi - self._lo))
        return -self._jit if x < -self._jit else self._jit if x > self._jit else x

    def next(self) -> Fate:
        n = self.n
        self.n += 1
        key = self.key
        if self._ge:
            u = uniform(key, n, _D_LOSS)
            self._bad = (u >= self._r) if self._bad else (u < self._p)
            lost = self._bad
        else:
            lost = self._loss > 0.0 and uniform(key, n, _D_LOSS) < self._loss
        held = self._hold > 0.0 and uniform(key, n, _D_HOLD) < self._hold
        dup = self._dup > 0.0 and uniform(key, n, _D_DUP) < self._dup
        return Fate(lost, self._jitter(n, _D_JITTER), held, self._jitter(n, _D_DUP_JITTER) if dup else None)

    def __iter__(self) -> Iterator[Fate]:
        while True:
            yield self.next()


# -- statistics --------------------------------------------------------------------------
class LinkStats:
    """Counters and one-way delays of one direction (what ``summary.json`` reports)."""

    def __init__(self) -> None:
        self.sent = 0
        self.delivered = 0
        self.duplicated = 0
        self.reordered = 0
        self.lost_by = {"random": 0, "blackout": 0, "queue": 0, "trace": 0}
        self.delays = array("d")  # seconds, every delivered copy
        self.in_flight = 0
        self.trace: DirectionTrace | None = None  # the trace replayed, whose own figures the summary adds

    @property
    def lost(self) -> int:
        return sum(self.lost_by.values())

    def percentiles_ms(self) -> dict[str, float | None]:
        if not self.delays:
            return {"p50": None, "p95": None, "p99": None, "max": None}
        import numpy as np  # lazy: the relay loads no numpy while it relays

        d = np.frombuffer(self.delays, dtype=float) * 1000.0
        p50, p95, p99 = np.percentile(d, (50.0, 95.0, 99.0))
        return {"p50": float(p50), "p95": float(p95), "p99": float(p99), "max": float(d.max())}

    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` keys of docs/design.md, "Files of a run", plus ``in_flight`` and ``lost_by``,
        and with a trace ``trace``: its file and its own records, loss and delays, beside what the flight met."""
        out = {
            "sent": self.sent,
            "delivered": self.delivered,
            "lost": self.lost,
            "duplicated": self.duplicated,
            "reordered": self.reordered,
            "delay_ms": self.percentiles_ms(),
            "in_flight": self.in_flight,
            "lost_by": dict(self.lost_by),
        }
        if self.trace is not None:
            out["trace"] = own_figures(self.trace)
        return out


# -- the model ------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Delivery:
    """A packet coming out of the link: its number, when it was sent and delivered (s)."""

    seq: int
    sent_t: float
    due_t: float
    payload: Any
    copy: bool = False  # the duplicate, not the original


class LinkImpairment:
    """One direction of an impaired link (see the module docstring).

    ``send(t, size, payload)`` puts a packet on the link at time t (s) and returns its
    number; ``deliver(t)`` returns every packet due by t, in delivery order. Times only
    need to be non-decreasing across calls. ``next_due()`` tells a real-time driver when
    to call :meth:`deliver` next.
    """

    def __init__(self, cfg: LinkConfig | None = None, direction: str = "up") -> None:
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be 'up' or 'down', got {direction!r}")
        self.cfg = cfg = cfg or LinkConfig()
        self.direction = direction
        self.fates = FateStream(cfg, direction)
        self.stats = LinkStats()
        self._delay = cfg.delay_ms / 1000.0
        self._rate = cfg.rate_bps
        self._queue = cfg.queue_ms / 1000.0
        self._free_at = -math.inf
        self._heap: list[tuple[float, int, Delivery]] = []
        self._order = 0
        self._held: list[Delivery] = []
        self._copies: dict[int, int] = {}  # seq -> copies still to come, for duplicated packets
        self._highest = -1
        self._last_due = -math.inf
        self._windows = tuple((s, s + d) for s, d in cfg.blackouts)
        self._replay = Replay(cfg.trace) if cfg.trace is not None else None
        self._origin = 0.0  # this model's clock (s) at mission time 0: where the trace starts
        self.stats.trace = cfg.trace

    def in_blackout(self, t: float) -> bool:
        return any(a <= t < b for a, b in self._windows)

    def shift_blackouts(self, offset_s: float) -> None:
        """Put mission time 0 at ``offset_s`` on this model's clock (s): the scheduled blackout
        windows and the trace's start, for a real-time driver whose clock started before the
        flight's time 0 (``math.inf``: not yet known, no blackout and the trace's first record)."""
        self._windows = tuple((s + offset_s, s + d + offset_s) for s, d in self.cfg.blackouts)
        self._origin = offset_s

    def send(self, t: float, size: int, payload: Any = None) -> int:
        """Put a packet of ``size`` bytes on the link at time t (s); returns its number."""
        st = self.stats
        fate = self.fates.next()
        seq = self.fates.n - 1
        st.sent += 1
        if self._windows and self.in_blackout(t):
            st.lost_by["blackout"] += 1
            return seq
        if fate.lost:
            st.lost_by["random"] += 1
            return seq
        delay = self._delay
        if self._replay is not None:
            delay = self._replay.delay_at(t - self._origin)
            if delay != delay:  # the trace lost it
                st.lost_by["trace"] += 1
                return seq
        tx = t
        if self._rate > 0.0:
            start = self._free_at if self._free_at > t else t
            if start - t > self._queue:
                st.lost_by["queue"] += 1
                return seq
            tx = self._free_at = start + size / self._rate
        due = tx + delay + fate.jitter_s
        st.in_flight += 1
        d = Delivery(seq, t, due, payload)
        if fate.dup_jitter_s is not None:
            self._copies[seq] = 2
            self._push(Delivery(seq, t, tx + delay + fate.dup_jitter_s, payload, True))
        if fate.held:
            self._held.append(d)
        else:
            self._push(d)
            for h in self._held:  # released just after this successor
                self._push(replace(h, due_t=max(h.due_t, due)))
            self._held.clear()
        return seq

    def _push(self, d: Delivery) -> None:
        self._order += 1
        heapq.heappush(self._heap, (d.due_t, self._order, d))

    def next_due(self) -> float | None:
        """When the next packet is due (s), or None if none is scheduled."""
        return self._heap[0][0] if self._heap else None

    def deliver(self, t: float) -> list[Delivery]:
        """Every packet due by time t (s), in delivery order; statistics updated."""
        heap = self._heap
        if not heap or heap[0][0] > t:
            return []
        out = []
        st = self.stats
        while heap and heap[0][0] <= t:
            d = heapq.heappop(heap)[2]
            out.append(d)
            self._last_due = d.due_t
            st.delays.append(d.due_t - d.sent_t)
            left = self._copies.get(d.seq)
            if left is not None:
                if left == 2:
                    self._copies[d.seq] = 1
                else:
                    del self._copies[d.seq]
                    st.duplicated += 1
                    continue
            st.delivered += 1
            st.in_flight -= 1
            if d.seq < self._highest:
                st.reordered += 1
            else:
                self._highest = d.seq
        return out

    def drain(self) -> list[Delivery]:
        """Everything still scheduled, held packets included (end of a test stream)."""
        out = self.deliver(math.inf)
        if self._held:
            for h in self._held:  # no successor came: released after the last packet delivered
                self._push(replace(h, due_t=max(h.due_t, self._last_due)))
            self._held.clear()
            out += self.deliver(math.inf)
        return out


def fates(cfg: LinkConfig, direction: str, n: int) -> list[Fate]:
    """The first n fates of a direction (for tests and inspection)."""
    s = FateStream(cfg, direction)
    return [s.next() for _ in range(n)]
