"""The seeded link model between controller and vehicle, in simulation time: no sockets.

In:  a ``[link]`` table, flags, a trace file or a profile name; Out: each datagram's fate
(delivered at t, or lost, and why), for the scalar ends and for a whole batch of cells at once

- :mod:`bridge.link.model`    the seeded link model and its one range table
- :mod:`bridge.link.trace`    measured link traces: the file, its records, replay
- :mod:`bridge.link.fit`      the model's table that fits a trace; traces the model makes
- :mod:`bridge.link.profile`  named link profiles (``profiles/*.toml``)
- :mod:`bridge.link.ends`     the two ends of an impaired link in simulation time
- :mod:`bridge.link.plan`     the batch engine's link planner: every cell's traffic, chunks on threads
- :mod:`bridge.link.plan_cell` one cell's plan, compiled; :mod:`bridge.link.fates` its packets' draws
"""
