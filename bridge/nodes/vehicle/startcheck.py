"""The vehicle's check of a held mission before its start (``--await-mission``), run on a thread as the upload ends,
as PX4's navigator checks a mission once it is stored (its MissionFeasibilityChecker: ``mission_result.valid``,
which Commander asks of MISSION_START and of Mission mode).

In:  the items held (:class:`~bridge.mavlink.missionitems.MissionItem`): the mission's, the fence's and the rally
     points' (:data:`Held`), the vehicle's home (deg, deg, m AMSL), its settings'
     :class:`~bridge.core.flight.Flight` (with the controller's ``--param-at``) and the step cap of its session (or
     None)
Out: :meth:`StartCheck.result`: the items' goals (:class:`~bridge.nodes.vehicle.missionwatch.Goal`), why the
     mission cannot be flown (str), or None while the check runs

The check is the controller's own (:func:`bridge.nodes.uploaded.uploaded_flight`: the route, its timing, the fence
and rally points read as the controller reads them from its download, the longest a mission may last, a
``--param-at`` after its end, the session's step cap, the points its ``mission.toml`` may hold): a mission the
vehicle starts is one the controller flies; an upload or a clear of any of the three is checked afresh. Timing a
plan takes seconds (about 7 s for 1000 items), so it runs off the vehicle's loop, which goes on answering
meanwhile; a start asked for before it is done waits for it at most :data:`WAIT_S` (a few items' check is done by
then), else is refused saying so.
"""

from __future__ import annotations

import threading
import time

from bridge.core.flight import Flight
from bridge.mavlink.missionitems import MissionItem
from bridge.nodes.uploaded import uploaded_flight
from bridge.nodes.vehicle.missionwatch import Goal, goals_of
from missions.steps import StepCap
from params import ConfigError

WAIT_S = 0.5  # s of wall time a start waits for a check under way (the vehicle's loop waits with it)
SOURCE = "the vehicle's mission"
Held = tuple[tuple[MissionItem, ...], tuple[MissionItem, ...], tuple[MissionItem, ...]]  # mission, fence, rally


class StartCheck:
    """One held mission's check (with the fence and rally points held with it), on its own thread from the moment
    it is made."""

    def __init__(self, held: Held, home: tuple[float, float, float], flight: Flight, cap: StepCap | None) -> None:
        self.held = held
        self.items = held[0]
        self.began = time.monotonic()
        self._out: tuple[Goal, ...] | str | BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(home, flight, cap), name="mission-check",
                                        daemon=True)
        self._thread.start()

    def _run(self, home: tuple[float, float, float], flight: Flight, cap: StepCap | None) -> None:
        try:
            uploaded_flight(flight, self.items, home, cap, SOURCE, *self.held[1:])
            self._out = goals_of(self.items, home)
        except (ConfigError, ValueError) as exc:  # (as the controller's download takes them: a refusal)
            self._out = str(exc)
        except BaseException as exc:  # a fault, not a refusal: raised on the vehicle's own thread (result)
            self._out = exc

    def of(self, held: Held) -> bool:
        """Whether this is the check of ``held`` (the very items: an upload or a clear holds new ones)."""
        return all(mine is theirs for mine, theirs in zip(self.held, held))

    def result(self, wait_s: float = 0.0) -> tuple[Goal, ...] | str | None:
        """The goals, why not (str), or None: still checking after ``wait_s`` more seconds."""
        self.wait(wait_s)
        if self._thread.is_alive():
            return None
        if isinstance(self._out, BaseException):
            raise self._out
        return self._out

    def wait(self, wait_s: float) -> None:
        """Wait for the check to end, ``wait_s`` at most."""
        self._thread.join(wait_s)

    def running(self) -> bool:
        return self._thread.is_alive()
