"""One direction of the link model's settings, and the ranges every ``[link]`` number takes (the
mission's tables, the CLI's flags and a sweep's axes all check against them).

In:  one direction's impairment: delays ms, loss %, burst length packets, ``rate_bps`` bytes/s,
     blackouts (start s, duration s), a seed, a measured trace
Out: :class:`LinkConfig` (checked on construction), the range tables (:data:`NUMBER_RANGES`,
     :data:`GUARD_RANGES`, :data:`LO_OPEN` / :data:`HI_OPEN`, the blackout and seed ranges), :func:`burst_problem`,
     :func:`trace_clash`, :data:`NEEDS` and :func:`idle_problem` (a key that acts only with another),
     :func:`guard_problem` (the guard's keys that clash)

What the model does with them: :mod:`bridge.link.impairment`; reading a mission's ``[link]`` table
into them: :mod:`bridge.link.model`, which re-exports every name here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from bridge.link.trace import DirectionTrace
from params import ConfigError

DIRECTIONS = ("up", "down")
JITTER_KINDS = ("uniform", "normal")
# normal jitter is truncated at ±5 sigma (and at ±delay): bridge.link.impairment's own _NORMAL_BOUND_SIGMAS, which
# the compiled kernels read (a constant imported by name would leave their cache blind to this module's edits);
# tests/test_link.py holds the two equal
NORMAL_BOUND_SIGMAS = 5.0



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

    @property
    def jitter_bound_ms(self) -> float:
        """The half-width the jitter is drawn within (ms), as :mod:`bridge.link.impairment` flies it: ±jitter_ms
        (uniform) or ±5 sigma (normal), capped at the delay so that no delay is negative; 0: no jitter flown."""
        if not (self.jitter_ms > 0.0 and self.delay_ms > 0.0):
            return 0.0
        return min(self.delay_ms, self.jitter_ms if self.jitter == "uniform" else NORMAL_BOUND_SIGMAS * self.jitter_ms)

    @property
    def jitter_capped(self) -> bool:
        """Whether the delay capped the jitter asked for: uniform's half-width, or normal's ±5 sigma, is cut (at a
        delay of 0, to nothing)."""
        nominal = self.jitter_ms if self.jitter == "uniform" else NORMAL_BOUND_SIGMAS * self.jitter_ms
        return self.jitter_ms > 0.0 and self.jitter_bound_ms < nominal

    def _delay_text(self) -> str:
        """The delay and jitter as flown: ``delay 20 ms ± 5 ms uniform``; a capped jitter says so."""
        text = f"delay {self.delay_ms:g} ms"
        if not self.jitter_ms:
            return text
        b = self.jitter_bound_ms
        if not b:
            return f"{text}, no jitter (jitter {self.jitter_ms:g} ms {self.jitter} capped at the delay)"
        if self.jitter == "uniform":
            return text + (f" ± {b:g} ms uniform (jitter {self.jitter_ms:g} ms capped at the delay)"
                           if self.jitter_capped else f" ± {b:g} ms uniform")
        return text + f" ± {self.jitter_ms:g} ms normal" + (f" truncated at ± {b:g} ms (the delay)"
                                                            if self.jitter_capped else "")

    def describe(self) -> str:
        """One line for logs: only what is switched on, as it is flown (a jitter the delay caps, as capped)."""
        parts = [self.trace.describe()] if self.trace is not None else []
        if self.delay_ms or self.jitter_ms:
            parts.append(self._delay_text())
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


# a direction's key that acts only where another is set (non-zero, or a trace): that key, what the first does, and
# what is missing without it; a key that would change nothing is refused, flag or table alike (docs/links.md)
NEEDS: dict[str, tuple[str, str, str]] = {
    "burst_len": ("loss_pct", "it sets the mean length of the loss bursts", "no packet is lost"),
    "queue_ms": ("rate_bps", "it bounds the wait in the bandwidth cap's queue", "there is no bandwidth cap"),
    "trace_loop": ("trace", "it loops the link trace", "no trace is replayed"),
}


def idle_problem(key: str, links: Iterable[Any]) -> str | None:
    """Why the direction key ``key`` (of :data:`NEEDS`) changes nothing on every one of ``links`` (directions: each a
    :class:`LinkConfig` or a mapping of its values, as :func:`trace_clash` takes), or None when one of them uses it.
    The text follows "changes nothing: " (its caller's, which names the flag or the axis)."""
    need, does, missing = NEEDS[key]
    for v in links:
        if v.get(need) if isinstance(v, Mapping) else getattr(v, need):
            return None
    return f"{does}, and {missing} ({need} {'none' if need == 'trace' else '0'})"


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
# and the ones that exclude their top: at reorder_pct = 100 every packet waits for a successor that waits too,
# so nothing is ever delivered (docs/links.md)
HI_OPEN = frozenset({"reorder_pct"})
COMMAND_LAG_RANGE_MS = GUARD_RANGES["command_lag_ms"]


def guard_problem(values: Mapping[str, Any], prefer: Iterable[str] = ()) -> tuple[str, str, str] | None:
    """The guard's keys that clash (``values``: ``compensation``, ``stale_ms``, ``stop_ms``, ``command_lag_ms``, in
    ms): a stop age below the stale age, a command lag without prediction, as (the key to name, why, the key it
    clashes with); None. The key named is the one of the pair in ``prefer`` (what a flag gave: the refusal names
    that flag, :func:`bridge.cli.linkflags.guard_flag_refusal`), else the table's own wording's."""
    prefer = set(prefer)
    stale, stop = values["stale_ms"], values["stop_ms"]
    if stop < stale:
        if "stale_ms" in prefer and "stop_ms" not in prefer:
            return "stale_ms", f"must be <= stop_ms = {stop:g}, got {stale:g}", "stop_ms"
        return "stop_ms", f"must be >= stale_ms = {stale:g}, got {stop:g}", "stale_ms"
    lag, comp = values["command_lag_ms"], values["compensation"]
    if lag and comp != "predict":
        if "compensation" in prefer and "command_lag_ms" not in prefer:
            return ("compensation", f'must be "predict" where command_lag_ms = {lag:g} (the lag prediction covers), '
                    f"got {comp!r}", "command_lag_ms")
        return "command_lag_ms", 'needs compensation = "predict"', "compensation"
    return None
SEED_RANGE = (0, 2**31 - 1)
# every key a direction's table takes, and every key [link] itself takes (besides [link.up] and [link.down])
DIRECTION_KEYS = (*NUMBER_RANGES, "jitter", "seed", "blackouts", "trace", "trace_loop")
LINK_KEYS = (*DIRECTION_KEYS, "profile", "compensation", *GUARD_RANGES, "shared")
BLACKOUT_START_RANGE_S = (0.0, 1e6)  # a window's start, s of mission time
BLACKOUT_DURATION_RANGE_S = (0.0, 1e6)  # its duration, s (0 excluded)

