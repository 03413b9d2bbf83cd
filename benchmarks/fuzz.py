"""Fuzz (issue 7): ``--datagrams`` (10^6) hostile datagrams into the vehicle's controller link
during a lockstep mission, against an undisturbed run of the same mission and seed.

The datagrams (:class:`tests.hostile.Fuzzer`, seeded): random bytes, truncated and bit-flipped
valid frames, valid targets from other systems, commands for other systems, unknown message
ids, NaN/inf and out-of-range targets with the controller's ids, stale and future targets,
MAVLink 1 frames, empty and 64 KiB datagrams; sent from ``--sources`` addresses, paced on the
vehicle's socket queue so the kernel drops nothing. Prints what was sent by kind, what the
vehicle refused by reason, whether the refusals add up to what was sent, whether the trace is
the undisturbed one byte for byte, the burst's rate and the vehicle's CPU time per datagram.

Then (issue 11) ``--commands`` (10^5) valid MAVLink 2 frames of every message id of the common
dialect (:class:`CommandFuzzer`: pymavlink-encoded, every field random or extreme) during a
lockstep missions/sine.toml: from strangers (random ids, ``--sources`` addresses) to the
controller link, and from the ground station (255:190) to the GCS link, never a valid
ARM_DISARM. Prints whether the trace is the undisturbed one byte for byte, whether the
refusals add up (every stranger's frame refused; every GCS frame the vehicle handles refused
or answered) and the safety policies' verdicts (``summary.json["policies"]``). Either mode
is skipped with 0.

    .venv/bin/python benchmarks/fuzz.py [--datagrams 1000000] [--rate 40000] [--duration 120] [--speed 2]
        [--commands 100000] [--command-rate 8000] [--command-speed 1] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from bridge.autopilot.params import BY_NAME, ParamRefused, VehicleParams, change_param  # noqa: E402
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT  # noqa: E402
from bridge.mavlink.ftp import is_request as ftp_request  # noqa: E402
from bridge.mavlink.modes import (  # noqa: E402
    PARAM_TYPES,
    param_from_wire,
    param_name,
    requested_custom_mode,
    requested_mode,
)
from bridge.mavlink.receive import addressed_elsewhere  # noqa: E402
from bridge.nodes.vehicle.mission import MESSAGES as MISSION_MESSAGES  # noqa: E402
from bridge.nodes.vehicle.mission import MISSIONPLANNER  # noqa: E402
from bridge.record.halves import count_records  # noqa: E402
from bridge.session import sitl  # noqa: E402
from missions import MISSION_DIR, Mission, Sine, load_mission  # noqa: E402
from tests.hostile import MIN_STEP, Sender, Station, fly_fuzzed, session_thread, udp_queue  # noqa: E402
from tests.waiting import wait_for  # noqa: E402

# -- the command surface (issue 11): valid frames of every message id, from strangers and a GCS ------
F32_MAX = 3.4028234663852886e38
F64_MAX = sys.float_info.max
FLOAT_EXTREMES = (math.nan, math.inf, -math.inf, 0.0, -0.0, F32_MAX, -F32_MAX, 1.4e-45, 1.0, -1.0)
DOUBLE_EXTREMES = (math.nan, math.inf, -math.inf, 0.0, -0.0, F64_MAX, -F64_MAX, 5e-324, 1.0, -1.0)
INT_RANGES = {"int8_t": (-2**7, 2**7 - 1), "uint8_t": (0, 2**8 - 1), "int16_t": (-2**15, 2**15 - 1),
              "uint16_t": (0, 2**16 - 1), "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1),
              "int64_t": (-2**63, 2**63 - 1), "uint64_t": (0, 2**64 - 1)}
M = mavlink
ARM = M.MAV_CMD_COMPONENT_ARM_DISARM
COMMANDS = (ARM, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_MESSAGE,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_DO_SET_MODE,
            M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
PARAM1 = (0.0, 1.0, float(M.MAVLINK_MSG_ID_ATTITUDE), float(M.MAVLINK_MSG_ID_HOME_POSITION),
          float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION), 0.5, 2.0**24, -1.0, *FLOAT_EXTREMES[:3])
PARAM2 = (-1.0, 0.0, 1e4, 1e6, 21196.0, 1e12, -5.0, *FLOAT_EXTREMES[:3])
# what the vehicle handles from a ground station: each such frame is refused (counted) or answered
# (the mission protocol's other messages: withheld, see mission_reaching)
GCS_HANDLED = ("COMMAND_LONG", "COMMAND_INT", "HIL_ACTUATOR_CONTROLS", "SET_ACTUATOR_CONTROL_TARGET", "SET_MODE",
               "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET", *sorted(MISSION_MESSAGES))
# a datagram holding one is the answer to one frame
ANSWERS = ("COMMAND_ACK", "TIMESYNC", "MISSION_COUNT", "MISSION_ACK", "PARAM_VALUE", "FILE_TRANSFER_PROTOCOL")
# refusals that are answered too (a DENIED COMMAND_ACK, the unchanged PARAM_VALUE): counted once in the sum
ANSWERED_REFUSALS = ("bad_number", "param_refused")
MODE_COMMANDS = (M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
GCS_IDS = (255, 190)


def flight_changing(m: Any, sysid: int) -> bool:
    """Whether ``m``, from a ground station, is a valid command that changes the flight: an
    ARM_DISARM for this vehicle with param1 exactly 0 or 1 (docs/design.md, "Authority"). The
    GCS stream never sends one, so that the trace must stay the undisturbed run's."""
    return (m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command == ARM and m.param1 in (0.0, 1.0)
            and m.target_system in (0, sysid) and m.target_component in (0, 1))


