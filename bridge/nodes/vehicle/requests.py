"""Requests for messages and their rates, on the sender's link's streams, as PX4's MAVLink receiver answers them.

In:  COMMAND_LONG / COMMAND_INT from a sender with authority (:class:`~bridge.autopilot.vehicleevents.Sender`):
     SET_MESSAGE_INTERVAL (param1 message id, param2 us: -1 off, 0 the default), GET_MESSAGE_INTERVAL and
     REQUEST_MESSAGE (param1 message id), REQUEST_AUTOPILOT_CAPABILITIES, GET_HOME_POSITION; each link's stream
     table (:class:`~bridge.nodes.vehicle.streams.StreamTable`, intervals s)
Out: the MAV_RESULT and the messages asked for (MESSAGE_INTERVAL us, the message requested, AUTOPILOT_VERSION,
     HOME_POSITION), sent after the COMMAND_ACK by the commander (:mod:`.commander`); an ``interval`` event when a
     link's rate changes; a bad number counted (``bad_number``), DENIED, nothing done; a message the vehicle cannot
     send, DENIED (REQUEST_MESSAGE), or stream, FAILED (SET_MESSAGE_INTERVAL), as PX4's receiver answers them. A
     link's requests change its own streams; the controller's messages are in the mission's frame, a ground
     station's in its own.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import SimVehicle
from bridge.autopilot.vehicleevents import Sender
from bridge.mavlink import telemetry as tm
from bridge.mavlink.receive import interval_arg, message_id_arg
from bridge.nodes.vehicle.actions import PROTOCOL_VERSION, ProtocolVersion
from bridge.nodes.vehicle.streams import HEARTBEAT_S, StreamTable

_STREAM_COMMANDS = (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
                    mavlink.MAV_CMD_REQUEST_MESSAGE)
Result = tuple[int, tuple[Any, ...]]  # (MAV_RESULT, the messages a command asked for)


class MessageRequests:
    """The commands that ask for messages or set their rates, for one vehicle."""

    def __init__(self, sim: SimVehicle, streams: dict[str, StreamTable], sysid: int,
                 message: Callable[[int, bool], list[Any]], reject: Callable[[str], None]) -> None:
        self.sim = sim
        self.streams = streams  # link (controller, gcs) -> its stream table
        self.sysid = sysid
        self.message = message  # the message(s) of an id as a stream sends them (own: a GCS's frame)
        self.reject = reject  # count a refusal (bridge.mavlink.receive.Rejections)

    def run(self, m: Any, by: Sender) -> Result | None:
        """Answer a request (MAV_RESULT, the messages it asked for); None: not one of these commands."""
        cmd = m.command
        if cmd in _STREAM_COMMANDS:
            return self._stream_command(m, by)
        if cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return mavlink.MAV_RESULT_ACCEPTED, (tm.autopilot_version(self.sysid),)
        if cmd == mavlink.MAV_CMD_GET_HOME_POSITION:
            return mavlink.MAV_RESULT_ACCEPTED, tuple(self.message(mavlink.MAVLINK_MSG_ID_HOME_POSITION,
                                                                   by.link != "controller"))
        return None

    def _stream_command(self, m: Any, by: Sender) -> Result:
        """SET_MESSAGE_INTERVAL, GET_MESSAGE_INTERVAL, REQUEST_MESSAGE on the sender's link's streams."""
        cmd = m.command
        mid = message_id_arg(m.param1)
        interval = interval_arg(m.param2) if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL else 0.0
        if mid is None or interval is None:
            self.reject("bad_number")
            return mavlink.MAV_RESULT_DENIED, ()
        table = self.streams[by.link]
        if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(table, mid, interval, by), ()
        if cmd == mavlink.MAV_CMD_GET_MESSAGE_INTERVAL:
            if mid > 0xFFFF:  # MESSAGE_INTERVAL's message_id has 16 bits
                return mavlink.MAV_RESULT_UNSUPPORTED, ()
            iv = table.get(mid, HEARTBEAT_S if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT else 0.0)
            return mavlink.MAV_RESULT_ACCEPTED, (
                mavlink.MAVLink_message_interval_message(mid, int(iv * 1e6) if iv > 0 else -1),)
        if mid == ProtocolVersion.id:  # no stream: answered as REQUEST_PROTOCOL_VERSION is (PX4's receiver)
            return mavlink.MAV_RESULT_ACCEPTED, (ProtocolVersion(*PROTOCOL_VERSION),)
        follow = tuple(self.message(mid, by.link != "controller"))  # the controller's: the mission's frame
        # none to send: DENIED, as PX4's handle_request_message_command answers a message it cannot send
        return (mavlink.MAV_RESULT_ACCEPTED if follow else mavlink.MAV_RESULT_DENIED), follow

    def _set_interval(self, table: StreamTable, mid: int, interval_us: float, by: Sender) -> int:
        """A checked SET_MESSAGE_INTERVAL on one link's streams; a change is an event."""
        if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            return mavlink.MAV_RESULT_ACCEPTED if interval_us in (0, HEARTBEAT_S * 1e6) else mavlink.MAV_RESULT_DENIED
        if mid not in table:  # no such stream: FAILED, as PX4's set_message_interval answers one it cannot make
            return mavlink.MAV_RESULT_FAILED
        iv = table.set(mid, interval_us, time.monotonic())
        if iv is not None:
            name = mavlink.mavlink_map[mid].msgname
            self.sim.event("interval", f"{name} every {iv:g} s on the {by.link} link" if iv > 0
                           else f"{name} off on the {by.link} link")
        return mavlink.MAV_RESULT_ACCEPTED
