"""UDP addresses as pymavlink's connection strings, and the project's identities and ports.

In:  an address text (``udpin:`` / ``udpout:`` / ``udp:`` HOST:PORT) and the flag it came from
Out: an :class:`Address` (mode, host, port), or a ConfigError naming the flag; the ports (UDP) and MAVLink
     ids of docs/design.md, "The MAVLink contract"
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

from params import ConfigError

# Identities and ports of docs/design.md, "The MAVLink contract". Instance N (0-9) adds N to both ports and
# makes the vehicle sysid N + 1, as PX4 does.
GCS_PORT = 14550
LINK_PORT = 14560
VEHICLE_COMPID = 1  # MAV_COMP_ID_AUTOPILOT1
CONTROLLER_SYSID = 200  # not 255 (MAVProxy) nor 245 (MAVSDK): a GCS can run beside the controller
CONTROLLER_COMPID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER


@dataclass(frozen=True)
class Address:
    """A UDP address and what to do with it: ``udpin`` binds it, ``udpout`` sends to it."""

    mode: str
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.mode}:{self.host}:{self.port}"

    @property
    def hostport(self) -> str:
        return f"{self.host}:{self.port}"


def parse_address(text: str, default_mode: str = "udpout", flag: str = "address") -> Address:
    """``[udpin:|udpout:|udp:]HOST:PORT`` (also ``udpin://HOST:PORT``) -> :class:`Address`.

    ``udp:`` is pymavlink's name for ``udpin``. Errors name ``flag`` (exit 2 material).
    """
    s = text.strip()
    mode = default_mode
    for prefix, m in (("udpin", "udpin"), ("udpout", "udpout"), ("udp", "udpin")):
        for sep in ("://", ":"):
            if s.startswith(prefix + sep):
                mode, s = m, s[len(prefix) + len(sep):]
                break
        else:
            continue
        break
    host, _, port_text = s.rpartition(":")
    if not host or not port_text:
        raise ConfigError.at(f"{flag} {text!r}", None, "expected [udpin:|udpout:]HOST:PORT")
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError.at(f"{flag} {text!r}", None, "port must be an integer") from None
    lo = 0 if mode == "udpin" else 1
    if not lo <= port <= 65535:
        raise ConfigError.at(f"{flag} {text!r}", None, f"port must be in [{lo}, 65535]")
    try:
        socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError):
        raise ConfigError.at(f"{flag} {text!r}", None, f"unknown host {host!r}") from None
    return Address(mode, host, port)


def check_free(address: Address) -> None:
    """Raise OSError if ``address`` is bound already (probed without ``SO_REUSEPORT``, which
    a socket holding the port with it refuses too)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((address.host, address.port))
    finally:
        probe.close()
