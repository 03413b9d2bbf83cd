"""Everything that connects a law to a plant; the only package that touches the network.

- :mod:`bridge.loop`      the in-process closed loop (``bsst sim``), :func:`simulate`
- :mod:`bridge.flight`    a mission validated into the parts that fly it
- :mod:`bridge.simvehicle` plant + arming + timeout + failsafe, shared by every clock
- :mod:`bridge.failsafe`  level-and-descend failsafe
- :mod:`bridge.wire`      frame conversion NWU <-> NED and actuator normalisation
- :mod:`bridge.runlog`    the run directory: trace, events, summary
- :mod:`bridge.metrics`   RMS, settling, finite-time bound, total variation
- :mod:`bridge.plots`     the paper-style figures
- :mod:`bridge.endpoint`  MAVLink 2 over UDP: an endpoint owning its socket, hot-path codec, tlogs
- :mod:`bridge.vehicle`   the simulated vehicle as a MAVLink endpoint (``bsst vehicle``)
- :mod:`bridge.telemetry` what the vehicle tells a ground station, from the paper state
- :mod:`bridge.offboard`  the offboard controller as a MAVLink endpoint (``bsst controller``)
- :mod:`bridge.session`   the SITL session launcher (``bsst sitl``), :func:`~bridge.session.sitl`
- :mod:`bridge.process`   status lines, stop signals and parent death for the child processes
- :mod:`bridge.cli`       ``bsst``
"""

from bridge.loop import simulate
from bridge.runlog import Run

__all__ = ["Run", "simulate"]
