"""Just enough pcapng to get frame bytes out of a corpus capture (EPB and SPB blocks)."""

from __future__ import annotations

import struct
from pathlib import Path


def pcapng_frames(path: Path) -> list[bytes]:
    raw = path.read_bytes()
    order = "<" if raw[8:12] == b"\x4d\x3c\x2b\x1a" else ">"
    frames, pos = [], 0
    while pos + 12 <= len(raw):
        kind, length = struct.unpack_from(order + "II", raw, pos)
        if length < 12:
            break
        if kind == 6:  # enhanced packet block
            caplen = struct.unpack_from(order + "I", raw, pos + 20)[0]
            frames.append(raw[pos + 28 : pos + 28 + caplen])
        elif kind == 3:  # simple packet block
            frames.append(raw[pos + 12 : pos + length - 4])
        pos += length
    return frames
