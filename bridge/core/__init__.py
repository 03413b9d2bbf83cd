"""What a flight is made of, and the one path that builds it from a mission.

In:  a mission and its overrides; Out: a :class:`~bridge.core.flight.Flight` (plant, law, link, vehicle)

No sockets, no files, no wall clock (but for the pure arithmetic of :mod:`~bridge.core.clock`).
The parts themselves live one layer down: the link model in :mod:`bridge.link`, the on-board
autopilot (simulated vehicle, estimator, failsafe, PX4 parameters) in :mod:`bridge.autopilot`.

- :mod:`bridge.core.flight`  mission + overrides -> :class:`~bridge.core.flight.Flight` (the one path)
- :mod:`bridge.core.weather` the mission's air and timeline of events, checked against the vehicle
- :mod:`bridge.core.wire`    paper frame <-> MAVLink NED/FRD, actuator normalisation, stamps
- :mod:`bridge.core.clock`   the real-time clocks as arithmetic: Pace, FixedRate
"""
