"""One process each, speaking MAVLink 2 over UDP: the vehicle, the offboard controller, the relay.

- :mod:`bridge.nodes.vehicle`   the simulated vehicle (``bsst vehicle``)
- :mod:`bridge.nodes.offboard`  the offboard controller (``bsst controller``)
- :mod:`bridge.nodes.relay`     the link model on the wall clock (``bsst relay``)
- :mod:`bridge.nodes.process`   report lines out, stop signals, parent death
- :mod:`bridge.nodes.report`    the children's reports to the session (JSON lines), read in one place
- :mod:`bridge.nodes.watched`   work in a forked child, watched (``bsst sim`` with a law of the user's own)
"""