def mode_or_param_changing(m: Any, sysid: int) -> bool:
    """Whether ``m``, from a ground station, for this vehicle, would change its mode (DO_SET_MODE of a
    mode it flies, NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH, SET_MODE) or a parameter (a valid PARAM_SET):
    withheld too, by addressing it to another system (refused as ``target``), so that the trace stays the same."""
    kind = m.get_type()
    if getattr(m, "target_system", -1) not in (0, sysid) or getattr(m, "target_component", 0) not in (0, 1):
        return False
    if kind in ("COMMAND_LONG", "COMMAND_INT"):
        if m.command == M.MAV_CMD_DO_SET_MODE:
            return requested_mode(m.param1, m.param2, m.param3)[0] is not None
        return m.command in MODE_COMMANDS
    if kind == "SET_MODE":
        return requested_custom_mode(m.base_mode, m.custom_mode)[0] is not None
    if kind == "PARAM_SET":
        name = param_name(m)
        spec = BY_NAME.get(name)
        if spec is None or m.param_type != PARAM_TYPES[spec.kind]:
            return False
        try:
            change_param(VehicleParams(), name, param_from_wire(m.param_value, m.param_type))
        except ParamRefused:
            return False
        return True
    return False


def mission_reaching(m: Any, sysid: int) -> bool:
    """Whether ``m``, from a ground station, is a mission-protocol message for this vehicle other than
    MISSION_REQUEST_LIST (which is always answered: MISSION_COUNT, or MISSION_ACK): withheld too, by
    addressing it to another system (refused as ``target``). The protocol ignores some of them by design
    (a MISSION_ACK, a request with no transfer, an item out of sequence, as PX4 does) and an upload it
    starts sends requests unasked, so the frame-by-frame count of answers holds only without them; the
    protocol's own hostile cases are tests/test_mission_protocol.py's."""
    if m.get_type() not in MISSION_MESSAGES or m.get_type() == "MISSION_REQUEST_LIST":
        return False
    return not addressed_elsewhere(m, sysid, 1) or (m.target_system == sysid and m.target_component == MISSIONPLANNER)


