"""A SITL fleet's shared step clock, one vehicle's side: the barrier between the vehicles of one lockstep fleet.

In:  the fleet's gate file (JSON, written by :mod:`bridge.session.fleet`: this vehicle's index, every vehicle's
     system id, disc radius (m) and gate port on 127.0.0.1); the plant's true position (m, x y z, the paper's
     frame) after each lockstep step k; the other vehicles' gate datagrams, and the fleet's word that one's
     process ended (:func:`say_lost`); wall time (s, ``time.monotonic``)
Out: datagrams to the other vehicles' gates (this vehicle at step k and where, or gone from step k and where it
     stays: NaN, nowhere known, when it flies on, on the wall clock); :meth:`Gate.clear`: whether step k may be
     flown (every other vehicle has flown step k - 1), else the clock ``gated``, or the contact's text to end the
     flight with (``collision``); :meth:`Gate.stats` (steps, seconds gated, the step and place it left, its
     contact, any vehicle taken as gone and why)

The offline fleet (:mod:`bridge.swarm`) flies every vehicle one step, then judges the world on their positions.
Here each vehicle, its step k - 1 flown, sends the state of step k to its controller and its position to every
other vehicle; before it flies step k with its controller's answer, it waits until it has every other vehicle's
position at step k (or that vehicle is gone, an obstacle where it stays), then judges the world itself with
:func:`missions.fleet.clearance`, the offline loop's test: every vehicle judges the same positions, so each
knows alone, at the same step, whether it touched, and whom. So the controllers compute while the vehicles
wait for each other, and no vehicle flies step k before every other has flown step k - 1. No vehicle is more than one
step ahead of another, so a datagram carries the last two positions, and one lost is made good by the next or
by the resend every :data:`RESEND_S`. A vehicle whose process ended without leaving (killed, crashed, stopped by
its session, or killed by it frozen) is taken as gone where it was last heard, at once: its fleet, which sees the
process end, binds the gate port it no longer holds and says so in its name (:func:`say_lost`, a ``LOST`` or
``FROZEN`` word: handled alike, said apart, :data:`SAID`). One silent for :data:`SILENT_S` (the fleet's word lost) is
taken as gone the same way. Each is said (:attr:`Gate.dropped`). A vehicle is heard from its own gate port only
(which no other process can bind while it runs, and its fleet holds once it is gone); the gate has no signing, as
the links without ``--key``.
"""

from __future__ import annotations

import json
import math
import select
import socket
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.link.radio import NEVER, RadioFile
from bridge.link.turns import LEFT, TurnRadio
from bridge.mavlink.endpoint import Endpoint, sweep
from bridge.nodes.vehicle.clock import Clock, ClockState, Trigger
from missions.fleet import clearance
from params import ConfigError

RESEND_S = 0.1  # s of wall time waiting at the gate before this vehicle's last word is sent again
SILENT_S = 30.0  # s of wall time without a word from a vehicle that has not flown step k: taken as gone
# s of wall time a fleet's controller waits for its vehicle's next state (bsst controller --state-timeout): its
# vehicle may wait at the gate SILENT_S after a silent vehicle's last word, which may come a step after this
# vehicle's state went out; the margin is for a loaded machine's steps (a controller alone waits 2 s)
STATE_WAIT_S = SILENT_S + 5.0
# s of wall time between two looks at the radio's turns while waiting for one (a lost TURN word's cost)
TURN_LOOK_S = 0.005
# TURN: a turn on the fleet's one radio taken (only wakes the others up); LOST: the fleet's word that the vehicle's
# process ended without leaving (:func:`say_lost`: no step, no position); FROZEN: the same of one its session
# killed, frozen (its controller heard nothing from it: bridge.session.alone)
AT, GONE, TURN, LOST, FROZEN = 0, 1, 2, 3, 4
# the fleet's two words, each said as what happened (Gate.dropped, summary.json's sitl.gate: docs/swarm.md): a
# frozen vehicle is taken as gone as a lost one is, where it was last heard; the record says which it was
SAID = {LOST: "ended (its process gone, said by the fleet)",
        FROZEN: "frozen (its controller heard nothing from it: killed, said by the fleet)"}
