"""Link impairment: one seeded model of a bad radio link, used by every clock (docs/design.md, "Link model").

In:  one direction's :class:`~bridge.link.config.LinkConfig` (delays ms, loss %, burst length packets,
     ``rate_bps`` bytes/s, blackouts s) and its handovers (mission time s, the link from then), then packets:
     send time (s, on the driver's clock), size (bytes), any payload
Out: the packets due by a time (s), each with its send and due times (s); :class:`LinkStats` (counts,
     one-way delay percentiles, ms)

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
   wait longer than ``queue_ms`` is dropped (tail drop); on a radio shared by a fleet
   (:mod:`bridge.link.radio`) they queue behind every vehicle's packets. Sizes are real MAVLink 2 frame
   sizes (:data:`FRAME_BYTES`) offline and the datagram's length in the relay;
4. **delay**: fixed ``delay_ms`` plus **jitter** ``jitter_ms`` — ``uniform`` on ±jitter_ms
   or ``normal`` with σ = jitter_ms, truncated symmetrically to ±min(delay_ms, bound) so
   that the total is never negative and its mean stays exactly ``delay_ms`` (bound =
   jitter_ms for uniform, 5σ for normal). Independent jitter may reorder packets, as
   netem's does;
5. **reordering** (``reorder_pct``): the packet is held back and released just after the
   next packet that is delivered normally, i.e. past its successor;
6. **duplication** (``dup_pct``): a second copy follows with its own jitter draw
   (duplication happens after the bottleneck: the copy costs no bandwidth); the copy is of the
   packet as step 5 left it, so a held packet's copy is held with it and released with it (until
   the fix-linkdup branch the copy went through on time and undid the hold-back: ``--dup 100
   --reorder 99.9`` flew as a perfect link).

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
from collections.abc import Iterator
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any, NamedTuple

from bridge.link.config import DIRECTIONS, LinkConfig
from bridge.link.radio import Radio
from bridge.link.trace import DirectionTrace, Replay, own_figures

# MAVLink 2 frame sizes in bytes (header 10 + payload with trailing zeros truncated + CRC 2,
# unsigned), measured once with pymavlink's encoder; tests/test_link.py re-measures them.
FRAME_BYTES = {
    "ODOMETRY": 242,  # covariances unknown (NaN first element), no extension fields
    "HIL_ACTUATOR_CONTROLS": 93,  # motors mode
    "SET_ACTUATOR_CONTROL_TARGET": 55,  # wrench mode
    "COMMAND_LONG": 44,  # ARM_DISARM
}

_DIRECTION_SALT = {"up": 0x5550, "down": 0x444F574E}
_M64 = (1 << 64) - 1
_NORMAL_BOUND_SIGMAS = 5.0


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


_CERTAIN = Fate(False, 0.0, False, None)  # a packet's fate on a link that leaves nothing to chance


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
        # nothing left to chance (no loss, jitter, hold-back or duplicate): every fate is _CERTAIN, no draw made
        self._certain = not self._ge and L <= 0.0 and self._jit == 0.0 and self._dup <= 0.0 and self._hold <= 0.0

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
        if self._certain:
            return _CERTAIN
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
class Delivery(NamedTuple):
    """A packet coming out of the link: its number, when it was sent and delivered (s). (A named tuple, not a
    frozen dataclass: one is made for every packet on the lockstep's critical path, in a third of the time.)"""

    seq: int
    sent_t: float
    due_t: float
    payload: Any
    copy: bool = False  # the duplicate, not the original


class LinkImpairment:
    """One direction of an impaired link (see the module docstring).

    ``radio``: a :class:`~bridge.link.radio.Radio` this link shares with others (as its user ``user``: a
    fleet on one radio); by default the link has a radio of its own, made from its config's cap and queue.
    ``send(t, size, payload)`` puts a packet on the link at time t (s) and returns its
    number; ``deliver(t)`` returns every packet due by t, in delivery order. Times only
    need to be non-decreasing across calls. ``next_due()`` tells a real-time driver when
    to call :meth:`deliver` next.
    """

    def __init__(self, cfg: LinkConfig | None = None, direction: str = "up",
                 handovers: tuple[tuple[float, LinkConfig], ...] = (), radio: Radio | None = None,
                 user: int = 0) -> None:
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be 'up' or 'down', got {direction!r}")
        if radio is not None and handovers:
            raise ValueError("a link on a shared radio takes no handovers (the radio's rate is the fleet's)")
        self._shared = radio  # a radio shared with other links (this link its user ``user``), or None: its own
        self._user = user
        self.direction = direction
        self.stats = LinkStats()
        self._heap: list[tuple[float, int, Delivery]] = []
        self._order = 0
        self._held: list[Delivery] = []
        self._copies: dict[int, int] = {}  # seq -> copies still to come, for duplicated packets
        self._highest = -1
        self._last_due = -math.inf
        self._origin = 0.0  # this model's clock (s) at mission time 0: where the trace starts
        self._handovers = list(handovers)  # (mission time s, the link from then), in time order
        self._use(cfg or LinkConfig())

    def _use(self, cfg: LinkConfig) -> None:
        """Put packets on the link ``cfg`` from now (a handover: those in flight keep their fates; the packet
        numbers, and so the fates' draws, run on)."""
        n = self.fates.n if hasattr(self, "fates") else 0
        self.cfg = cfg
        self.fates = FateStream(cfg, self.direction)
        self.fates.n = n
        self._delay = cfg.delay_ms / 1000.0
        self.radio = self._shared if self._shared is not None else Radio(cfg.rate_bps, cfg.queue_ms / 1000.0)
        self._windows = tuple((s + self._origin, s + d + self._origin) for s, d in cfg.blackouts)
        self._replay = Replay(cfg.trace) if cfg.trace is not None else None
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
        while self._handovers and t - self._origin >= self._handovers[0][0] - 1e-9:
            self._use(self._handovers.pop(0)[1])
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
        tx = self.radio.admit(t, size, self._user)  # the bandwidth cap: its own radio's, or a shared one's
        if tx is None:
            st.lost_by["queue"] += 1
            return seq
        due = tx + delay + fate.jitter_s
        st.in_flight += 1
        d = Delivery(seq, t, due, payload)
        # the copy (step 6) is of the packet as the hold-back (step 5) left it: a held packet's copy is held with it
        both = (Delivery(seq, t, tx + delay + fate.dup_jitter_s, payload, True), d) if fate.dup_jitter_s is not None \
            else (d,)
        if len(both) == 2:
            self._copies[seq] = 2
        if fate.held:
            self._held.extend(both)
        else:
            for x in both:
                self._push(x)
            for h in self._held:  # released just after this successor
                self._push(h._replace(due_t=max(h.due_t, due)))
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
                self._push(h._replace(due_t=max(h.due_t, self._last_due)))
            self._held.clear()
            out += self.deliver(math.inf)
        return out


def fates(cfg: LinkConfig, direction: str, n: int) -> list[Fate]:
    """The first n fates of a direction (for tests and inspection)."""
    s = FateStream(cfg, direction)
    return [s.next() for _ in range(n)]
