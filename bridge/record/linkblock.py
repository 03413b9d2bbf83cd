"""A session's ``summary.json["link"]``: each direction's counts and delays, from what each side said on exit.

In:  the join's measures (:class:`~bridge.record.joiner.Joined`: per-packet one-way times, ms; the controller's rows
     and steps), each side's ``stats`` report (counts; monotonic s), the relay's statistics (``relay.json``'s dict),
     and for a side that ended without its stats (killed: :class:`Cut`) the per-step messages as both tlogs show them
Out: :func:`link_block`'s dict (counts of datagrams, delays ms), per direction ``up`` (controller -> vehicle) and
     ``down``; where a side left no stats its directions are counted from both tlogs up to its cut, or are null
     with the reason (``counted`` / ``unknown``), never made up from one side's counts (docs/sitl.md)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from bridge.record.joiner import Joined
from bridge.record.metrics import percentiles
from bridge.record.tlogmatch import DirectionRecords

_SENT = {"up": "actuator target", "down": "ODOMETRY"}  # the per-step messages counted, each way


@dataclass(frozen=True)
class Cut:
    """A side that ended without its ``stats`` report (a SIGKILL leaves none; its tlog and half end at their last
    write): ``side`` (``vehicle`` or ``controller``), ``how`` (its exit, as said: ``killed by SIGKILL``) and the
    per-step messages (up: the actuator targets, down: ODOMETRY) as both tlogs show them, up to the last one the two
    logs both hold (``records``: up, down, :func:`bridge.record.linkextract.step_records`; None: no readable pair);
    ``modelled``: the dead side applied a link model (or a shared radio's turns) to what its socket read (lockstep:
    the model acts after the socket, in simulation time), so its direction's counts are the sockets', not the
    model's, which went with its stats."""

    side: str
    how: str
    records: tuple[DirectionRecords, DirectionRecords] | None
    modelled: bool = False


def cut_counts(direction: str, cut: Cut) -> dict[str, Any]:
    """One direction's counts where ``cut.side`` left no stats: from both tlogs up to the cut (``counted`` says so),
    or, without them, null (``unknown`` says why; until the third wave's forty-third session ``reordered`` was null
    even where both tlogs held the order). Before the third wave's forty-second session one side's count
    stood in for the other's: a vehicle killed at 2.2 s read ``up: sent 561 delivered 0 lost 561``, ``down: sent 0
    delivered 567 lost -567``."""
    why = f"the {cut.side} ended without its stats ({cut.how})"
    if cut.records is None:
        return {"sent": None, "delivered": None, "lost": None, "duplicated": None, "reordered": None,
                "unknown": f"{why} and the run holds no readable vehicle.tlog and controller.tlog to count from"}
    r = cut.records[0 if direction == "up" else 1]
    model = ""
    if cut.modelled and direction == ("up" if cut.side == "vehicle" else "down"):  # its side's model: after the socket
        model = (f"; counted at the sockets: the link model the {cut.side} applied after its socket (lockstep) went "
                 f"with its stats, so what that model lost, duplicated or held back is not in these counts")
    return {"sent": r.sent, "delivered": r.sent - r.lost, "lost": r.lost, "duplicated": r.duplicates,
            "reordered": r.reordered,
            "counted": f"{why}: each {_SENT[direction]} in both tlogs up to the last one both hold ({cut.side}'s "
                       f"tlog ends at its last write; reordered: received after one sent later, in the order the "
                       f"receiver's tlog read them); those sent after are not counted{model}"}