_WIRE = struct.Struct("<4sBBqdddddd")  # magic, kind, index, step, position at step, position at step - 1
_MAGIC = b"BSSG"


@dataclass(frozen=True)
class GateConfig:
    """The fleet's shared clock as one vehicle sees it: its index, and every vehicle's id, disc radius, port."""

    index: int
    ids: tuple[int, ...]
    radii: tuple[float, ...]  # m
    ports: tuple[int, ...]  # UDP on 127.0.0.1
    radio: str | None = None  # the fleet's one radio's file (bridge.link.turns; this vehicle its user ``index``)

    @staticmethod
    def load(path: str | Path) -> GateConfig:
        """Read a gate file; a bad one is a ConfigError naming it and what is wrong."""
        try:
            d = json.loads(Path(path).read_text())
            cfg = GateConfig(int(d["index"]), tuple(map(int, d["ids"])), tuple(map(float, d["radii"])),
                             tuple(map(int, d["ports"])), None if d.get("radio") is None else str(d["radio"]))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ConfigError(f"--gate {path}: not a fleet gate file ({exc})"[:300]) from None
        n = len(cfg.ids)
        if not (n >= 2 and len(cfg.radii) == n and len(cfg.ports) == n and 0 <= cfg.index < n
                and all(0 < p < 65536 for p in cfg.ports) and all(r > 0 and math.isfinite(r) for r in cfg.radii)):
            raise ConfigError(f"--gate {path}: expected index 0..N-1 and N >= 2 ids, disc radii > 0 m and ports")
        return cfg

    def dump(self, path: Path) -> None:
        path.write_text(json.dumps({"index": self.index, "ids": self.ids, "radii": self.radii, "ports": self.ports,
                                    "radio": self.radio}))


def resting(X: tuple[float, ...], armed: bool) -> tuple[float, float, float]:
    """Where a vehicle of state X (paper frame, m) stays once out of the shared clock: its centre, or, disarmed in
    the air, on the ground below it: lockstep time stands still for a disarmed vehicle, so its plant never flies
    the fall (the offline fleet's does, and lies there)."""
    return X[0], X[2], X[4] if armed or X[4] <= 0.0 else 0.0


