"""A ground station's MAV_CMD_NAV_TAKEOFF altitude as PX4 takes it (pure; docs/ground-station.md, "Modes").

In:  the command's altitude (param7 of COMMAND_LONG, z of COMMAND_INT: m AMSL, as PX4 reads it; NaN: not given), the
     least altitude the vehicle takes off to (MIS_TAKEOFF_ALT, m above home), the highest (MIS_TAKEOFF_ALT's upper
     bound: the plant's envelope, m above home), the home's altitude (m AMSL)
Out: :class:`TakeoffAltitude`: the altitude to climb to (m above home) or why none (a STATUSTEXT's text, the command
     DENIED), and the WARNING PX4 says when it raises a lower one to the least
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class TakeoffAltitude:
    """The altitude a NAV_TAKEOFF climbs to (m above home), or why it is refused; ``warning``: PX4's STATUSTEXT
    for an altitude it raised (None: nothing said)."""

    alt_m: float | None
    why: str | None = None
    warning: str | None = None


def takeoff_altitude(amsl_m: float, least_m: float, highest_m: float, home_m: float) -> TakeoffAltitude:
    """NAV_TAKEOFF's altitude above home (m) from its altitude ``amsl_m`` (m AMSL; NaN: ``least_m``). ``least_m``
    (MIS_TAKEOFF_ALT) is also the least it climbs to: a lower altitude (below home too) is raised to it, with PX4's
    STATUSTEXT unless within 10 cm of it; one above ``highest_m`` (or not finite) is refused."""
    if math.isnan(amsl_m):
        return TakeoffAltitude(least_m)
    rel = amsl_m - home_m
    if not (math.isfinite(amsl_m) and rel <= highest_m):
        return TakeoffAltitude(None, f"NAV_TAKEOFF: altitude {amsl_m:g} m AMSL is {rel:g} m above home; "
                                     f"must be at most {highest_m:g} m above (home {home_m:g} m)")
    if rel < least_m:
        # PX4 says nothing for less than 10 cm
        said = f"Using minimum takeoff altitude: {home_m + least_m:.2f} m" if rel < least_m - 0.1 else None
        return TakeoffAltitude(least_m, warning=said)
    return TakeoffAltitude(rel)
