"""Covers bridge.nodes.report: the children's reports to the session, one JSON object a line, read in one place.

Pure: no processes, no sockets (the processes writing them are tested in test_sitl.py, test_relay*.py,
test_offboard_realtime.py).
"""

from __future__ import annotations

import json

import pytest

from bridge.autopilot.vehicleevents import ITSELF, ParamChanged, Sender
from bridge.autopilot.vehicleevents import Event as VehicleEvent
from bridge.nodes.report import (
    BadInput,
    Done,
    Event,
    Kind,
    Ready,
    Refused,
    Stats,
    StatusText,
    Warning,
    parse_line,
    to_line,
)
from params import ConfigError

GCS = Sender(255, 190, "127.0.0.1", 14550, "gcs")

EVERY_KIND = [
    Ready("vehicle", listen="127.0.0.1:14560", gcs="127.0.0.1:14550", sysid=1, clock="lockstep", profile="paper",
          controller_from="127.0.0.1:40000"),
    Ready("controller", vehicle="127.0.0.1:14560", local="127.0.0.1:40000", clock="realtime"),
    Ready("relay", listen="127.0.0.1:5", to="127.0.0.1:6", back="127.0.0.1:7", up="delay 10 ms", down="perfect"),
    Event(1.25, "armed", "armed, offboard control", Sender(200, 191, "127.0.0.1", 40000, "controller")),
    Event(3.0, "disarmed", "landed: disarmed", ITSELF),
    Event(0.5, "connected", "vehicle sysid 1 compid 1"),
    Event(10.0, "fault", "gps off", GCS, gps=False),
    Event(5.328, "failsafe", "the vehicle's flight ended", answers=("crashed", "diverged", "collision")),
    StatusText(2, "lockstep: left (no answer)"),
    Warning("rejected 3: sender 2, crc 1"),
    Refused("PARAM_SET MPC_XY_VEL_MAX: out of range"),
    Stats({"commands": 10, "rejected": {"stale": 1}, "down": None}),
    Done("completed"),
    Done("aborted", True, "vehicle silent for 2 s", silent=True),
    Done("aborted", False, "the vehicle was switched to HOLD: no more targets sent", "HOLD"),
    Event(2.0, "end", "the vehicle did not take the mission's end action (LAND): no answer", result="no answer"),
    BadInput("--gcs udpin:127.0.0.1:5: cannot bind (Address already in use)", "--gcs udpin:127.0.0.1:5", None,
             "cannot bind (Address already in use)"),
    BadInput("bsst relay: unrecognized arguments: --bogus", "bsst relay", None, "unrecognized arguments: --bogus"),
    BadInput("missions/x.toml: no such file"),
]


@pytest.mark.parametrize("report", EVERY_KIND, ids=lambda r: type(r).__name__)
def test_every_report_is_one_json_line_and_reads_back_equal(report):
    line = to_line(report)
    assert "\n" not in line
    body = json.loads(line)
    assert Kind(body["report"]).value == body["report"]
    assert parse_line(line) == report
    assert parse_line(line + "\n") == report  # as read from a pipe


def test_an_events_sender_travels_as_an_object():
    body = json.loads(to_line(Event(1.0, "disarmed", "disarmed by command", GCS)))
    assert body["by"] == {"sysid": 255, "compid": 190, "host": "127.0.0.1", "port": 14550, "link": "gcs"}
    assert json.loads(to_line(Event(1.0, "x", "y")))["by"] is None


def test_event_times_are_reported_to_the_millisecond():
    assert Event.at(1.23456, "k", "t").t == 1.235
    assert Event.at(2.0004999, "k", "t").t == float("2.000")


