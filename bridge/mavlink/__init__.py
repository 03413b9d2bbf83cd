"""Bytes and sockets: MAVLink 2 over UDP, with no plant and no law.

- :mod:`bridge.mavlink.endpoint`   an endpoint owning its socket; the hot-path codec; tlogs
- :mod:`bridge.mavlink.receive`    the one receive path: what is refused, and how it is counted
- :mod:`bridge.mavlink.signing`    MAVLink 2 message signing
- :mod:`bridge.mavlink.telemetry`  what the vehicle tells a ground station, from the paper state
"""
