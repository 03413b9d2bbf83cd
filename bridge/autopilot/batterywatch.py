"""The vehicle's battery failsafe, as PX4's commander has it (BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR,
COM_LOW_BAT_ACT).

In:  the charge left (0..1 of the pack's capacity, ``plant.battery.Battery.remaining``), the three levels (fractions)
     and COM_LOW_BAT_ACT (0 warning, 2 land, 3 return at critical and land at emergency)
Out: each level newly passed (:data:`LEVELS`), its event's text and the failsafe action it asks for (a ``[failsafe]
     action`` name: ``land`` or ``return``; None: a warning only) (:meth:`BatteryWatch.passed`); why arming is denied
     (:meth:`BatteryWatch.arming_refusal`: at the critical level or below)

PX4 warns at the low level whatever COM_LOW_BAT_ACT says; 2 lands at the critical level; 3 returns at the critical
level and lands at the emergency level (from wherever Return has got to). PX4 first holds for COM_FAIL_ACT_T; here
the action is flown at once, as the geofence's is. Each level is said once a flight, in order, and a later level
never gives way to an earlier one's action.
"""

from __future__ import annotations

from dataclasses import dataclass

LEVELS = ("low", "critical", "emergency")  # PX4's battery_status warning levels, in order
LEVEL_PARAMS = ("BAT_LOW_THR", "BAT_CRIT_THR", "BAT_EMERGEN_THR")  # each level's parameter
_ACTIONS = {2: {"critical": "land"}, 3: {"critical": "return", "emergency": "land"}}  # COM_LOW_BAT_ACT -> level -> act


@dataclass
class BatteryWatch:
    """One vehicle's battery levels, its action, and the worst level said so far (0: none; 1..3: LEVELS)."""

    low: float = 0.15  # BAT_LOW_THR
    critical: float = 0.07  # BAT_CRIT_THR
    emergency: float = 0.05  # BAT_EMERGEN_THR
    action: int = 0  # COM_LOW_BAT_ACT
    said: int = 0
    returning: bool = False  # its critical level's Return flies (the emergency level's landing may take over)

    def level(self, remaining: float) -> int:
        """The level of the charge left (0..1), as PX4's battery judges it, the worst first: 3 emergency (below
        BAT_EMERGEN_THR), 2 critical, 1 low, 0 none."""
        return next((3 - i for i, lim in enumerate((self.emergency, self.critical, self.low)) if remaining < lim), 0)

    def passed(self, remaining: float) -> list[tuple[str, str, str | None]]:
        """The levels passed since the last call, each (level, text, failsafe action or None)."""
        now, out = self.level(remaining), []
        limits = (self.low, self.critical, self.emergency)
        for i in range(self.said, now):
            name = LEVELS[i]
            text = f"{name}: {100.0 * remaining:.1f} % left ({LEVEL_PARAMS[i]} = {100.0 * limits[i]:g} %)"
            out.append((name, text, _ACTIONS.get(self.action, {}).get(name)))
        self.said = max(self.said, now)
        return out

    def arming_refusal(self, remaining: float) -> str | None:
        """Why arming is denied at this charge (PX4's pre-arm battery check: at the critical level or below), or
        None."""
        level = self.level(remaining)
        if level < 2:
            return None
        limit = 100.0 * self.critical
        return f"battery {LEVELS[level - 1]}: {100.0 * remaining:.1f} % left (BAT_CRIT_THR = {limit:g} %)"
