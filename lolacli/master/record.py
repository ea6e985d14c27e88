"""Recordings of a master's run: pcapng (every frame, both directions) and MCAP.

:class:`PcapngRecorder` is a transport tap: every frame the master sends and every frame
that comes back is one Enhanced Packet Block with a nanosecond timestamp (the transport's
clock: in simulation the chain's delay model), encoded by :mod:`lolacli.capture.writer`.
Blocks are written whole, one ``write`` each, so a file cut by Ctrl-C holds every frame
up to the last one written; closing flushes it.

:class:`McapRecorder` writes MCAP through the ``mcap`` library: JSON-schema channels
``/cycle`` (per-cycle timing, WKC, lost frames), ``/joints`` (per-joint target and actual
position), ``/dc`` (largest system time difference).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

from lolacli.capture.writer import epb, idb, shb
from lolacli.errors import UsageError


def open_output(path: str | Path) -> IO[bytes]:
    """Open ``path`` for writing; UsageError (exit 2, one line) when it cannot be."""
    try:
        return open(path, "wb")  # noqa: SIM115 - closed by the recorder
    except IsADirectoryError:
        raise UsageError(f"cannot write {path}: is a directory") from None
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


class PcapngRecorder:
    """A transport tap writing pcapng (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        self._file = open_output(path)
        self._file.write(shb() + idb(tsresol=9, snaplen=0))
        self.frames = 0

    def __call__(self, t_ns: int, frame: bytes, returned: bool) -> None:
        self._file.write(epb(t_ns, frame))
        self.frames += 1

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


_SCHEMAS: dict[str, dict[str, Any]] = {
    "/cycle": {
        "title": "lolacli.cycle",
        "type": "object",
        "properties": {
            "cycle": {"type": "integer"},
            "t_ns": {"type": "integer"},
            "round_trip_ns": {"type": ["integer", "null"]},
            "wkc_mismatches": {"type": "integer"},
            "lost_frames": {"type": "integer"},
            "sections_ns": {"type": "object", "additionalProperties": {"type": "integer"}},
        },
    },
    "/joints": {
        "title": "lolacli.joints",
        "type": "object",
        "properties": {
            "cycle": {"type": "integer"},
            "names": {"type": "array", "items": {"type": "string"}},
            "target": {"type": "array", "items": {"type": "integer"}},
            "actual": {"type": "array", "items": {"type": "integer"}},
        },
    },
    "/dc": {
        "title": "lolacli.dc",
        "type": "object",
        "properties": {"t_ns": {"type": "integer"}, "max_error_ns": {"type": "integer"}},
    },
}


class McapRecorder:
    """MCAP with JSON channels (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import Writer

        self.path = str(path)
        self._file = open_output(path)
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="lolacli")
        self._channels: dict[str, int] = {}
        for topic, schema in _SCHEMAS.items():
            schema_id = self._writer.register_schema(
                name=str(schema["title"]),
                encoding="jsonschema",
                data=json.dumps(schema).encode(),
            )
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id
            )
        self.messages = 0
        self._closed = False

    def write(self, topic: str, t_ns: int, message: dict[str, Any]) -> None:
        self._writer.add_message(
            channel_id=self._channels[topic],
            log_time=t_ns,
            publish_time=t_ns,
            data=json.dumps(message, separators=(",", ":")).encode(),
        )
        self.messages += 1

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._writer.finish()  # type: ignore[no-untyped-call]
            self._file.close()
