"""The plant's verdict on a flight after each control period: diverged, crashed, or a disarmed vehicle's impact.

In:  the plant (:meth:`plant.Quadrotor.diverged`, its first hard touchdown :attr:`plant.Quadrotor.impact`: t s,
     speed m/s, tilt rad), whether the vehicle is armed after the period, and each disarm as it happens
Out: the verdict (``diverged``, ``crashed``: the flight ends; None: it goes on) and the event saying it (kind,
     text): :meth:`ImpactWatch.judge`

A hard touchdown (faster than ``CRASH_SPEED_MPS`` or tilted more than ``CRASH_TILT_RAD``, docs/weather.md
"Outcomes") is a crash when the vehicle was armed as it touched down, whoever flew it (the offboard controller, a
ground station's LAND, a failsafe's landing): the vehicle's own landing disarms it on the ground one physics step
after the touchdown, before the period ends, so the verdict asks whether it was armed then (:meth:`disarming`
tells it), not whether it is armed now. A vehicle disarmed before it hit the ground (a ``disarm`` failsafe, a
forced disarm in the air) makes an ``impact``: logged once, and the flight goes on.
"""

from __future__ import annotations

from dataclasses import dataclass

from bridge.autopilot.vehicleevents import impact_text
from plant import Quadrotor


@dataclass
class ImpactWatch:
    """One flight's hard touchdown: whether it was judged, and whether the vehicle was armed when it happened."""

    noted: bool = False  # the hard touchdown was judged (once a flight)
    armed_at_impact: bool = False  # a disarm came after a hard touchdown not yet judged: it was armed then

    def disarming(self, plant: Quadrotor) -> None:
        """The vehicle disarms now: a hard touchdown the plant has had and no verdict has judged happened armed."""
        if plant.impact is not None and not self.noted:
            self.armed_at_impact = True

    def judge(self, plant: Quadrotor, armed: bool) -> tuple[str | None, tuple[str, str] | None]:
        """After a control period: (the verdict, the event (kind, text) to log; None: none). ``diverged`` when the
        plant diverged; ``crashed`` for a hard touchdown the vehicle was armed at (``armed`` now, or disarmed
        since it: :meth:`disarming`); an ``impact`` event (no verdict) for one it was disarmed at; judged once."""
        why = plant.diverged()
        if why:
            return "diverged", ("diverged", why)
        if plant.impact is None or self.noted:
            return None, None
        self.noted = True
        if armed or self.armed_at_impact:
            return "crashed", ("crashed", impact_text(plant.impact))
        return None, ("impact", impact_text(plant.impact, armed=False))
