"""What the kernel says it dropped for a UDP socket: the ``drops`` column of ``/proc/net/udp`` (Linux).

In:  a UDP socket (its inode, by ``os.fstat``), or a test on a row's columns; the table ``/proc/net/udp``
Out: the socket's count of datagrams the kernel dropped (its receive buffer full, a bad checksum), or None where
     the table cannot be read; the first row of the table a test takes (its columns, str), or None

Split out of :mod:`bridge.mavlink.endpoint` (whose :meth:`~bridge.mavlink.endpoint.Endpoint.kernel_drops` reads it,
as the relay's statistics do): reading the kernel's table is here.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable


def udp_table_row(match: Callable[[list[str]], bool], reads: int = 5) -> list[str] | None:
    """The first row of ``/proc/net/udp`` (its columns) that ``match`` takes, or None (none, or the table
    cannot be read). The kernel hands the table out a page per read and finds its place again by counting
    rows, so a row is skipped when a socket listed before it closes between two reads (other processes do,
    all the time on a busy machine): a row not found is looked for again, ``reads`` reads of the table in all."""
    for _ in range(reads):
        try:
            with open("/proc/net/udp") as f:
                next(f)
                for line in f:
                    cols = line.split()
                    if len(cols) >= 13 and match(cols):
                        return cols
        except (OSError, StopIteration):
            return None
    return None


def socket_drops(sock: socket.socket) -> int | None:
    """The kernel's count of datagrams it dropped for the UDP socket ``sock`` (its receive buffer full, a bad
    checksum): the ``drops`` column of ``/proc/net/udp`` (Linux; SO_RXQ_OVFL counts the same per datagram
    received, the column needs no receive). None where it cannot be read."""
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except OSError:
        return None
    row = udp_table_row(lambda cols: cols[9] == inode)
    return int(row[12]) if row is not None else None