class Gate:
    """One vehicle's side of the shared clock (the module's docstring): :meth:`after_step` (its word to the others),
    :meth:`clear` before each step, :meth:`serve` while gated, :meth:`over` (it leaves when its flight is over)."""

    def __init__(self, cfg: GateConfig, clock: Clock, position: Callable[[], tuple[float, float, float]],
                 rate: float, turns: TurnRadio | None = None,
                 rest: Callable[[], tuple[float, float, float]] | None = None) -> None:
        self.cfg = cfg
        self.turns = turns  # the fleet's one radio (up): this vehicle's turns on it
        self.turn_at: int | None = None  # the step whose turn on the radio it waits for
        self.clock = clock
        self.position = position  # the plant's true centre now (m)
        self.rest = rest or position  # where it stays once out of the shared clock (m): disarmed, on the ground
        self.rate = rate
        self.me = cfg.index
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(("127.0.0.1", cfg.ports[self.me]))
        except OSError as exc:
            self.sock.close()
            raise ConfigError(f"--gate: cannot bind 127.0.0.1:{cfg.ports[self.me]} ({exc.strerror})") from None
        self.sock.setblocking(False)
        self.others = [j for j in range(len(cfg.ids)) if j != self.me]
        self._to = [("127.0.0.1", cfg.ports[j]) for j in self.others]
        self._from = dict(zip(self.others, self._to))
        self.at: dict[int, dict[int, tuple[float, float, float]]] = {j: {} for j in self.others}
        self.gone: dict[int, tuple[int, tuple[float, float, float]]] = {}  # index: (from step, where it stays)
        self.heard = {j: time.monotonic() for j in self.others}
        self.dropped: list[str] = []  # the vehicles taken as gone where last heard (process ended, silent): when, why
        self.flying = False  # arrived at a step once: a member of the shared clock until it leaves
        self.left: tuple[int, tuple[float, float, float]] | None = None
        self.step = -1  # the step it waits at
        self.judged = -1  # the last step judged (its verdict given)
        self.pos = self.prev = (math.nan, math.nan, math.nan)
        self._last = b""
        self._sent_at = 0.0
        self.steps = 0
        self.wait_s = 0.0
        self._since: float | None = None
        self.contact: dict[str, Any] | None = None

    # -- in the vehicle's loop ----------------------------------------------------------------------
    def after_step(self, k: int, alive: bool) -> None:
        """Lockstep step k - 1 flown (the mission's, or its end landing's: clocked as the mission, judged as it, as
        the offline loop judges it), the plant now at step k (``alive``: not diverged or crashed), its state gone to
        the controller: tell every other vehicle. The vehicle leaves the shared clock when its lockstep flight is
        over: where its plant ended it (diverged, crashed: there, as the offline fleet's vehicle stays where it
        ended, in the air too), or where it comes to rest (:attr:`rest`: its landing disarmed it, a disarm, the wall
        clock)."""
        if self.left is not None:
            return
        if not alive:
            self.leave(k, self.position())
        elif self.clock.state is not ClockState.LOCKSTEP:
            self.leave(k, self.rest())
        else:
            self.arrive(k, self.position())

    def clear(self, collide: Callable[[str], None], turn: int | None = None) -> bool:
        """The answer of step k held (ANSWERED or GATED): whether step k may be flown now, every other vehicle
        having flown step k - 1 and none touching this one, and on the fleet's one radio this vehicle's ``turn``
        of step k come (None: no turn, the mission's end). If not yet, the clock is GATED until :meth:`serve`
        clears it; touched, ``collide`` ends the flight (and the vehicle leaves, where it is)."""
        if self.left is not None:
            self.turn_at = None
            return True
        self.turn_at = turn if self.turns is not None else None
        if self.judged != self.step:
            self.poll()
            why = self.verdict(self.rate)
            if why is None:
                return self._gated()
            self.judged = self.step
            if why:
                self._waited()
                collide(why)
                self.leave()
                return False
        if self.turn_at is not None and self.turns.blocking(self.turn_at):  # type: ignore[union-attr]
            return self._gated()
        self.turn_at = None
        self._waited()
        if self.clock.state is ClockState.GATED:
            self.clock.fire(Trigger.RELEASE)
        return True

    def _gated(self) -> bool:
        """Not clear yet: the held answer waits (GATED), from now if it just came."""
        if self.clock.state is ClockState.ANSWERED:
            self.clock.fire(Trigger.GATE)
            self._since = time.monotonic()
        return False

    def _waited(self) -> None:
        if self._since is not None:  # the time its answer was held for the others (gated)
            self.wait_s += time.monotonic() - self._since
            self._since = None

    def took(self, k: int) -> None:
        """This vehicle's turn of step k on the fleet's one radio is taken (its packets of the step admitted):
        said in the radio's file, and the other vehicles woken up to look."""
        self.turns.took(k)  # type: ignore[union-attr]
        word = _WIRE.pack(_MAGIC, TURN, self.me, k, *self.pos, *self.prev)
        for a in self._to:
            try:
                self.sock.sendto(word, a)
            except OSError:
                pass  # (a vehicle gone: nothing waits on it)

    def serve(self, endpoints: Sequence[Endpoint], deadline: float,
              handle: Callable[[Endpoint, Any, tuple[str, int]], None], collide: Callable[[str], None],
              fly: Callable[[], None]) -> None:
        """Gated: serve the links until ``deadline`` or every other vehicle has flown the step before; then the
        held answer's step is flown (``fly``), or, touched by another vehicle, the flight ends (``collide``)."""
        for ep, m, addr in self.wait(endpoints, deadline):
            handle(ep, m, addr)
        if self.clock.state is ClockState.GATED and self.clear(collide, self.turn_at):
            fly()

    def over(self, k: int) -> None:
        """Not in lockstep any more (disarmed, on the wall clock, halted): a flight that was at the gate leaves it, to
        stay where it comes to rest (:attr:`rest`)."""
        if self.flying and self.left is None:
            self.leave(k, self.rest())

    # -- this vehicle ------------------------------------------------------------------------------
    def arrive(self, k: int, pos: tuple[float, float, float]) -> None:
        """Step k flown (its true position after it, m): tell every other vehicle, and wait at the gate."""
        self.flying = True
        self.prev, self.pos, self.step = self.pos, pos, k
        self._send(AT, k, pos, self.prev)
        self.steps += 1

    def leave(self, k: int | None = None, pos: tuple[float, float, float] | None = None) -> None:
        """This vehicle's lockstep flight is over: it stays at ``pos`` from step ``k`` (default: the last step it
        arrived at, where it was then), an obstacle; the others wait for it no more."""
        if self.left is not None:
            return
        k, pos = (self.step, self.pos) if k is None or pos is None else (k, pos)
        self.left = (k, pos)
        if self.turns is not None:  # in the radio's file before any vehicle hears of it (bridge.link.turns)
            self.turns.leave(k)
        # flying on, on the wall clock (a ground station's mode, its controller lost): not there for long, so no
        # obstacle there (the fleet judges its record afterwards, bridge.swarm); else it stays there
        there = (math.nan,) * 3 if self.clock.state is ClockState.FREE_RUNNING else pos
        for _ in range(2):  # (a copy: nothing waits for an answer to this one)
            self._send(GONE, k, there, there)

    def _send(self, kind: int, k: int, pos: Sequence[float], prev: Sequence[float]) -> None:
        self._last = _WIRE.pack(_MAGIC, kind, self.me, k, *pos, *prev)
        self._sent_at = time.monotonic()
        for a in self._to:
            try:
                self.sock.sendto(self._last, a)
            except OSError:
                pass  # a vehicle not bound yet, or gone: its resend or its silence decides

    # -- the others -------------------------------------------------------------------------------
    def poll(self) -> None:
        """Take every datagram waiting on the gate's socket (never blocks)."""
        now = time.monotonic()
        while True:
            try:
                data, addr = self.sock.recvfrom(256)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # (an ICMP refusal of an earlier send to a vehicle not bound yet)
            if len(data) != _WIRE.size:
                continue
            magic, kind, j, k, *xs = _WIRE.unpack(data)
            if magic != _MAGIC or self._from.get(j) != addr:
                continue  # (heard from vehicle j's own gate port only, as the controller from its pinned port)
            self.heard[j] = now
            if kind == GONE:
                self.gone.setdefault(j, (k, (xs[0], xs[1], xs[2])))
            elif kind in SAID:
                self._drop(j, SAID[kind])
            elif kind == AT and j not in self.gone:
                seen = self.at[j]
                seen[k] = (xs[0], xs[1], xs[2])
                seen.setdefault(k - 1, (xs[3], xs[4], xs[5]))

    def _where(self, j: int, k: int) -> tuple[float, float, float] | None:
        """Vehicle j's position at step k, None if not known yet."""
        p = self.at[j].get(k)
        if p is not None:
            return p
        g = self.gone.get(j)
        return g[1] if g is not None and g[0] <= k else None

    def complete(self) -> bool:
        """Whether every other vehicle's position at the step waited at is known."""
        k = self.step
        return all(self._where(j, k) is not None for j in self.others)

    def verdict(self, rate: float) -> str | None:
        """Waiting at step k: None until every other vehicle's position at k is known; then "" (no contact) or
        the contact's text, as the offline loop tells it (its last pair, in id order, touching this vehicle;
        ``rate`` Hz, for its time)."""
        k = self.step
        where = []
        for j in self.others:
            p = self._where(j, k)
            if p is None:
                self._silence(j)
                return None
            where.append((j, p))
        for j in self.others:
            seen = self.at[j]
            for s in [s for s in seen if s < k]:
                del seen[s]
        why = ""
        me, ids, radii, t = self.me, self.cfg.ids, self.cfg.radii, k / rate
        for j, p in where:
            d, c = clearance(self.pos, p, radii[me], radii[j])
            if c <= 0.0:
                a, b = min(me, j), max(me, j)
                why = (f"vehicles {ids[a]} and {ids[b]} touched at t={t:.3f} s (centres {d:.3f} m apart, "
                       f"rotor discs {c:.3f} m)")
                self.contact = {"step": k, "with": ids[j], "why": why}
        return why

    def _silence(self, j: int) -> None:
        """Vehicle j has not flown step k: send this vehicle's word again now and then; silent too long, j is
        taken as gone where it was last heard of."""
        now = self._resend()
        if now - self.heard[j] >= SILENT_S:
            self._drop(j, f"silent for {SILENT_S:g} s")

    def _drop(self, j: int, why: str) -> None:
        """Vehicle j did not leave but is gone (``why``): from the step waited at, where it was last heard of (its
        words of later steps, one ahead, still count); said in :attr:`dropped`. One that left already stays where
        it said."""
        if j in self.gone:
            return
        seen = self.at[j]
        last = seen[max(seen)] if seen else (math.nan, math.nan, math.nan)
        self.gone[j] = (self.step, last)
        self.dropped.append(f"vehicle {self.cfg.ids[j]} {why} at step {self.step}: taken as gone where it was last")

    def _resend(self) -> float:
        """Waiting at the gate (for the others, or for a turn on the radio): this vehicle's last word again once
        :data:`RESEND_S` has passed since it was sent (one sent before another vehicle's gate was bound, or lost,
        is made good so); the time now."""
        now = time.monotonic()
        if now - self._sent_at >= RESEND_S and self._last:
            for a in self._to:
                try:
                    self.sock.sendto(self._last, a)
                except OSError:
                    pass
            self._sent_at = now
        return now

    def wait(self, endpoints: Sequence[Endpoint], deadline: float) -> list[tuple[Endpoint, Any, tuple[str, int]]]:
        """Messages from the links, waiting at most until ``deadline`` (``time.monotonic``) or the gate's word."""
        self.poll()
        out = sweep(endpoints, deadline)
        turn = self.turn_at is not None
        if out or (self.complete() and not turn):
            return out
        if turn:  # (judged: _silence does not run)
            self._resend()
        left = min(deadline, self._sent_at + RESEND_S, time.monotonic() + TURN_LOOK_S if turn else math.inf)
        left -= time.monotonic()
        if left > 0.0:
            try:
                select.select([self.sock] + [ep.wake_socket for ep in endpoints], [], [], left)
            except InterruptedError:
                pass
        self.poll()
        return sweep(endpoints, deadline)

    def stats(self) -> dict[str, Any]:
        """The shared clock as this vehicle saw it (its stats report's ``gate``)."""
        left = self.left
        return {"steps": self.steps, "wait_s": round(self.wait_s, 3), "contact": self.contact,
                "left": None if left is None else {"step": left[0], "position": list(left[1])},
                "dropped": self.dropped}

    def close(self) -> None:
        self.sock.close()


