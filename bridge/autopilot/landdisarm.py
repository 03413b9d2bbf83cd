"""PX4's auto-disarm after landing (COM_DISARM_LAND): how long a landed vehicle waits, motors idle, before it disarms.

In:  COM_DISARM_LAND (s; 0 or less: never), and at each physics step the vehicle rests on the ground under a target
     that lands (LAND, Return's landing, the mission's end landing, a failsafe's): the plant time (s) and that target
Out: whether it disarms now (:meth:`LandDisarm.due`)

PX4's commander (src/modules/commander/Commander.cpp, 1.14 in ``run``, 1.15 in ``handleAutoDisarm``): armed, once
the land detector says landed after a takeoff (not amid a mission), a hysteresis of COM_DISARM_LAND seconds runs,
then it disarms (``arm_disarm_reason_t::auto_disarm_land``); COM_DISARM_LAND 0 or less disables it
(commander_params.c: default 2 s, no bounds in 1.14, -1..20 s in earlier versions: the range here). Meanwhile the
multicopter sits on the ground at idle: here its motors are off (no thrust either way). The land detector's own
delay (its ground-contact and maybe-landed stages) is not modelled: the wait counts from the physics step the plant
rests on the ground; nor is the auto-disarm of a landing the offboard controller flies (only the vehicle's own).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class LandDisarm:
    """COM_DISARM_LAND (``delay_s``) and the landing it times: the target it rests under and since when (plant s)."""

    delay_s: float = 2.0
    since: float | None = None  # plant time (s) the vehicle first rested on the ground under :attr:`target`
    target: Any = None  # the landing target it rests under (a new target: a new wait)

    def due(self, t: float, target: Any) -> bool:
        """Resting on the ground under ``target`` at plant time ``t`` (s): whether COM_DISARM_LAND has passed since
        it first rested under it (never when COM_DISARM_LAND is 0 or less)."""
        if target is not self.target or self.since is None:
            self.target, self.since = target, t
        return self.delay_s > 0.0 and t - self.since >= self.delay_s - 1e-9

    def waits_under(self, target: Any) -> bool:
        """Whether a landed vehicle waits out COM_DISARM_LAND under ``target``. A failsafe that lands it changes its
        mode, not this wait (PX4's auto-disarm counts from the land detector's ``landed``, whatever the mode)."""
        return self.since is not None and target is self.target

    def landed_text(self, X: tuple[float, ...]) -> str:
        """The ``landed`` event's text at state X (paper frame, m): where, and when it disarms."""
        when = f"disarms in COM_DISARM_LAND = {self.delay_s:g} s" if self.delay_s > 0 else \
            "stays armed (COM_DISARM_LAND <= 0: no auto-disarm)"
        return f"landing detected at x={X[0]:.3f} y={X[2]:.3f} m: {when}"

    def wait_s(self) -> float:
        """The most a landed vehicle waits before it disarms (s: 0 when it never does), for bounds on a landing."""
        return max(self.delay_s, 0.0)