def link_block(joined: Joined, vehicle: Mapping[str, Any], controller: Mapping[str, Any],
               relay: Mapping[str, Any] | None, cut: Cut | None = None) -> dict[str, Any]:
    """``summary.json["link"]`` (docs/design.md, "Files of a run") from each side's ``stats`` (``vehicle``,
    ``controller``; empty when a side left none), the join's measures, and the relay's statistics, per direction:

    - lockstep: the link model's exact statistics, from the end that applies it (the
      vehicle: ``up``, the controller: ``down``), ``delay_ms`` in simulation time; plus
      ``socket_ms``, the wall-clock one-way time of the per-step messages over the socket;
    - real time through the relay: the relay's counts (every datagram), ``delay_ms``
      measured end to end on every per-step message delivered (ODOMETRY down, the targets up)
      from both ends' tlogs (one host: one clock, no offset to estimate), the
      model's schedule (``model_delay_ms``) and the delay the relay added (``relay_added_ms``);
    - a side that ended without its stats (``cut``: killed), where neither of those holds: :func:`cut_counts`;
    - otherwise (real time, perfect link): counts from both sides (one a unit test gives none of: its joined rows
      stand for it), ``delay_ms`` from their stamps.
    """
    vs, cs = vehicle, controller
    # what each side's receive path refused (bridge.mavlink.receive), and all of it by reason
    by = {"vehicle": dict(vs.get("rejected", {})), "controller": dict(cs.get("rejected", {}))}
    rejected = {r: by["vehicle"].get(r, 0) + by["controller"].get(r, 0)
                for r in sorted(set(by["vehicle"]) | set(by["controller"]))}
    own = int(vs.get("rejected_from_controller", sum(by["vehicle"].values())))  # of the controller's datagrams
    # none measured (no step flown: a failsafe before the first target) is null, as offline, never 0 ms: a run that
    # never flew said "delay p50 0.00 ms" of a 95 ms link until the third wave's forty-third session
    measured = {"up": percentiles(joined.up_ms, empty=None), "down": percentiles(joined.down_ms, empty=None)}
    model = {"up": vs.get("up"), "down": cs.get("down")}
    sides = {"up": socket_counts(int(cs.get("commands", joined.commands)), int(vs.get("accepted", 0)), own,
                                 *targets_outside(vs, cs), kernel=vs.get("kernel_drops")),
             # a killed controller left no stats: its rows, the steps they answer, and no time it stopped reading
             "down": socket_counts(int(vs.get("odometry_sent", 0)), int(cs.get("states", joined.commands)),
                                   int(cs.get("states_refused", 0)),
                                   *sends_outside(vs, cs if "state_window" in cs
                                                  else {"state_window": joined.controller_steps}),
                                   kernel=cs.get("kernel_drops"))}
    sides["up"]["reordered"] = int(rejected.get("reordered", 0))
    out: dict[str, Any] = {}
    for d in ("up", "down"):
        if relay is not None:
            r = relay[d]
            out[d] = {**{k: r[k] for k in ("sent", "delivered", "lost", "duplicated", "reordered", "in_flight",
                                           "lost_by")},
                      # the relay's socket of this direction: what the kernel dropped before the relay read it
                      "dropped_by_kernel": (relay.get("kernel_drops") or {}).get(d),
                      "delay_ms": measured[d], "model_delay_ms": r["delay_ms"], "relay_added_ms": r["measured_ms"]}
            if "trace" in r:  # a replayed link trace: its own delays and losses, as offline
                out[d]["trace"] = r["trace"]
        elif model[d]:
            out[d] = {**model[d], "socket_ms": measured[d]}
        elif cut is not None:  # a side killed: no count of its own, nor one side's for both
            out[d] = {**cut_counts(d, cut), "delay_ms": measured[d]}
        else:
            out[d] = {**sides[d], "delay_ms": measured[d]}
    out["rejected"] = rejected
    out["rejected_by"] = by
    # of those, how many came from the other side itself, and how many from anyone else on the link (a
    # ground station's, a stranger's): the vehicle counts its controller's apart from the GCS link's
    ctl_own = int(cs.get("rejected_from_vehicle", sum(by["controller"].values())))
    out["rejected_from_peer"] = {"vehicle": own, "controller": ctl_own}
    out["rejected_from_others"] = {"vehicle": max(0, sum(by["vehicle"].values()) - own),
                                   "controller": max(0, sum(by["controller"].values()) - ctl_own)}
    if relay is not None:  # datagrams the relay refused, from neither of its two ends, by reason
        out["relay_refused"] = relay.get("refused", {})
        if relay.get("radio"):  # a fleet's one radio in real time: this vehicle's part of it, by direction
            out["radio"] = relay["radio"]
    elif vs.get("radio") or cs.get("radio"):  # in lockstep: the vehicle's commands, the controller's states
        out["radio"] = {"up": vs.get("radio"), "down": cs.get("radio")}
    return out


