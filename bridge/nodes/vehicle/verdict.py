"""``bsst vehicle`` alone: how its flights ended, for its exit status.

In:  the vehicle's events in the order it said them (:class:`~bridge.autopilot.vehicleevents.Event`: t s, kind,
     text, a ``mode`` event's mode and whether it acted on an armed vehicle); its timeline's events not acted on
     and its mission's time 0 (:class:`~bridge.autopilot.simvehicle.SimVehicle`, plant time s)
Out: :func:`flights_not_ended_well`: one line each for a flight the plant ended (``crashed``, ``diverged``, a
     ``collision``, a ground station's ``terminated``) and for a failsafe the flight ended in (no arm, no mode
     selected armed, after it: a controller's or a ground station's taking it back), as ``bsst sitl`` names those
     outcomes; any one makes the exit status 1

:func:`timeline_not_reached`: one line each for an event of the mission's timeline (``[[events]]``, a ``[wind]``
gust) never acted on by a vehicle whose flight began (armed, its time 0 come): the vehicle was stopped before its
time, or its plant ended the flight before it (crashed, diverged, a collision: the time of that end, not of the stop,
which may come minutes later). A flight that never began (real time: no controller's target, no ground station's
takeoff; an arm that left it on the ground, in HOLD or LAND, flies nothing: :mod:`bridge.autopilot.flightstart`)
asked nothing of its timeline: no line; any one makes the exit status 1 too, as ``summary.json``'s
``ended_by.not_reached`` is said by ``bsst sitl``

:func:`start_not_flown`: one line for a mission a ground station started under ``--await-mission`` that no
controller ever took up (the vehicle alone waits for ``bsst controller --await-mission``), or whose controller's arm
PX4's pre-arm check refused (a ``preflight`` event after the start: said with why): exit status 1 too

``bsst controller`` alone says what went wrong as far as it knows (bridge.nodes.offboard.run); the vehicle alone,
stopped (Ctrl-C, SIGTERM), says what its own flights came to. A clean stop of a vehicle whose flights ended well (or
that never flew) says nothing and exits 0.
"""

from __future__ import annotations

from collections.abc import Iterable

from bridge.autopilot.simvehicle import SimVehicle
from bridge.autopilot.vehicleevents import Event

PLANT_ENDS = ("crashed", "diverged", "collision", "terminated")  # the flight's end, its plant's (or motors cut)
HALTS = ("crashed", "diverged", "collision")  # the plant is stepped no more after these (its clock halted)


def flights_not_ended_well(events: Iterable[Event]) -> list[str]:
    """What the vehicle's flights came to that was not a safe end, one line each, in the order it happened
    (module docstring); empty for a vehicle whose flights ended well."""
    said: list[tuple[float, str]] = []
    failsafe: Event | None = None  # the latest failsafe its flight has not come back from
    for e in events:
        if e.kind in PLANT_ENDS:
            said.append((e.t, f"{e.kind} at t={e.t:.3f} s: {e.shown}"))
        elif e.kind == "failsafe":
            failsafe = e
        elif e.kind == "armed" or e.kind == "mode" and e.armed:
            failsafe = None  # armed again (a new flight, or back under offboard control), or a mode selected armed
    if failsafe is not None:
        said.append((failsafe.t, f"failsafe at t={failsafe.t:.3f} s: {failsafe.shown}: its flight ended in it (no "
                                 "arm, no mode selected, took it back)"))
    return [text for _, text in sorted(said, key=lambda s: s[0])]


def start_not_flown(starting: bool, started: dict[str, str] | None, since: Iterable[Event] = ()) -> list[str]:
    """A mission a ground station started (``--await-mission``) that no controller's arm ever took up, one line
    (module docstring); empty if none is pending (never started, or flown). A controller that came but whose arm
    PX4's pre-arm check denied (a ``preflight`` event in ``since``: the vehicle's events from the start on) is said
    so, with why (the latest)."""
    if not starting or started is None:
        return []
    refused = [e for e in since if e.kind == "preflight"]
    why = ("no controller took it up (bsst controller --await-mission flies it; bsst sitl --await-mission runs both)"
           if not refused else f"its arm was refused at t={refused[-1].t:.3f} s: {refused[-1].text}")
    return [f"not flown: the mission started by {started['command']} [by {started['by']}] was never flown: {why}"]


def timeline_not_reached(sim: SimVehicle) -> list[str]:
    """The timeline's events a vehicle whose flight began never acted on, one line each, in mission time order
    (module docstring); empty if no flight began (never armed, or real time with no time 0: an arm is not a
    flight, :mod:`bridge.autopilot.flightstart`) or all acted."""
    t0 = sim.mission_t0
    if t0 is None or not any(e.kind == "armed" for e in sim.events):
        return []
    end = next((e for e in sim.events if e.kind in HALTS), None)  # its plant ended the flight: no event acts after
    if end is not None:
        why = f"its plant ended the flight at t={end.t - t0:.3f} s of its flight's time ({end.kind} at t={end.t:.3f} s)"
    else:
        why = f"the vehicle stopped at t={sim.t - t0:.3f} s of its flight's time"
    return [f"not reached: {late}: {why}" for late in sim.not_reached()]
