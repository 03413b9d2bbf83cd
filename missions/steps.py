"""How long a flight may be: a command's cap on the control steps it keeps, and the check of a plan against it
before the plan's trajectory is timed.

In:  a flight's duration (s) and control rate (Hz); a plan's least duration (s, :func:`missions.route.least_duration_s`)
     and its item count; the mission's longest duration (s)
Out: :class:`StepCap` (steps, and what the cap is for, said in the refusal); :class:`PlanBudget`, which refuses
     (:class:`params.ConfigError`, naming the plan file) a plan that cannot fit before it is timed

A 3 000-item plan took ~30 s to time (its legs sampled against the speed limits, then the envelope and the
airframe) before ``bsst sim`` refused it for its 7.5 hours (docs/missions.md, "Loading a long plan"): the bound
costs milliseconds, so a plan too long even at its speed limits is refused first.
"""

from __future__ import annotations

from dataclasses import dataclass

from params import ConfigError


@dataclass(frozen=True)
class StepCap:
    """At most ``steps`` control steps a command keeps of one flight; ``why`` the cap is (``a run keeps in memory
    for its summary``) and ``hint`` what to do instead, said in the refusal; ``rate_hz`` the rate the command flies
    at when it is not the mission's own (an override: ``--rate``), else None."""

    steps: int
    why: str
    hint: str = ""
    rate_hz: float | None = None

    def problem(self, duration_s: float, rate_hz: float, least_of: str = "") -> str | None:
        """Why a flight of ``duration_s`` at the rate it flies (``rate_hz`` unless the cap has its own) is over the
        cap, or None. ``least_of``: the duration is a lower bound, of that (said)."""
        rate = self.rate_hz or rate_hz
        n = int(round(duration_s * rate))
        if n <= self.steps:
            return None
        more = "at least " if least_of else ""
        of = f" ({least_of})" if least_of else ""
        then = f"; {self.hint}" if self.hint else ""
        return (f"duration_s: {more}{duration_s:g} s{of} at {rate:g} Hz is {more}{n} control steps, over the "
                f"{self.steps} {self.why} ({self.steps / rate:g} s at this rate){then}")


@dataclass(frozen=True)
class PlanBudget:
    """What a plan being loaded may last: ``longest_s`` (the mission's longest duration) and, when the command caps
    the steps it keeps, ``cap`` at ``rate_hz`` (the mission's rate; the cap's own if it has one)."""

    longest_s: float
    rate_hz: float
    cap: StepCap | None = None

    def check(self, source: str, items: int, least_s: float) -> None:
        """Refuse a plan of ``items`` items whose flight (its trajectory and the rest after) lasts at least
        ``least_s``, if that is already too long: ConfigError naming the plan file."""
        if least_s > self.longest_s:
            raise ConfigError(f"{source}: mission.items: {items} items fly at least {least_s:.0f} s at their speed "
                              f"limits, over the {self.longest_s:g} s a mission may last (duration_s)")
        of = f"{items} items at their speed limits"
        why = self.cap.problem(round(least_s, 1), self.rate_hz, of) if self.cap is not None else None
        if why:
            raise ConfigError(f"{source}: {why}")
