"""Bytes and sockets: MAVLink 2 over UDP, with no plant and no law.

- :mod:`bridge.mavlink.endpoint`   an endpoint owning its socket, and waiting on several
- :mod:`bridge.mavlink.kerneldrops` what the kernel dropped for a UDP socket (``/proc/net/udp``)
- :mod:`bridge.mavlink.events`     the vehicle's events as typed EVENT messages (added to pymavlink's common here)
- :mod:`bridge.mavlink.compmeta`   the component metadata: the events' libevents JSON, COMPONENT_METADATA (added here)
- :mod:`bridge.mavlink.ftp`        MAVLink FTP, read-only: the payload codec and the sessions of a file server
- :mod:`bridge.mavlink.frames`     the frame stage of the receive path; the hot-path codec
- :mod:`bridge.mavlink.tlog`       the telemetry log of every frame sent or received
- :mod:`bridge.mavlink.receive`    the one receive path: what is refused, and how it is counted
- :mod:`bridge.mavlink.signing`    MAVLink 2 message signing
- :mod:`bridge.mavlink.telemetry`  what the vehicle tells a ground station, from the paper state
"""

from bridge.mavlink import compmeta, events

events.register()
compmeta.register()
