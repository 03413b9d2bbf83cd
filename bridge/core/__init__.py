"""Simulation time only: the parts a flight is made of, and the one path that builds them.

No sockets, no files, no wall clock (but for the pure arithmetic of :mod:`~bridge.core.clock`).

- :mod:`bridge.core.flight`      mission + overrides -> :class:`~bridge.core.flight.Flight` (the one path)
- :mod:`bridge.core.link`        the seeded link model and its one range table
- :mod:`bridge.core.linktrace`   measured link traces: the file, its records, replay
- :mod:`bridge.core.linkfit`     the model's table that fits a trace; traces the model makes
- :mod:`bridge.core.linkprofile` named link profiles (``linkprofiles/*.toml``)
- :mod:`bridge.core.linkends`    the two ends of an impaired link in simulation time
- :mod:`bridge.core.simvehicle`  plant + arming + offboard timeout + failsafe, for every clock
- :mod:`bridge.core.failsafe`    level-and-descend landing loop
- :mod:`bridge.core.wire`        paper frame <-> MAVLink NED/FRD, actuator normalisation, stamps
- :mod:`bridge.core.clock`       the real-time clocks as arithmetic: Pace, FixedRate
"""