@pytest.mark.parametrize("line", [
    "", "hello", "{", "[1, 2]", '{"report": "nonsense"}', '{"no": "kind"}',
    '{"report": "done"}',  # a missing field
    '{"report": "done", "outcome": "completed", "extra": 1}',  # a field no reader knows
    '{"report": "event", "t": "soon", "kind": "armed", "text": "x", "by": null}',
    '{"report": "event", "t": 1.0, "kind": "armed", "text": "x", "by": {"link": "gcs"}}',
    '{"report": "stats", "values": [1, 2]}',
    '{"report": "event", "t": 1.0, "kind": "end", "text": "x", "by": null, "answers": [1]}',
    '{"report": "event", "t": 1.0, "kind": "end", "text": "x", "by": null, "answers": "end"}',
    '{"report": "warning", "text": 5}',
    '{"report": "done", "outcome": "aborted", "silent": 1}',  # a frozen vehicle is killed on it: a bool only
    '{"report": "event", "t": 1.0, "kind": "end", "text": "x", "by": null, "result": 4}',
    '{"report": "bad_input", "text": 5}',
    '{"report": "event", "t": 1.0, "kind": "fault", "text": "gps off", "by": null, "gps": "off"}',
    '{"report": "bad_input", "text": "x", "source": 1}',
    '{"report": "bad_input"}',
    "relay: listening on 127.0.0.1:5",  # a person's line, not a report
])
def test_a_line_that_is_not_a_report_is_none_not_a_traceback(line):
    assert parse_line(line) is None


# -- the vehicle's events: their sender and typed fields travel as fields, never in the text -----------------
def test_a_vehicle_event_travels_with_its_sender_and_typed_fields():
    mode = VehicleEvent(1.23456, "mode", "HOLD (disarmed: armed in it next)", GCS, mode="hold", armed=False)
    r = parse_line(to_line(Event.of(mode)))
    assert r == Event(1.235, "mode", "HOLD (disarmed: armed in it next)", GCS, mode="hold", armed=False)
    change = ParamChanged("COM_OF_LOSS_T", 0.5, 0.01)
    param = VehicleEvent(2.0, "param", "COM_OF_LOSS_T = 0.01 (was 0.5)", GCS, param=change)
    assert parse_line(to_line(Event.of(param))) == Event(2.0, "param", param.text, GCS, param=change)
    assert param.shown == "COM_OF_LOSS_T = 0.01 (was 0.5) [by 255:190 127.0.0.1:14550 gcs]"  # for people only
    landed = parse_line(to_line(Event.of(VehicleEvent(3.0, "disarmed", "landed: disarmed", ITSELF))))
    assert landed == Event(3.0, "disarmed", "landed: disarmed", ITSELF) and landed.by is ITSELF


@pytest.mark.parametrize("field, bad", [("mode", 1), ("armed", "yes"), ("armed", 1), ("param", 5),
                                        ("param", {"name": "X"})])
def test_a_mistyped_event_field_is_no_report(field, bad):
    body = json.loads(to_line(Event(1.0, "mode", "x")))
    assert parse_line(json.dumps({**body, field: bad})) is None


def test_a_vehicle_ready_report_describes_itself():
    assert EVERY_KIND[0].describe() == ("listen=127.0.0.1:14560 gcs=127.0.0.1:14550 sysid=1 clock=lockstep "
                                        "profile=paper controller_from=127.0.0.1:40000")


def test_text_lines_are_no_reports():
    for line in ("ready listen=127.0.0.1:14560 sysid=1", "event t=1.250 armed: armed", "refused takeoff: too high",
                 'stats {"accepted": 3}'):
        assert parse_line(line) is None


def test_a_sender_is_shown_as_the_written_suffix():
    assert str(GCS) == "255:190 127.0.0.1:14550 gcs" and GCS.suffix == " [by 255:190 127.0.0.1:14550 gcs]"
    assert str(ITSELF) == "vehicle" and ITSELF.is_vehicle and not GCS.is_vehicle
    assert Sender.from_dict(GCS.as_dict()) == GCS and Sender.from_dict(ITSELF.as_dict()) is ITSELF


def test_a_bad_input_report_is_its_refusal_again_with_its_typed_fields():
    """A session's child refused at its start reports its ConfigError (``bad_input``); the session raises it again
    from the report's fields (bridge.session.session.Session._died), not from the child's stderr line."""
    refused = ConfigError.at("m.toml", "link.up.trace", "no such file")
    again = parse_line(to_line(BadInput.of(refused)))
    assert isinstance(again, BadInput)
    e = again.error()
    assert (str(e), e.source, e.key, e.what) == ("m.toml: link.up.trace: no such file", "m.toml", "link.up.trace",
                                                 "no such file")
