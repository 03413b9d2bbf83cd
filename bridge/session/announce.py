"""What ``bsst sitl`` tells a person on stderr once a vehicle is up: where a ground station connects.

In:  the vehicle's :class:`~bridge.nodes.report.Ready` (``gcs``: the HOST:PORT of its ground-station link, or
     None, and ``gcs_mode``: whether it sends there or is bound there; ``sysid``), whether it waits for a ground
     station's mission (``--await-mission``), and the pace it will fly that at (real time, or lockstep at X times
     real time, or as fast as it goes)
Out: :func:`vehicle_up_line`: one line of text (no newline), what :class:`~bridge.session.session.Session`
     writes on stderr with ``announce``

As PX4 SITL says at its start where each MAVLink instance talks (``INFO [mavlink] mode: Normal, data rate:
4000000 B/s on udp port 18570 remote port 14550``: ``Mavlink::task_main`` in PX4-Autopilot's
src/modules/mavlink/mavlink_main.cpp): without it a ``bsst sitl --await-mission`` waited silently, with no word of
the port a ground station listens on. By default the vehicle sends its ground-station telemetry to that address
(it is ``udpout``), so the ground station listens there (``udpin``); given ``--gcs udpin:`` (or ``udp:``) the
vehicle is bound there, so the ground station sends to it (``udpout``); with no GCS link it says so.
"""

from __future__ import annotations

from bridge.mavlink.address import GCS_PORT
from bridge.nodes.report import Ready

PREFIX = "bsst sitl: "


def _listen_hints(hostport: str) -> str:
    """How the usual ground stations listen on ``hostport`` (HOST:PORT), for the line."""
    host, _, port = hostport.rpartition(":")
    local = host.startswith("127.") or host == "localhost"
    qgc = "QGroundControl listens there by default; " if local and port == str(GCS_PORT) else ""
    return (f"{qgc}mavproxy.py --master=udpin:{host if local else '0.0.0.0'}:{port}; "
            f"MAVSDK udpin://0.0.0.0:{port}")


def _send_hints(hostport: str) -> str:
    """How the usual ground stations send to a vehicle bound on ``hostport`` (HOST:PORT; a wildcard host is
    reached on 127.0.0.1), for the line."""
    host, _, port = hostport.rpartition(":")
    host = "127.0.0.1" if host in ("0.0.0.0", "") else host
    return f"mavproxy.py --master=udpout:{host}:{port}; MAVSDK udpout://{host}:{port}"


def pace_words(realtime: bool, speed: float | None) -> str:
    """How a started mission flies: on the wall clock, or lockstep at ``speed`` (x real time; None: as fast as it
    goes), with the flag that changes it."""
    if realtime:
        return "on the wall clock (--realtime)"
    if speed is None:
        return "as fast as it goes (--speed 0; --speed X: at most X times real time)"
    return f"in lockstep at {speed:g}x real time (--speed X: X times; 0: as fast as it goes)"


SIGNED = ("; every frame signed (--key): a ground station signs with the same key, or the vehicle refuses what it "
          "sends (docs/sitl.md, Signing)")


def vehicle_up_line(ready: Ready, await_mission: bool, realtime: bool = False, speed: float | None = None,
                    signed: bool = False) -> str:
    """The line (no newline) saying that the vehicle ``ready`` describes is up, where a ground station connects
    (the address its ground-station link sends to, its system id), with ``signed`` that it must sign
    (:data:`SIGNED`: a ground station that does not sees the telemetry and has every message refused) and, with
    ``await_mission``, that the session waits, with no time limit, for a ground station's mission, and the pace it
    will fly it at (:func:`pace_words`)."""
    who = f"vehicle up, sysid {ready.sysid}"
    if ready.gcs is None:
        return f"{PREFIX}{who}: no ground-station link"
    if ready.gcs_mode == "udpin":  # --gcs udpin: / udp:: the vehicle is bound there and answers who sends first
        line = (f"{PREFIX}{who}: a ground station connects by sending to UDP {ready.gcs}, where the vehicle "
                f"listens and answers with its telemetry ({_send_hints(ready.gcs)})")
    else:
        line = (f"{PREFIX}{who}: a ground station connects by listening on UDP {ready.gcs}, where the vehicle "
                f"sends its telemetry ({_listen_hints(ready.gcs)})")
    if signed:
        line += SIGNED
    if await_mission:
        line += ("; waiting, with no time limit (Ctrl-C stops), for a ground station to upload a mission and "
                 f"start it: MISSION_START, or AUTO.MISSION and arm; it flies {pace_words(realtime, speed)}")
    return line
