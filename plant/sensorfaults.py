"""Sensor faults a timeline injects (plant/events.py): the state :class:`plant.sensors.SensorSuite` applies.

In:  a sensor event (gps off|on|jump, baro drift, mag off|on, gyro bias) and the time it acts (s)
Out: whether the position fix and the heading are delivered, the position offset (m, NWU) and the barometer's
     altitude offset at a time (m); a gyro bias step is added to the suite's true gyro bias itself

A fix sampled while the GPS is off is drawn (its noise consumed, so the stream after it is the one a flight
without the outage sees) and dropped; a jump shifts every later fix by (dx, dy, dz); a drift makes the barometer's
error grow at ``drift_mps`` from its time on (a later drift continues from the error reached).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SensorFaults:
    gps_on: bool = True
    mag_on: bool = True
    position_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    baro_drift_mps: float = 0.0
    baro_offset_m: float = 0.0  # the error reached when the drift last changed
    baro_since: float = 0.0  # s: when it last changed

    @property
    def active(self) -> bool:
        return (not self.gps_on or not self.mag_on or self.position_offset != (0.0, 0.0, 0.0)
                or self.baro_drift_mps != 0.0 or self.baro_offset_m != 0.0)

    def baro_error(self, t: float) -> float:
        """The barometer's altitude error at t (m)."""
        return self.baro_offset_m + self.baro_drift_mps * (t - self.baro_since)

    def set_drift(self, rate_mps: float, t: float) -> None:
        self.baro_offset_m = self.baro_error(t)
        self.baro_since = t
        self.baro_drift_mps = rate_mps

    def jump(self, d: tuple[float, float, float]) -> None:
        o = self.position_offset
        self.position_offset = (o[0] + d[0], o[1] + d[1], o[2] + d[2])
