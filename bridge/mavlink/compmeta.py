"""The vehicle's component metadata (MAVLink's component information service): the files a ground station reads
to know the vehicle's EVENT ids, and the messages that say where they are. Pure: bytes made once, no sockets.

In:  the one table of event kinds (:class:`bridge.mavlink.events.EventId`: id, name, message); the time since boot
     (ms) of a COMPONENT_METADATA or COMPONENT_INFORMATION answer
Out: :data:`FILES`, the files served read-only over MAVLink FTP (path -> bytes: the general metadata JSON and the
     events JSON in libevents' format); COMPONENT_METADATA (397) and the deprecated COMPONENT_INFORMATION (395),
     each naming the general file's ``mftp://`` URI and its CRC32; :func:`crc32`, MAVLink's CRC32

As PX4 publishes its own (PX4-Autopilot, src/modules/mavlink/streams/COMPONENT_METADATA.hpp: the URI
``mftp://etc/extras/component_general.json.xz`` and its CRC; src/lib/component_information/
generate_component_general.py: ``{"version": 1, "metadataTypes": [{"type", "uri", "fileCrc"}]}``, each CRC MAVLink's
CRC32 of the file's bytes). Ours are plain JSON (the schema allows xz, not requires it), under the same directory.
The events file follows libevents' schema (mavlink/libevents, validation/schema.json, version 2): one component,
key 181 (0xB5, the upper 8 bits of our ids), namespace ``bsst``, group ``default``, each event keyed by the low 24
bits of its id, named by its kind; no arguments (ours carry none).
"""

from __future__ import annotations

import json
import zlib
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.events import NAMESPACE, EventId, message_class

COMPONENT_INFORMATION, COMPONENT_METADATA = 395, 397
COMP_METADATA_TYPE_EVENTS = 4  # COMP_METADATA_TYPE_EVENTS (common.xml)
DIRECTORY = "etc/extras"  # where PX4 keeps its metadata files, and so do we
GENERAL_PATH = f"{DIRECTORY}/component_general.json"
EVENTS_PATH = f"{DIRECTORY}/all_events.json"
EVENTS_NAMESPACE = "bsst"  # libevents' namespace of our component (pattern ^[a-z][a-z0-9_]*$)
EVENTS_DESCRIPTION = "Said in full by the STATUSTEXT sent with it (kind: text)."


def crc32(data: bytes) -> int:
    """MAVLink's CRC32 of ``data``: the reflected 0xEDB88320 polynomial from 0, with no final XOR (PX4's
    generate_crc.py and mavlink's crc32 in checksum.h; zlib's CRC-32 starts from and ends with an inversion)."""
    return zlib.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF


def uri(path: str) -> str:
    """The MAVLink FTP URI of a file we serve (``mftp://`` and its path: QGroundControl asks for ``/`` + path)."""
    return f"mftp://{path}"


def events_metadata() -> dict[str, Any]:
    """The events JSON (libevents' format, version 2), made from the one table of kinds (:class:`EventId`)."""
    events = {str(int(e) & 0xFFFFFF): {"name": e.name.lower(), "message": e.message,
                                       "description": EVENTS_DESCRIPTION} for e in EventId}
    return {"version": 2, "components": {str(NAMESPACE >> 24): {
        "namespace": EVENTS_NAMESPACE, "event_groups": {"default": {"events": events}}}}}


def _encoded(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, indent=1) + "\n").encode()


def general_metadata(events_file: bytes) -> dict[str, Any]:
    """The general metadata JSON (COMP_METADATA_TYPE_GENERAL, mavlink's general.schema.json): the events file's
    URI and CRC (QGroundControl skips a type without ``fileCrc``: CompInfoGeneral.cc)."""
    return {"version": 1, "vendorName": "bsst-sitl", "modelName": "BS-ST SITL quadrotor",
            "metadataTypes": [{"type": COMP_METADATA_TYPE_EVENTS, "uri": uri(EVENTS_PATH),
                               "fileCrc": crc32(events_file)}]}


_EVENTS = _encoded(events_metadata())
FILES: dict[str, bytes] = {GENERAL_PATH: _encoded(general_metadata(_EVENTS)), EVENTS_PATH: _EVENTS}
GENERAL_CRC = crc32(FILES[GENERAL_PATH])

URI_LEN = 100  # char[100] in both messages
MAVLink_component_information_message = message_class("COMPONENT_INFORMATION", COMPONENT_INFORMATION, 0, (
    ("time_boot_ms", "uint32_t", 0), ("general_metadata_file_crc", "uint32_t", 0),
    ("general_metadata_uri", "char", URI_LEN), ("peripherals_metadata_file_crc", "uint32_t", 0),
    ("peripherals_metadata_uri", "char", URI_LEN)))
MAVLink_component_metadata_message = message_class("COMPONENT_METADATA", COMPONENT_METADATA, 182, (
    ("time_boot_ms", "uint32_t", 0), ("file_crc", "uint32_t", 0), ("uri", "char", URI_LEN)))
MESSAGES = (MAVLink_component_information_message, MAVLink_component_metadata_message)


def component_metadata(time_boot_ms: int) -> Any:
    """COMPONENT_METADATA: the general metadata file's URI and CRC32 (PX4's answer to REQUEST_MESSAGE 397)."""
    return MAVLink_component_metadata_message(time_boot_ms & 0xFFFFFFFF, GENERAL_CRC, uri(GENERAL_PATH).encode())


def component_information(time_boot_ms: int) -> Any:
    """COMPONENT_INFORMATION (deprecated since 2022-04 for COMPONENT_METADATA; older ground stations ask for it): the
    same URI and CRC, no peripherals file."""
    return MAVLink_component_information_message(time_boot_ms & 0xFFFFFFFF, GENERAL_CRC, uri(GENERAL_PATH).encode(),
                                                  0, b"")


def register() -> None:
    """Add both messages to pymavlink's common dialect (idempotent), as :func:`bridge.mavlink.events.register`."""
    for cls in MESSAGES:
        mavlink.mavlink_map.setdefault(cls.id, cls)