class CommandFuzzer:
    """Seeded valid MAVLink 2 frames (pymavlink-encoded, good CRC) for a vehicle of system
    ``sysid``: frame i is, for even i, the next message class of the common dialect in id
    order (every id in turn), for odd i a message the vehicle handles aimed at it (a command
    it knows, a TIMESYNC request, a MISSION_REQUEST_LIST, an actuator target); every field
    random or extreme (NaN, +-inf, 0, the type's max and min), char arrays random bytes,
    arrays of their length. :attr:`sent` counts by message type; :attr:`withheld` the GCS's
    valid ARM_DISARMs whose param1 was made NaN instead (:func:`flight_changing`)."""

    def __init__(self, seed: int, sysid: int) -> None:
        self.rng = random.Random(seed)
        self.sysid = sysid
        self.classes = sorted(M.mavlink_map.values(), key=lambda c: c.id)
        self.mav = M.MAVLink(None)
        self.sent: Counter[str] = Counter()
        self.withheld = 0
        self.handled = 0  # GCS frames of a kind the vehicle handles (see GCS_HANDLED)

    def value(self, ftype: str) -> Any:
        r = self.rng
        if ftype in ("float", "double"):
            extremes = FLOAT_EXTREMES if ftype == "float" else DOUBLE_EXTREMES
            return r.choice(extremes) if r.random() < 0.5 else r.uniform(-1e6, 1e6)
        lo, hi = INT_RANGES[ftype]
        return r.choice((lo, hi, 0, 1)) if r.random() < 0.5 else r.randint(lo, hi)

    def message(self, cls: Any, aimed: bool) -> Any:
        r = self.rng
        focus = {"target_system": (0, self.sysid, self.sysid, r.randrange(256)),
                 "target_component": (0, 1, 1, r.randrange(256)), "command": COMMANDS,
                 "param1": PARAM1, "param2": PARAM2, "tc1": (0,), "group_mlx": (0, 0, 1)} if aimed else {}
        args: list[Any] = []
        for i, (name, ftype) in enumerate(zip(cls.fieldnames, cls.fieldtypes, strict=True)):
            n = cls.array_lengths[cls.orders[i]]
            if ftype == "char":
                args.append(r.randbytes(max(n, 1)))
            elif n:
                args.append([self.value(ftype) for _ in range(n)])
            elif name in focus and r.random() < 0.8:
                args.append(r.choice(focus[name]))
            else:
                args.append(self.value(ftype))
        return cls(*args)

    def make(self, i: int, src: tuple[int, int], gcs: bool = False) -> bytes:
        """Frame i (see the class) from ``src`` (sysid, compid); ``gcs``: for the GCS link."""
        aimed = i % 2 == 1
        cls = self.rng.choice([M.MAVLink_command_long_message, M.MAVLink_command_int_message,
                               M.MAVLink_command_long_message, M.MAVLink_command_int_message,
                               M.MAVLink_timesync_message, M.MAVLink_mission_request_list_message,
                               M.MAVLink_set_actuator_control_target_message,
                               M.MAVLink_hil_actuator_controls_message]) if aimed \
            else self.classes[(i // 2) % len(self.classes)]
        m = self.message(cls, aimed)
        if gcs and flight_changing(m, self.sysid):
            m.param1 = math.nan
            self.withheld += 1
        elif gcs and (mode_or_param_changing(m, self.sysid) or mission_reaching(m, self.sysid)):
            m.target_system = self.sysid % 250 + 1  # another vehicle's: refused as target
            self.withheld += 1
        kind = m.get_type()
        if gcs and (kind in GCS_HANDLED or (kind == "TIMESYNC" and m.tc1 == 0) or (
                kind == "FILE_TRANSFER_PROTOCOL" and (addressed_elsewhere(m, self.sysid, 1)
                                                      or ftp_request(bytes(m.payload))))):
            self.handled += 1
        self.sent[kind] += 1
        mav = self.mav
        mav.srcSystem, mav.srcComponent = src
        buf = bytes(m.pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
        return buf

    def stranger_ids(self) -> tuple[int, int]:
        """Another system or component than the controller's, or (one in eight) its ids, which
        from another address than its flight's are a stranger's."""
        r = self.rng
        if r.random() < 0.125:
            return CONTROLLER_SYSID, CONTROLLER_COMPID
        while (ids := (r.randrange(256), r.randrange(256))) == (CONTROLLER_SYSID, CONTROLLER_COMPID):
            pass
        return ids


@dataclass
class CommandFuzzed:
    """What :func:`fly_commands` saw: the run, the fuzzer, the frames sent to each link, the
    answers the ground stations got (datagrams holding one of :data:`ANSWERS`), the kernel's
    drops on the vehicle's two sockets, the steps flown when the last frame had been read and
    the burst's wall time."""

    run: Any
    fuzz: CommandFuzzer
    to_controller_link: int
    to_gcs_link: int
    answers: int
    drops: int
    flown: int
    elapsed_s: float


def _to_gcs_link(gcs: Station, frames: list[bytes], rate_hz: float, timeout: float = 120.0) -> None:
    """Send ``frames`` from the ground station ``gcs`` (one frame a datagram) at ``rate_hz`` at
    most on a drift-free schedule, taking what comes back as it goes (so none of it is lost)."""
    t0 = time.monotonic()
    for i, frame in enumerate(frames):
        due = t0 + i / rate_hz
        if time.monotonic() < due:
            gcs.poll()
            wait_for(lambda due=due: time.monotonic() >= due, timeout, "the GCS schedule", poll_s=0.0005)
        gcs.send_raw(frame)
    gcs.poll()


def answers(gcs: Station) -> int:
    """The answers ``gcs`` got: one datagram (led by one of :data:`ANSWERS`) per frame answered (a
    parameter list is one datagram of PARAM_VALUEs)."""
    return sum(gcs.first[kind] for kind in ANSWERS)


def fly_commands(mission: Mission, out: Path, frames: int, seed: int = 11, sources: int = 64, speed: float = 1.0,
                 rate_hz: float = 8000.0, gcs_rate_hz: float = 900.0) -> CommandFuzzed:
    """Fly ``mission`` lockstep into ``out`` while ``frames`` frames of :class:`CommandFuzzer`
    go, once it is past step :data:`tests.hostile.MIN_STEP`, for frames / ``rate_hz`` seconds:
    from the ground station (255:190, on the GCS port: the GCS link hears no other address) to
    the vehicle's GCS link at ``gcs_rate_hz`` (under its 1000 frames/s budget), and the rest
    from strangers (random ids, ``sources`` addresses) to its controller link."""
    with session_thread(mission, out, speed=speed) as (n, th, result):
        gcs = Station(GCS_IDS, port=GCS_PORT + n)  # where the vehicle's GCS link sends: learns its address
        to_link = Sender(LINK_PORT + n, sources=sources, rate_hz=rate_hz - gcs_rate_hz)
        try:
            fuzz = CommandFuzzer(seed, n + 1)
            ground = round(frames * gcs_rate_hz / rate_hz)
            grounded = [fuzz.make(i, GCS_IDS, gcs=True) for i in range(ground)]
            strange = [fuzz.make(i, fuzz.stranger_ids()) for i in range(frames - ground)]
            vhalf = out / "vehicle.bin"
            wait_for(lambda: count_records(vhalf) > MIN_STEP or not th.is_alive(), 60, "the flight starting")
            gcs.wait(lambda m: True, 10, "a datagram on the GCS link")
            failed: list[BaseException] = []

            def strangers() -> None:
                try:
                    to_link.send(strange)
                except BaseException as exc:  # re-raised below, in the caller's thread
                    failed.append(exc)

            t0 = time.monotonic()
            other = threading.Thread(target=strangers)
            other.start()
            _to_gcs_link(gcs, grounded, gcs_rate_hz)
            other.join()
            if failed:
                raise failed[0]
            gcs_port = gcs.dest[1]
            if udp_queue(gcs_port) is None:
                raise AssertionError(f"the vehicle's GCS socket 127.0.0.1:{gcs_port} is not in /proc/net/udp")
            wait_for(lambda: (udp_queue(gcs_port) or (0, 0))[0] == 0, 30, "the vehicle draining its GCS socket",
                     poll_s=0.001)
            drops = to_link.drained(timeout=120) + (udp_queue(gcs_port) or (0, 0))[1]
            elapsed = time.monotonic() - t0
            flown = count_records(vhalf)
            # the last answers: the vehicle answers a frame in the housekeeping tick that read it (ms)
            quiet = t0 + elapsed + 0.2

            def settled() -> bool:
                gcs.poll()
                return time.monotonic() > quiet

            wait_for(settled, 10, "the last answers", poll_s=0.001)
            got = answers(gcs)
        finally:
            to_link.close()
            gcs.close()
    return CommandFuzzed(result["run"], fuzz, to_link.sent, len(grounded), got, drops, flown, elapsed)


def command_checks(f: CommandFuzzed, ref_trace: Path, steps: int) -> dict[str, Any]:
    """The three checks of a command-surface run of ``steps`` steps against the undisturbed
    run's ``ref_trace``: the trace byte for byte; the refusals (of others than the controller)
    add up: every stranger's frame refused, every GCS frame of a kind the vehicle handles
    refused or answered (a ``bad_number`` is both: DENIED), the rest ignored; no safety policy
    violated."""
    s = f.run.summary
    link = s["link"]
    by = link["rejected_by"]["vehicle"]
    refused = sum(by.values()) - link["rejected_from_peer"]["vehicle"]
    due = f.to_controller_link + f.fuzz.handled
    policies = s.get("policies") or []
    return {
        "trace_identical": (Path(f.run.path) / "trace.csv").read_bytes() == ref_trace.read_bytes(),
        "refused": refused, "refused_by_reason": dict(sorted(by.items(), key=lambda kv: -kv[1])),
        "answered": f.answers, "bad_number": by.get("bad_number", 0), "due": due,
        "ignored": f.to_gcs_link - f.fuzz.handled,
        "adds_up": refused + f.answers - sum(by.get(r, 0) for r in ANSWERED_REFUSALS) == due and f.drops == 0,
        "policies_checked": len(policies), "policies_violated": [p["name"] for p in policies if not p.get("ok")],
        "withheld_arm_disarm": f.fuzz.withheld, "outcome": s["outcome"], "kernel_drops": f.drops,
        "done_before_mission_end": f.flown < steps, "controller_refused": link["rejected_by"]["controller"],
    }


def datagram_fuzz(args: argparse.Namespace) -> tuple[dict[str, Any], bool]:
    """The ``--datagrams`` mode (issue 7): its figures and whether every check held."""
    mission = Mission(Sine(), duration_s=args.duration, name="fuzz")
    with tempfile.TemporaryDirectory(prefix="bsst-fuzz-") as tmp:
        sitl(mission, out=Path(tmp) / "ref", plots=False, instance=None)  # the undisturbed run
        f = fly_fuzzed(mission, Path(tmp) / "fuzz", args.datagrams, seed=args.seed, sources=args.sources,
                       speed=args.speed, rate_hz=args.rate)
        same = (Path(tmp) / "fuzz" / "trace.csv").read_bytes() == (Path(tmp) / "ref" / "trace.csv").read_bytes()
    s = f.run.summary
    link = s["link"]
    by = link["rejected_by"]["vehicle"]
    others = sum(by.values()) - link["rejected_from_peer"]["vehicle"]
    short = {r: n - by.get(r, 0) for r, n in f.fuzz.expected().items() if by.get(r, 0) < n}
    res = {
        "load_1min": os.getloadavg()[0], "datagrams": f.sent, "sent_by_kind": dict(f.fuzz.sent),
        "refused_by_reason": dict(sorted(by.items(), key=lambda kv: -kv[1])), "refused_from_others": others,
        "adds_up": others == f.sent and f.drops == 0 and not short, "kernel_drops": f.drops,
        "trace_identical": same, "outcome": s["outcome"], "died": s["sitl"]["died"],
        "exits": [s["sitl"]["vehicle_exit"], s["sitl"]["controller_exit"]],
        "fuzz_done_before_mission_end": f.flown < mission.steps, "burst_s": f.elapsed_s,
        "datagrams_per_s": f.sent / f.elapsed_s, "vehicle_cpu_us_per_datagram": 1e6 * f.vehicle_cpu_s / f.sent,
        "statustexts": len([t for t in f.texts if t.startswith("rejected ")]), "controller_refused": link[
            "rejected_by"]["controller"],
    }
    if not args.json:
        print(f"{f.sent} hostile datagrams from {args.sources} sources in {f.elapsed_s:.1f} s "
              f"({res['datagrams_per_s']:.0f}/s) during a lockstep {args.duration:g} s sine; "
              f"load {res['load_1min']:.2f}")
        print("sent by kind: " + ", ".join(f"{k} {v}" for k, v in sorted(f.fuzz.sent.items(), key=lambda kv: -kv[1])))
        print("vehicle refused: " + ", ".join(f"{k} {v}" for k, v in res["refused_by_reason"].items()))
        print(f"refusals of others' datagrams {others} = sent {f.sent}: {others == f.sent}; kernel drops {f.drops}; "
              f"each kind's least count met: {not short}{'' if not short else ' ' + str(short)}")
        print(f"trace.csv identical to the undisturbed run: {same}; outcome {s['outcome']}; vehicle "
              f"{s['sitl']['vehicle_exit']}, controller {s['sitl']['controller_exit']}; controller refused "
              f"{res['controller_refused']}")
        print(f"vehicle CPU {res['vehicle_cpu_us_per_datagram']:.1f} us per datagram (its flight included); "
              f"{res['statustexts']} STATUSTEXT reports of refusals")
    ok = res["adds_up"] and same and s["outcome"] == "completed" and res["fuzz_done_before_mission_end"]
    return res, ok


def command_fuzz(args: argparse.Namespace) -> tuple[dict[str, Any], bool]:
    """The ``--commands`` mode (issue 11) on missions/sine.toml: its figures and whether every check held."""
    mission = load_mission(MISSION_DIR / "sine.toml")
    with tempfile.TemporaryDirectory(prefix="bsst-cmdfuzz-") as tmp:
        sitl(mission, out=Path(tmp) / "ref", plots=False, instance=None)  # the undisturbed run
        f = fly_commands(mission, Path(tmp) / "cmd", args.commands, seed=args.seed, sources=args.sources,
                         speed=args.command_speed, rate_hz=args.command_rate)
        res = command_checks(f, Path(tmp) / "ref" / "trace.csv", mission.steps)
    sent = f.to_controller_link + f.to_gcs_link
    res.update({"load_1min": os.getloadavg()[0], "frames": sent, "to_controller_link": f.to_controller_link,
                "to_gcs_link": f.to_gcs_link, "message_ids": len(f.fuzz.sent), "burst_s": f.elapsed_s,
                "frames_per_s": sent / f.elapsed_s})
    if not args.json:
        print(f"{sent} valid frames of {res['message_ids']} message ids in {f.elapsed_s:.1f} s "
              f"({res['frames_per_s']:.0f}/s): {f.to_controller_link} from strangers to the controller link, "
              f"{f.to_gcs_link} from the ground station (255:190) to the GCS link, during lockstep "
              f"{mission.name}.toml; "
              f"load {res['load_1min']:.2f}")
        print("vehicle refused: " + ", ".join(f"{k} {v}" for k, v in res["refused_by_reason"].items()))
        print(f"refused {res['refused']} + answered {res['answered']} - DENIED bad numbers {res['bad_number']} "
              f"= {res['refused'] + res['answered'] - res['bad_number']}; due {res['due']} (every stranger's frame, "
              f"every GCS frame the vehicle handles; {res['ignored']} others ignored): {res['adds_up']}; "
              f"kernel drops {f.drops}")
        print(f"trace.csv identical to the undisturbed run: {res['trace_identical']} (the GCS's "
              f"{res['withheld_arm_disarm']} valid ARM_DISARMs sent with param1 NaN instead); outcome "
              f"{res['outcome']}; controller refused {res['controller_refused']}")
        print(f"policies: {res['policies_checked']} checked, violated: {res['policies_violated'] or 'none'}")
    ok = (res["adds_up"] and res["trace_identical"] and not res["policies_violated"] and res["policies_checked"] > 0
          and res["outcome"] == "completed" and res["done_before_mission_end"])
    return res, ok


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--datagrams", type=int, default=1_000_000, help="hostile datagrams (0: skip this mode)")
    ap.add_argument("--commands", type=int, default=100_000,
                    help="valid frames of every message id from strangers and a GCS (0: skip this mode)")
    ap.add_argument("--duration", type=float, default=120.0, help="s of the sine mission flown (--datagrams)")
    ap.add_argument("--speed", type=float, default=2.0, help="lockstep at most this many times real time")
    ap.add_argument("--sources", type=int, default=128)
    ap.add_argument("--rate", type=float, default=40000.0,
                    help="datagrams/s at most: under the vehicle's limits for others (bridge.mavlink.receive), so that "
                         "every datagram is parsed and its reason counted")
    ap.add_argument("--command-rate", type=float, default=8000.0,
                    help="frames/s at most of --commands, both links together (900/s of them to the GCS link)")
    ap.add_argument("--command-speed", type=float, default=1.0, help="lockstep speed of --commands' sine.toml")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out: dict[str, Any] = {}
    ok = True
    for name, n, mode in (("datagrams", args.datagrams, datagram_fuzz), ("commands", args.commands, command_fuzz)):
        if n > 0:
            out[name], held = mode(args)
            ok = ok and held
    if args.json:
        print(json.dumps(out, indent=2))
    return 0 if ok else 1

if __name__ == "__main__":
    sys.exit(main())