def say_lost(cfg: GateConfig, frozen: bool = False) -> socket.socket | None:
    """Vehicle ``cfg.index``'s process has ended (its fleet saw it): every other gate is told at once that it is
    gone where it was last heard (a ``LOST`` word, ``FROZEN`` for one its session killed ``frozen``, twice, from its
    own gate port, which the process no longer holds;
    a gate that heard it leave keeps where it said it stays), and on the fleet's one radio it takes no turn after
    the ones it took. The port's socket is returned for the caller to hold until the fleet is over, so that no other
    process speaks for the vehicle; None if the port is taken (the others' :data:`SILENT_S` then acts)."""
    j = cfg.index
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind(("127.0.0.1", cfg.ports[j]))
    except OSError:
        sock.close()
        return None
    if cfg.radio is not None:  # in the radio's file before any gate hears of it, as a vehicle that leaves
        _left_radio(cfg.radio, j)
    word = _WIRE.pack(_MAGIC, FROZEN if frozen else LOST, j, -1, *(math.nan,) * 6)
    for _ in range(2):  # (a copy: nothing answers it; the silence rule is the last resort)
        for i, port in enumerate(cfg.ports):
            if i != j:
                try:
                    sock.sendto(word, ("127.0.0.1", port))
                except OSError:
                    pass  # (a vehicle gone too)
    return sock


def _left_radio(path: str, j: int) -> None:
    """User j of the fleet's one radio takes no turn from the first step it has not taken both turns of (up, its
    vehicle's; down, its controller's), unless it left already: nobody waits for a turn it never takes."""
    f = RadioFile(path, j, "--gate's radio")
    try:
        f.lock()
        try:
            row = f.turns()[j]
            if row[LEFT] == NEVER:
                f.set_turn(LEFT, min(row[0], row[1]) + 1)
        finally:
            f.unlock()
    finally:
        f.close()
