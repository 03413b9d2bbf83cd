"""Covers bridge.session.eventorder: the children's reports of one read, put in the order things happened.

A session reads its controller's pipe, then its vehicle's; events of one time go by cause, and the vehicle's own
events keep the order it said them in. Only a child's ``name`` is read, so the children here are named stand-ins.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from bridge.autopilot.vehicleevents import CONTROLLER_LINK, Sender
from bridge.nodes.report import Event
from bridge.session.eventorder import in_cause_order

pytestmark = pytest.mark.process  # (bridge.session is the layer that starts the children: its import counts)

CONTROLLER, VEHICLE = SimpleNamespace(name="controller"), SimpleNamespace(name="vehicle")
BY_CONTROLLER = Sender(1, 191, "127.0.0.1", 14580, CONTROLLER_LINK)
BY_GCS = Sender(255, 190, "127.0.0.1", 14550, "gcs")


def _kinds(reports: list) -> list[str]:
    times = [r.t for _, r in reports]
    return [f"{child.name}:{r.kind}" for child, r, _ in in_cause_order(reports, times, {})]


def test_a_controllers_act_goes_before_the_change_it_caused_at_one_time() -> None:
    """In lockstep a ``--param-at`` change is made at the step its PARAM_SET is stamped at: sent, made, confirmed."""
    reports = [(CONTROLLER, Event(4.0, "param", "PARAM_SET COM_OBL_ACT = 1 sent")),
               (CONTROLLER, Event(4.0, "param", "COM_OBL_ACT = 1 confirmed", answers=("param",))),
               (VEHICLE, Event(4.0, "param", "COM_OBL_ACT = 1 (was -1)", BY_CONTROLLER))]
    assert _kinds(reports) == ["controller:param", "vehicle:param", "controller:param"]
    assert [r.text for _, r, _ in in_cause_order(reports, [4.0] * 3, {})][0].endswith("sent")


def test_the_vehicles_events_of_one_time_keep_the_order_it_said_them_in() -> None:
    """The controller's ARM, then a ground station's fence upload, both at the step the flight waits at: armed
    first. The tie's rank put the vehicle's own event (the fence) before the one its controller caused (the arm), and
    test_mission_in_flight's fence test failed once in a make test ('armed' after 'fence')."""
    reports = [(VEHICLE, Event(0.0, "armed", "armed", BY_CONTROLLER)),
               (VEHICLE, Event(0.0, "fence", "a fence of 4 vertices uploaded", BY_GCS)),
               (VEHICLE, Event(0.0, "mode", "AUTO.MISSION", BY_GCS))]
    assert _kinds(reports) == ["vehicle:armed", "vehicle:fence", "vehicle:mode"]


def test_the_vehicles_own_event_before_a_caused_one_stays_before_the_controllers_act() -> None:
    """A failsafe the vehicle said before the change its controller's PARAM_SET made: failsafe, sent, change."""
    reports = [(CONTROLLER, Event(2.0, "param", "PARAM_SET COM_OBL_ACT = 1 sent")),
               (VEHICLE, Event(2.0, "failsafe", "offboard lost", None)),
               (VEHICLE, Event(2.0, "param", "COM_OBL_ACT = 1 (was -1)", BY_CONTROLLER))]
    assert _kinds(reports) == ["vehicle:failsafe", "controller:param", "vehicle:param"]
