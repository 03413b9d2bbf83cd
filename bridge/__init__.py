"""Everything that connects a law to a plant; the only package that touches the network.

- :mod:`bridge.loop`      the in-process closed loop (``bsst sim``), :func:`simulate`
- :mod:`bridge.flight`    a mission validated into the parts that fly it
- :mod:`bridge.simvehicle` plant + arming + timeout + failsafe, shared by every clock
- :mod:`bridge.failsafe`  level-and-descend failsafe
- :mod:`bridge.link`      link impairment: one seeded model of a bad link, used by every clock
- :mod:`bridge.linkends`  the two ends of an impaired link in simulation time (offline and lockstep)
- :mod:`bridge.wire`      frame conversion NWU <-> NED and actuator normalisation
- :mod:`bridge.clock`     the real-time clocks: the vehicle's pace, the controller's fixed-rate schedule
- :mod:`bridge.runlog`    the run directory: trace, events, summary
- :mod:`bridge.metrics`   RMS, settling, finite-time bound, total variation
- :mod:`bridge.plots`     the paper-style figures
- :mod:`bridge.sweep`     latency and dropout campaigns (``bsst sweep``)
- :mod:`bridge.report`    a sweep's report: classes, tables, heat maps (``bsst report``)
- :mod:`bridge.endpoint`  MAVLink 2 over UDP: an endpoint owning its socket, hot-path codec, tlogs
- :mod:`bridge.guard`     the one receive path of both endpoints: what is refused, and how it is counted
- :mod:`bridge.signing`   MAVLink 2 message signing
- :mod:`bridge.vehicle`   the simulated vehicle as a MAVLink endpoint (``bsst vehicle``)
- :mod:`bridge.telemetry` what the vehicle tells a ground station, from the paper state
- :mod:`bridge.offboard`  the offboard controller as a MAVLink endpoint (``bsst controller``)
- :mod:`bridge.relay`     a real-time UDP relay applying the link model on the wall clock (``bsst relay``)
- :mod:`bridge.session`   the SITL session launcher (``bsst sitl``), :func:`~bridge.session.sitl`
- :mod:`bridge.process`   status lines, stop signals and parent death for the child processes
- :mod:`bridge.cli`       ``bsst``
"""

from typing import Any

__all__ = ["Run", "simulate"]


def __getattr__(name: str) -> Any:
    # imported on first use, so that ``bsst --help`` or a refused flag does not load the law
    if name == "simulate":
        from bridge.loop import simulate

        return simulate
    if name == "Run":
        from bridge.runlog import Run

        return Run
    raise AttributeError(f"module 'bridge' has no attribute {name!r}")