def socket_counts(sent: int, delivered: int, refused: int, in_flight: int, maybe: int = 0, *,
                  kernel: int | None) -> dict[str, Any]:
    """One direction of a link with no model between the two sockets (real time, perfect link), every datagram
    sent accounted for under its own name: ``delivered``; ``refused`` by the receiver; ``in_flight``, sent
    where the receiver was not reading (outside the steps it read, after it stopped: :func:`sends_outside`),
    plus of the ``maybe`` sends it cannot tell (read, or sent after it stopped) as many as were not read;
    ``shed`` by the receive budgets (none: the peer is exempt, docs/hostile-input.md); ``dropped_by_kernel`` (the
    receiving socket's counter, :func:`bridge.mavlink.kerneldrops.socket_drops`; 0 where unknown); ``lost`` on the
    link, the rest (sent = delivered + refused + lost + in_flight + shed + dropped_by_kernel)."""
    dropped = int(kernel or 0)
    in_flight += min(maybe, max(0, sent - delivered - refused - in_flight - dropped))
    return {"sent": sent, "delivered": delivered, "lost": sent - delivered - refused - in_flight - dropped,
            "duplicated": 0, "reordered": 0, "refused": refused, "in_flight": in_flight, "shed": 0,
            "dropped_by_kernel": dropped, "kernel_counts": kernel is not None}


def sends_outside(vehicle: Mapping[str, Any], controller: Mapping[str, Any]) -> tuple[int, int]:
    """Of the vehicle's state sends (its ``stats``: :class:`bridge.mavlink.receive.StepSends`), how many the
    controller surely never read, and how many it may not have: (surely, maybe). Surely: every send of a step
    outside the controller's window of steps read (``state_window``; each resend of one too), and a resend of a
    step inside it that left after the controller stopped reading (``read_until``; the resend's time before it
    left later: one host, one monotonic clock). Maybe: a resend that was leaving just then, one of steps past
    the vehicle's list, and the resends older than those it timed when even its oldest timed one left after."""
    window = controller.get("state_window")
    again = [(int(k), int(n)) for k, n in vehicle.get("odometry_again") or []]
    unlisted = int(vehicle.get("odometry_again_unlisted", 0))
    surely = steps_outside(vehicle.get("odometry_steps") or [], window)
    if window is None:  # it read none: every send
        return surely + sum(n for _, n in again) + unlisted, 0
    lo, hi = window
    surely += sum(n for k, n in again if not lo <= k <= hi)
    inside = sum(n for k, n in again if lo <= k <= hi)  # resends of steps it read: before it stopped, or after
    until = controller.get("read_until")
    if until is None:  # it did not say when it stopped reading
        return surely, unlisted + inside
    resent = vehicle.get("odometry_resent") or []  # the latest resends, oldest first: [step, before, after]
    timed = [(a, b) for k, a, b in resent if lo <= k <= hi]
    after, leaving = left_after(timed, until)
    untimed = sum(n for _, n in again) + unlisted - len(resent)  # older than those timed
    unsure = max(0, min(untimed, inside - len(timed))) if untimed > 0 and resent and resent[0][1] > until else 0
    return surely + after, unlisted + leaving + unsure


def targets_outside(vehicle: Mapping[str, Any], controller: Mapping[str, Any]) -> tuple[int, int]:
    """Of the controller's targets, how many surely left after the vehicle stopped reading (its ``read_until``; the
    controller's latest targets timed, ``targets_left``), and how many may have (leaving just then; older than those
    timed when even the oldest timed left after): (surely, maybe). (0, 0) where either side did not say."""
    until = vehicle.get("read_until")
    timed = [(a, b) for a, b in controller.get("targets_left") or []]
    if until is None or not timed:
        return 0, 0
    after, leaving = left_after(timed, until)
    older = int(controller.get("commands", 0)) - len(timed)
    return after, leaving + (older if older > 0 and timed[0][0] > until else 0)


def left_after(timed: Sequence[tuple[float, float]], until: float) -> tuple[int, int]:
    """Of sends timed ``(before, after)`` (s, ``time.monotonic``), how many surely left after ``until`` (the
    receiver's last look found its socket empty then: queued before it, read; after it, never) and how many were
    leaving at that very time (read or not)."""
    return sum(a > until for a, _ in timed), sum(a <= until <= b for a, b in timed)


def steps_outside(sent: Sequence[Sequence[int]], window: Sequence[int] | None) -> int:
    """How many of the steps ``sent`` (inclusive ``[first, last]`` ranges,
    :class:`bridge.mavlink.receive.StepRanges`) lie outside the receiver's ``window`` ([first, last] step read;
    None: it read none, all of them)."""
    total = sum(b - a + 1 for a, b in sent)
    if window is None:
        return total
    lo, hi = window
    inside = sum(max(0, min(b, hi) - max(a, lo) + 1) for a, b in sent)
    return total - inside


