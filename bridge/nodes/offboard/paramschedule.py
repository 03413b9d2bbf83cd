"""A ``--param-at`` change as the offboard controller sent it, and what the vehicle's echo said of it
(:mod:`bridge.nodes.offboard.link` sends and resends it).

In:  the change (:class:`~bridge.autopilot.params.ParamChange`: mission time s, name, value), its wire value
     (float32) and MAVLink type, the mission time it was first sent (s), the PARAM_SETs sent, the mission time
     the vehicle's PARAM_VALUE echoed it (s; in flight, or after the flight's end)
Out: its entry in the controller's ``stats`` and ``summary.json["param_at"]`` (:meth:`ScheduledSet.as_dict`);
     the wall time between resends (s)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bridge.autopilot.params import ParamChange

PARAM_RETRY_S = 0.2  # s of wall time between PARAM_SETs of one scheduled change the vehicle has not echoed


@dataclass
class ScheduledSet:
    """One ``--param-at`` change as sent: its wire value (float32) and MAVLink type, the mission time it was
    first sent (s), how many PARAM_SETs went, the next resend's wall time, and the mission time the vehicle's
    PARAM_VALUE echoed it (None: not yet), or ``late_t`` if that came after the flight's end (not made in flight)."""

    change: ParamChange
    wire: float
    kind: int
    sent_t: float
    sends: int = 0
    next_send: float = 0.0
    confirmed_t: float | None = None
    late_t: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """Its entry in the controller's ``stats`` (``param_at``) and ``summary.json["param_at"]``."""
        c, late = self.change, {} if self.late_t is None else {"late_t": round(self.late_t, 6)}
        return {"t_s": c.t_s, "name": c.name, "value": c.value, "sent_t": round(self.sent_t, 6), "sends": self.sends,
                "confirmed": self.confirmed_t is not None,
                "confirmed_t": None if self.confirmed_t is None else round(self.confirmed_t, 6), **late}
