"""A link as it was: per-packet one-way delays and losses of both directions, from a run directory of ours
or two tlogs recorded at the two ends of any MAVLink link (``bsst link extract``; docs/links.md).

In:  a real-time run directory (``vehicle.tlog`` and ``controller.tlog``; without them ``vehicle.bin``
     and ``controller.bin``), or a vehicle-end and a controller-end tlog (8-byte big-endian Unix time
     in us + one MAVLink 1 or 2 frame, repeated: what MAVProxy and our nodes write); which clock the two
     ends' stamps are on (``same``, or ``timesync``: the offset estimated from TIMESYNC exchanges)
Out: :class:`Extraction`: per direction the records (send time s from the trace's start, one-way delay
     s or None for lost) and its counts, the clock offset used, notes; :func:`extraction_text`, the
     trace file (``t_s, delay_ms, direction``) that ``[link] trace`` replays; :func:`step_delays`, a real-time
     session's per-step messages' one-way delays (ms), for its ``summary.json``; :func:`step_records`, those
     messages each way as both tlogs hold them (a killed side's link counted up to its cut)

How (tlogs): the frames of the two ends matched per source (:mod:`bridge.record.tlogmatch`), checked to be
the two ends of one link, on one clock (``timesync``: the controller's stamps shifted by the offset).
A run directory's trace starts (``t_s`` = 0) at the flight's time 0 (the state the first actuator
target answers left the vehicle), a pair of tlogs' at the first frame.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from bridge.link.trace import DELAY_RANGE_MS, trace_text
from bridge.record.halves import half_arrays
from bridge.record.tlogmatch import (
    STAMP_SLACK_S,
    DirectionRecords,
    Frame,
    Source,
    by_source,
    direction_records,
    merge_directions,
    parse_tlog,
    read_tlog,
    sender_ends,
    timesync_offset,
    u64,
)
from params import ConfigError, read_regular_file, unreachable

CLOCKS = ("same", "timesync")
RUN_INPUTS = ("vehicle.tlog", "controller.tlog", "vehicle.bin", "controller.bin", "summary.json")  # what it reads
EXTRACT = "bsst link extract"  # the command its refusals open with (ConfigError.source)
_ODOMETRY = 331
_TARGETS = (93, 139)  # HIL_ACTUATOR_CONTROLS, SET_ACTUATOR_CONTROL_TARGET: both open with time_usec
_HEARTBEAT, _AUTOPILOT_INVALID = 0, 8  # a HEARTBEAT's autopilot (payload byte 5): MAV_AUTOPILOT_INVALID is none


@dataclass
class Extraction:
    """Both directions of one link, where its time 0 is, and the clock and inputs it was read with."""

    up: DirectionRecords
    down: DirectionRecords
    origin: str  # what t_s = 0 is
    clock: str
    offset_s: float = 0.0  # vehicle clock - controller clock, as used
    timesync: tuple[float, float] | None = None  # (offset s, round trip s) TIMESYNC gives, when it can
    inputs: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)


def _flight_origin(vehicle: Sequence[Frame], controller: Sequence[Frame], ends: dict[Source, str],
                   shift_c: float) -> float | None:
    """The vehicle-clock time (s) the state answered by the first actuator target left the vehicle."""
    first = next((f for f in controller if f.msgid in _TARGETS and ends.get(f.src) == "b"), None)
    if first is None:
        return None
    usec = u64(first.payload)
    for f in vehicle:
        if f.msgid == _ODOMETRY and ends.get(f.src) == "a" and u64(f.payload) == usec:
            return f.t
    return first.t + shift_c


def extract_tlogs(vehicle: Sequence[Frame], controller: Sequence[Frame], clock: str = "same",
                  run_dir: bool = False, inputs: tuple[str, ...] = ()) -> Extraction:
    """Both directions of the link between the two ends whose tlogs these are (module docstring).
    ``run_dir``: the trace starts at the flight's time 0, else at the first frame. Two tlogs that are not
    the two ends of one link (one tlog twice, clocks that never overlap, no frame of one in the other, frames
    received before they were sent) are a ``ConfigError``: their figures would be nonsense."""
    if clock not in CLOCKS:
        raise ConfigError(f"--clock must be one of {', '.join(CLOCKS)}, got {clock!r}")
    names = " and ".join(inputs) or "the tlogs"
    if len(vehicle) == len(controller) and all(a.t == b.t and a.raw == b.raw for a, b in zip(vehicle, controller)):
        raise ConfigError(f"{names}: the same frames at the same times: one tlog given as both ends (give the "
                          f"vehicle's tlog and the controller's)")
    ends = sender_ends(vehicle, controller)
    if not ends:
        raise ConfigError(f"{names}: no MAVLink source appears in both, so no frame crossed between them: not the "
                          f"two ends of one link")
    _check_order(vehicle, controller, ends, inputs)
    ts = timesync_offset(vehicle, controller, ends)
    notes = []
    if clock == "timesync":
        if ts is None:
            raise ConfigError(f"--clock timesync: {names} hold no complete TIMESYNC exchange (a request and its "
                              f"answer, each seen at both ends)")
        shift_c = ts[0]  # controller stamps + shift = vehicle clock
    else:
        shift_c = 0.0
        if ts is not None and abs(ts[0]) > max(0.005, ts[1]):
            notes.append(f"TIMESYNC puts the vehicle's clock {ts[0] * 1e3:+.1f} ms from the controller's (round trip "
                         f"{ts[1] * 1e3:.1f} ms): if the two ends' clocks differ, use --clock timesync")
    _check_overlap(vehicle, controller, shift_c, names)
    v_by, c_by = by_source(vehicle), by_source(controller)
    per: dict[str, list[DirectionRecords]] = {"up": [], "down": []}
    for src, end in sorted(ends.items()):
        _check_sequence(v_by[src] if end == "a" else c_by[src], src, names)
        if end == "a":  # the vehicle's: down
            per["down"].append(direction_records(v_by[src], c_by[src], shift_c))
        else:  # the controller's, on its clock shifted to the vehicle's: up
            sent = [Frame(f.t + shift_c, f.src, f.msgid, f.seq, f.raw, f.payload) for f in c_by[src]]
            per["up"].append(direction_records(sent, v_by[src], 0.0))
    up, down = merge_directions(per["up"]), merge_directions(per["down"])
    _check_matched(up, down, names)
    outside = up.outside + down.outside
    if outside:
        notes.append(f"{_frames(outside)} received before the other end's tlog starts or after it ends (a tlog cut "
                     f"short?) left out: only the time both tlogs cover counts")
    notes += _delays_in_range(up, down, clock, names)
    origin = _flight_origin(vehicle, controller, ends, shift_c) if run_dir else None
    what = "the flight's time 0 (the state the first actuator target answers left the vehicle)"
    if origin is None:
        origin, what = min(r[0][0] for r in (up.records, down.records) if r), "the first frame sent either way"
    for d in (up, down):
        d.records = [(t - origin, x) for t, x in d.records if t >= origin]
    return Extraction(up, down, what, clock, shift_c, ts, inputs, notes)


def _check_sequence(sent: list[Frame], src: tuple[int, int], names: str) -> None:
    """Refuse a sender whose frames do not count up: the losses are read from the gaps in the sequence numbers,
    and a sequence that stands still (most frames with their predecessor's number) reads as 255 lost between any
    two delivered frames (a script that left pymavlink's seq at 0 gave 484 865 sent of the 2 000 it logged)."""
    still = sum(1 for a, b in zip(sent, sent[1:], strict=False) if a.seq == b.seq)
    if len(sent) > 2 and 2 * still > len(sent) - 1:
        raise ConfigError(f"{names}: source {src[0]}:{src[1]}'s frames do not count up ({still} of {len(sent) - 1} "
                          f"carry the sequence number of the one before): the losses are read from the sequence "
                          f"numbers, so they cannot be counted for it")


def _delays_in_range(up: DirectionRecords, down: DirectionRecords, clock: str, names: str) -> list[str]:
    """Make every delay one a trace may give (:data:`bridge.link.trace.DELAY_RANGE_MS`), or refuse; the notes
    that say what was changed. A frame stamped received before it was sent, by more than the stamps' resolution
    (:data:`STAMP_SLACK_S`) on one clock, is refused (clocks that differ, or not one link); within it, or on
    the TIMESYNC clock (whose offset is then off by that much), its delay is written as 0, and said so."""
    negative = [x for d in (up, down) for _, x in d.records if x is not None and x < 0.0]
    longest = max((x for d in (up, down) for _, x in d.records if x is not None), default=0.0)
    if longest > DELAY_RANGE_MS[1] / 1e3:
        raise ConfigError(f"{names}: a frame took {longest:.6g} s to arrive by the stamps, longer than a link trace "
                          f"may give ({DELAY_RANGE_MS[1] / 1e3:g} s): the two ends' clocks differ (use --clock "
                          f"timesync) or these are not the two ends of one link")
    if not negative:
        return []
    early = -min(negative)
    if early > STAMP_SLACK_S and clock == "same":
        raise ConfigError(f"{names}: {sum(x < -STAMP_SLACK_S for x in negative)} frames arrived before they were "
                          f"sent by the stamps (by up to {early:.6g} s): the two ends' clocks differ (use --clock "
                          f"timesync) or these are not the two ends of one link")
    for d in (up, down):
        d.records = [(t, None if x is None else max(x, 0.0)) for t, x in d.records]
    why = (f"within the stamps' resolution ({STAMP_SLACK_S * 1e3:g} ms)" if early <= STAMP_SLACK_S
           else "the TIMESYNC offset is off by at least that much")
    return [f"{_frames(len(negative))} arrived before they were sent by the stamps (by up to {early * 1e3:.3f} ms; "
            f"{why}): their delays are written as 0"]


def _frames(n: int) -> str:
    return f"{n} frame{'s' if n != 1 else ''}"


def _roles(frames: Sequence[Frame], own: set[Source]) -> tuple[set[Source], set[Source]]:
    """Of the sources ``own`` (those an end sent): the vehicles (a HEARTBEAT naming an autopilot, or ODOMETRY)
    and the offboard controllers (actuator targets)."""
    pilots, controllers = set(), set()
    for f in frames:
        if f.src not in own:
            continue
        if f.msgid == _HEARTBEAT and f.payload.ljust(6, b"\0")[5] != _AUTOPILOT_INVALID or f.msgid == _ODOMETRY:
            pilots.add(f.src)
        elif f.msgid in _TARGETS:
            controllers.add(f.src)
    return pilots, controllers


def _check_order(vehicle: Sequence[Frame], controller: Sequence[Frame], ends: dict[Source, str],
                 inputs: tuple[str, ...]) -> None:
    """Refuse the two tlogs given the wrong way round: the first (the vehicle's end) sent no vehicle's frames (an
    autopilot's HEARTBEAT, ODOMETRY) and no actuator targets, which the second sent. Each end is known by the
    sources it sent (their MAVLink ids, :func:`sender_ends`) and what they sent. A link neither says (two ground
    stations, say) is taken in the order given."""
    v_name, c_name = inputs if len(inputs) == 2 else ("the vehicle's tlog", "the controller's tlog")
    v_pilots, v_ctl = _roles(vehicle, {s for s, e in ends.items() if e == "a"})
    c_pilots, c_ctl = _roles(controller, {s for s, e in ends.items() if e == "b"})
    if (v_pilots or c_ctl) or not (c_pilots or v_ctl):
        return
    said = []
    if c_pilots:
        said.append(f"{c_name} looks like the vehicle's end ({_ids(c_pilots)} sent an autopilot's HEARTBEAT or "
                    f"ODOMETRY)")
    if v_ctl:
        said.append(f"{v_name} looks like the controller's end ({_ids(v_ctl)} sent actuator targets)")
    raise ConfigError.at(EXTRACT, None, f"the tlogs are given the wrong way round"
                         f"{' (both ends say so)' if c_pilots and v_ctl else ''}: {' and '.join(said)}; give the "
                         f"vehicle's tlog first: bsst link extract {c_name} {v_name}")


def _ids(sources: set[Source]) -> str:
    return ", ".join(f"{a}:{b}" for a, b in sorted(sources))


def _check_overlap(vehicle: Sequence[Frame], controller: Sequence[Frame], shift_c: float, names: str) -> None:
    """Refuse two tlogs whose stamps (the controller's shifted by ``shift_c`` s) never overlap in time."""
    v0, v1 = min(f.t for f in vehicle), max(f.t for f in vehicle)
    c0, c1 = min(f.t for f in controller) + shift_c, max(f.t for f in controller) + shift_c
    if v1 < c0 or c1 < v0:
        raise ConfigError(f"{names}: the vehicle's tlog spans {v0:.3f}..{v1:.3f} s, the controller's {c0:.3f}.."
                          f"{c1:.3f} s (Unix time{', TIMESYNC offset applied' if shift_c else ''}): they never "
                          f"overlap, so these are not the two ends of one link (or their clocks differ: "
                          f"--clock timesync)")


def _check_matched(up: DirectionRecords, down: DirectionRecords, names: str) -> None:
    """Refuse two tlogs where no frame, or in either direction fewer than half the frames received, match a
    frame the other end sent."""
    if not any(d.sent - d.lost for d in (up, down)):
        raise ConfigError(f"{names}: no frame was delivered either way (no frame one end received is one the "
                          f"other sent): not the two ends of one link")
    for name, d in (("up", up), ("down", down)):
        delivered = d.sent - d.lost
        if d.unmatched > delivered:
            raise ConfigError(f"{names}: {name}: {d.unmatched} of the {d.unmatched + delivered} frames received "
                              f"from the other end's sources are not in the other end's tlog: not the two ends of "
                              f"one link")


# -- a run directory -----------------------------------------------------------------------------------
def run_clock(path: Path) -> str | None:
    """The clock a run was flown on, from its summary.json (None: no readable summary)."""
    try:
        return json.loads((path / "summary.json").read_text()).get("clock")
    except (OSError, ValueError, AttributeError):
        return None


def check_run_dir(path: str | Path) -> Path:
    """``path`` as a directory to extract a run's link from; a ``ConfigError`` saying what it is otherwise."""
    p = Path(path)
    give = "give a real-time run directory, or the vehicle's tlog and the controller's tlog"
    why = unreachable(p)
    if why:
        raise ConfigError.at(EXTRACT, None, f"{p}: cannot read ({why}); {give}")
    if p.is_dir():
        return p
    if not p.exists():
        why = "no such file or directory" if not p.is_symlink() else "a broken symbolic link"
    elif p.is_file():
        why = "one tlog (the other end's is missing)" if p.suffix.lower() == ".tlog" else "a file, not a run directory"
    else:
        why = "not a run directory"
    raise ConfigError.at(EXTRACT, None, f"{p}: {why}; {give}")


def extract_run_dir(path: str | Path, clock: str = "same") -> Extraction:
    """Both directions of a real-time run's link: from its tlogs, else from vehicle.bin and controller.bin."""
    p = check_run_dir(path)
    flown = run_clock(p)
    if flown in ("lockstep", "offline"):
        raise ConfigError(f"{p}: flown {'in lockstep' if flown == 'lockstep' else 'offline'}: its link model acted in "
                          f"simulation time{' after the sockets' if flown == 'lockstep' else ''}, so no file holds the "
                          f"link as packets met it (its [link] table is in mission.toml); extract a real-time run")
    v, c = p / "vehicle.tlog", p / "controller.tlog"
    if v.is_file() and c.is_file():
        return extract_tlogs(read_tlog(v), read_tlog(c), clock, run_dir=True, inputs=(str(v), str(c)))
    vh, ch = p / "vehicle.bin", p / "controller.bin"
    if vh.is_file() and ch.is_file():
        if clock != "same":
            raise ConfigError(f"--clock {clock}: {p} has no tlogs; its trace halves are on one host's monotonic "
                              f"clock")
        return extract_halves(vh, ch)
    fleet = fleet_vehicle_dirs(p)
    if fleet:  # a fleet's run (bsst sitl --vehicles N --realtime): a link per vehicle, each in its own directory
        raise ConfigError(f"{p}: a fleet's run directory: each vehicle's link is in its own ({', '.join(fleet)}); "
                          f"extract each, as bsst link extract {p / fleet[0]}")
    raise ConfigError(f"{p}: neither vehicle.tlog and controller.tlog nor vehicle.bin and controller.bin: "
                      f"no record of a link to extract")


def fleet_vehicle_dirs(path: Path) -> list[str]:
    """The ``vehicle-<id>`` directories of a fleet's run directory (docs/swarm.md, "The run directory"), by id; none
    in another directory."""
    found = [d.name for d in path.glob("vehicle-*") if d.is_dir() and d.name[len("vehicle-"):].isdigit()]
    return sorted(found, key=lambda name: int(name[len("vehicle-"):]))


def step_records(path: Path) -> tuple[DirectionRecords, DirectionRecords] | None:
    """A real-time run's per-step messages each way (the actuator targets up, ODOMETRY down), matched by their bytes
    in the run's two tlogs (both ends' stamps, one host's clock: what ``bsst link extract`` reads, of these messages
    only): per message its send time and one-way delay (s; None: lost), counted from the first to the last one both
    tlogs hold (a tlog cut short by a SIGKILL ends the count there). None without two readable tlogs."""
    try:  # the run's own files, not a user's input (read_tlog would note them as one)
        v, c = (parse_tlog((path / f"{side}.tlog").read_bytes(), side) for side in ("vehicle", "controller"))
    except (OSError, ConfigError):
        return None
    out = []
    for ids, sender, receiver in ((_TARGETS, c, v), ((_ODOMETRY,), v, c)):
        sent, recv = (by_source([f for f in log if f.msgid in ids]) for log in (sender, receiver))
        out.append(merge_directions(_step_records(sent[s], recv[s]) for s in sent.keys() & recv.keys()))
    return out[0], out[1]


def _step_records(sent: Sequence[Frame], recv: Sequence[Frame]) -> DirectionRecords:
    """One source's per-step messages as sent and as received, matched by their bytes (a step's stamp makes each
    one's own; a second arrival of one is a duplicate): from the first to the last sent that arrived, each one's
    delay, or None where it never did. Not from the gaps in the sequence numbers (:func:`direction_records`): the
    source's other messages share them (counted so, a killed vehicle's first second read 8 of 242 targets lost on
    loopback). ``reordered``: those whose first copy was received after one sent later (the receiver's tlog is in
    the order it read them; the link model's own count, :class:`bridge.link.impairment.LinkStats`)."""
    out = DirectionRecords(reordered=0)
    waiting: dict[bytes, list[int]] = {}
    for i, f in enumerate(sent):
        waiting.setdefault(f.raw, []).append(i)
    arrival: dict[int, float] = {}
    highest = -1  # the latest sent of those received so far
    for r in recv:
        left = waiting.get(r.raw)
        if not left:  # received twice, or sent after the sender's log ends (cut short)
            out.duplicates += r.raw in waiting
            out.outside += r.raw not in waiting
            continue
        i = left.pop(0)
        arrival[i] = r.t
        if i < highest:
            out.reordered += 1
        highest = max(highest, i)
    if arrival:
        out.records = [(f.t, arrival[i] - f.t if i in arrival else None)
                       for i, f in enumerate(sent) if min(arrival) <= i <= max(arrival)]
    return out


def step_delays(path: Path) -> tuple[list[float], list[float]] | None:
    """A real-time run's per-step messages delivered, each way (the actuator targets up, ODOMETRY down): the
    one-way delay (ms) of every one that arrived, whether a step used it or not (a late one, refused as older than
    the newest, was delivered all the same), from the run's two tlogs (:func:`step_records`). None without two
    readable tlogs."""
    both = step_records(path)
    if both is None:
        return None
    up, down = ([1e3 * x for _, x in d.records if x is not None] for d in both)
    return up, down


def _half_rows(path: Path, names: Sequence[str], optional: str) -> list[dict[str, float]]:
    """The half's records, each the named columns (and ``optional``, when the file has it)."""
    try:
        half = half_arrays(read_regular_file(path, "a trace half"), str(path))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    missing = [n for n in names if n not in half]
    if missing:
        raise ConfigError(f"{path}: no column {missing[0]!r} in its header")
    names = tuple(names) + ((optional,) if optional in half else ())
    columns = [half[n].tolist() for n in names]
    return [dict(zip(names, values, strict=True)) for values in zip(*columns, strict=True)]


def _arrivals(rows: Sequence[dict[str, float]], key: str, wall: str, count: str, sent: dict[int, float]
              ) -> tuple[dict[int, float], bool]:
    """When the reader took each step's state (command) off the link (monotonic s), from its records of the step
    it used (``key``, its ``wall`` time taken) and how many it took since its previous record (``count``): those
    beyond the one it used, superseded before it could use them, are the sent steps just below it, taken in the
    same read. Without ``count`` (a half from before it was recorded) a superseded step reads as lost: the second
    value is False then."""
    taken: dict[int, float] = {}
    counted = bool(rows) and count in rows[0]
    first_sent = min(sent, default=0)
    before = first_sent - 1  # the step the previous record used (none yet: just before the first sent)
    for r in rows:
        k = int(r[key])
        if k < 0 or k <= before:
            continue
        taken[k] = r[wall]
        extra = int(r[count]) - 1 if counted else 0
        j = k - 1
        while extra > 0 and j > before:
            if j in sent and j not in taken:
                taken[j] = r[wall]
                extra -= 1
            j -= 1
        before = k
    return taken, counted


def extract_halves(vehicle_half: Path, controller_half: Path) -> Extraction:
    """Both directions from each side's half of the trace (one host's monotonic clock). A state or command is
    known by its step k; one superseded within one of its reader's ticks (two arrived in one period) is known by
    the reader's count (``odo_arrived``, ``cmd_arrived``); a tick that reuses a state sends a command with the
    same k (the first counts)."""
    v = _half_rows(vehicle_half, ("k", "odo_sent_wall", "cmd_k", "cmd_recv_wall"), "cmd_arrived")
    c = _half_rows(controller_half, ("k", "odo_recv_wall", "cmd_sent_wall"), "odo_arrived")
    if not v or not c:
        raise ConfigError(f"{vehicle_half if not v else controller_half}: no records")
    state_sent = {int(r["k"]): r["odo_sent_wall"] for r in v}
    cmd_sent: dict[int, float] = {}
    for r in c:
        cmd_sent.setdefault(int(r["k"]), r["cmd_sent_wall"])
    state_recv, counted_down = _arrivals(c, "k", "odo_recv_wall", "odo_arrived", state_sent)
    cmd_recv, counted_up = _arrivals(v, "cmd_k", "cmd_recv_wall", "cmd_arrived", cmd_sent)
    k0, k1 = int(c[0]["k"]), max(state_recv)  # from the first state the controller used (before it: phase-lock)
    down = DirectionRecords([(state_sent[k], state_recv[k] - state_sent[k] if k in state_recv else None)
                             for k in sorted(state_sent) if k0 <= k <= k1])
    delivered = [k for k in cmd_sent if k in cmd_recv]
    last = max(delivered) if delivered else k0
    up = DirectionRecords([(cmd_sent[k], cmd_recv[k] - cmd_sent[k] if k in cmd_recv else None)
                           for k in sorted(cmd_sent) if k <= last and math.isfinite(cmd_sent[k])])
    origin = state_sent.get(k0, min(t for t, _ in down.records))
    for d in (up, down):
        d.records = [(t - origin, x) for t, x in d.records if t >= origin and math.isfinite(t)]
    note = "from vehicle.bin and controller.bin (no tlogs): by step number, on one host's monotonic clock"
    if not (counted_down and counted_up):
        note += ("; approximate: these halves do not count what their reader took, so a state or command "
                 "superseded within one of its reader's ticks counts as lost")
    return Extraction(up, down, "the flight's time 0 (the first state the controller answered left the vehicle)",
                      "same", 0.0, None, (str(vehicle_half), str(controller_half)), [note])


# -- the trace file -------------------------------------------------------------------------------------
def extraction_rows(ex: Extraction) -> list[tuple[float, float | None, str]]:
    """(t_s, delay_ms or None, direction) rows, in time order, t_s rounded to us and strictly increasing
    per direction (two frames stamped alike are 1 us apart), delays to us."""
    rows = []
    for d, part in (("up", ex.up), ("down", ex.down)):
        last = -math.inf
        for t, x in part.records:
            t = round(max(t, last + 1e-6), 6)
            last = t
            rows.append((t, None if x is None else round(x * 1000.0, 3), d))
    rows.sort(key=lambda r: (r[0], r[2]))
    return rows


def extraction_text(ex: Extraction) -> str:
    """The trace file of an extraction, with where it came from as comments."""
    comments = [f"bsst link extract {' '.join(ex.inputs)}",
                f"t_s = 0 at {ex.origin}; clock {ex.clock}"
                + (f" (controller stamps {ex.offset_s * 1e3:+.3f} ms)" if ex.clock == "timesync" else ""),
                "one row per frame: delay_ms = one-way delay, empty = lost; up = controller -> vehicle"]
    comments += ex.notes
    return trace_text(extraction_rows(ex), comments)
