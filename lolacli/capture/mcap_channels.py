"""The MCAP channels lolacli writes: topic names and JSON schemas, one set for both
producers (``capture export --mcap`` and ``bus simulate --mcap``). No IO here: the
writers (:mod:`lolacli.capture.export`, :class:`lolacli.master.record.McapRecorder`)
register these with the ``mcap`` library's Writer.

Every channel has message encoding ``json`` and a ``jsonschema`` schema, which Foxglove
reads to offer each numeric field for plotting (``/cycle.round_trip_ns``). Topics:

``/frames``  one message per captured or sent/received frame: its bytes base64 in a JSON
             string (``contentEncoding: base64``, the form Foxglove's JSON schemas use for
             bytes), so that one file carries the wire data and the figures in one
             encoding; log time = the frame's timestamp.
``/cycle``   one message per cycle: round trip, period, WKC, lost frames. ``bus simulate``
             writes one per master cycle; ``capture export`` one per answered cyclic frame.
``/joints``  per-joint target and actual position (``bus simulate`` with drives).
``/dc``      DC system-time difference: ``max_error_ns`` the largest |difference|
             (simulate: over all DC slaves; capture: of one 0x092C read, ``error_ns``
             its sign).

Version 1 of ``/cycle`` and ``/dc`` (before ``capture export``) had a subset of these
fields; every field of it is kept with its meaning, the new ones are optional, so a
reader of the old files reads the new ones (schema names unchanged).
"""

from __future__ import annotations

import json
from typing import Any

FRAMES, CYCLE, JOINTS, DC = "/frames", "/cycle", "/joints", "/dc"

_INT = {"type": "integer"}
_INT_OR_NULL = {"type": ["integer", "null"]}

SCHEMAS: dict[str, dict[str, Any]] = {
    FRAMES: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "lolacli.frame",
        "description": "One Ethernet frame (EtherCAT), its bytes base64.",
        "type": "object",
        "properties": {
            "frame": {**_INT, "description": "frame number, 1-based (as Wireshark's)"},
            "t_ns": {**_INT, "description": "capture: its timestamp (ns since 1970); "
                                            "simulate: the transport's clock (ns)"},
            "length": {**_INT, "description": "bytes on the wire"},
            "returned": {"type": ["boolean", "null"],
                         "description": "came back from the bus (link layer: source MAC "
                                        "bit or packet type)"},
            "data": {"type": "string", "contentEncoding": "base64",
                     "description": "the captured bytes"},
        },
        "required": ["frame", "t_ns", "length", "data"],
    },
    CYCLE: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "lolacli.cycle",
        "description": "One cycle's figures.",
        "type": "object",
        "properties": {
            "cycle": {**_INT, "description": "cycle number"},
            "t_ns": {**_INT, "description": "capture: when the cyclic frame left; "
                                            "simulate: the master's clock at the cycle's "
                                            "end (ns)"},
            "frame": {**_INT_OR_NULL, "description": "capture: the cyclic frame's number"},
            "round_trip_ns": {**_INT_OR_NULL,
                              "description": "capture: this frame's; simulate: the last "
                                             "one measured"},
            "period_ns": {**_INT_OR_NULL,
                          "description": "since the previous message's t_ns (capture: "
                                         "the previous answered cyclic frame)"},
            "wkc": {"type": ["array", "null"], "items": _INT,
                    "description": "capture: working counter of each datagram of the "
                                   "returned frame"},
            "wkc_mismatches": {**_INT, "description": "WKC mismatches so far (simulate)"},
            "lost_frames": {**_INT, "description": "lost frames so far (simulate)"},
            "sections_ns": {"type": "object", "additionalProperties": _INT,
                            "description": "simulate --time-sections: per-section time"},
        },
        "required": ["cycle", "t_ns"],
    },
    JOINTS: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "lolacli.joints",
        "type": "object",
        "properties": {
            "cycle": _INT,
            "names": {"type": "array", "items": {"type": "string"}},
            "target": {"type": "array", "items": _INT},
            "actual": {"type": "array", "items": _INT},
        },
        "required": ["cycle"],
    },
    DC: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "lolacli.dc",
        "type": "object",
        "properties": {
            "t_ns": _INT,
            "max_error_ns": {**_INT, "description": "largest |system time difference|"},
            "error_ns": {**_INT_OR_NULL, "description": "capture: the signed difference"},
            "station": {**_INT_OR_NULL, "description": "capture: the slave read (FPRD)"},
        },
        "required": ["t_ns", "max_error_ns"],
    },
}


def register(writer: Any, topics: tuple[str, ...] | None = None) -> dict[str, int]:
    """Register the schemas and channels of ``topics`` (default: all) with an
    ``mcap.writer.Writer``; the channel id of each topic."""
    channels: dict[str, int] = {}
    for topic in topics if topics is not None else tuple(SCHEMAS):
        schema = SCHEMAS[topic]
        schema_id = writer.register_schema(
            name=str(schema["title"]), encoding="jsonschema", data=json.dumps(schema).encode()
        )
        channels[topic] = writer.register_channel(
            topic=topic, message_encoding="json", schema_id=schema_id
        )
    return channels


def encode(message: dict[str, Any]) -> bytes:
    """A message's JSON bytes (compact)."""
    return json.dumps(message, separators=(",", ":")).encode()


__all__ = ["CYCLE", "DC", "FRAMES", "JOINTS", "SCHEMAS", "encode", "register"]
