"""Fuzz: random bytes and mutated real frames into every decoder raise only WireError.

Seeds are the pinned real frames, mailbox frames read from the corpus (when present) and
SDO payloads built by our encoders. Mutations: bit flips, truncation, corrupted length
fields (EtherCAT header, datagram, mailbox, IPv4/UDP), random splices. 20 000 inputs in
all, deterministic (fixed seed). Whatever decode_frame accepts must encode back to the
very same bytes.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from test_wire_pinned import (
    AKD_ARMW,
    AKD_EOE,
    DC_DIFFERENCE,
    EK1914_UPLOAD,
    FMMU0_WRITE,
    ISSUE_255_LRW,
    SCAN_BOXES_SII,
    SDO_ERROR_ABORT,
    SM0_WRITE,
)
from wire_corpus import PCAPS, read_packets

from lolacli.errors import WireError
from lolacli.wire.coe import decode_coe_header, decode_emergency
from lolacli.wire.frame import (
    decode_any,
    decode_datagrams,
    decode_ecat_payload,
    decode_frame,
    encode_frame,
)
from lolacli.wire.mailbox import decode_mailbox, decode_mailbox_error, decode_mailbox_header
from lolacli.wire.registers import (
    decode_fmmu,
    decode_fmmus,
    decode_sync_manager,
    decode_sync_managers,
    decode_system_time_difference,
)
from lolacli.wire.sdo import decode_sdo
from lolacli.wire.udp import decode_udp_frame

DECODERS: list[Callable[[bytes], object]] = [
    decode_frame,
    decode_any,
    decode_udp_frame,
    decode_datagrams,
    decode_ecat_payload,
    lambda b: decode_ecat_payload(b, 14),
    decode_mailbox,
    decode_mailbox_header,
    decode_mailbox_error,
    decode_coe_header,
    decode_emergency,
    decode_sdo,
    decode_fmmu,
    decode_fmmus,
    decode_sync_manager,
    decode_sync_managers,
    decode_system_time_difference,
]

PINNED = [
    ISSUE_255_LRW, SCAN_BOXES_SII, SDO_ERROR_ABORT, EK1914_UPLOAD, AKD_ARMW, AKD_EOE,
    DC_DIFFERENCE, SM0_WRITE, FMMU0_WRITE,
]
UDP_FRAME = bytes.fromhex(  # built by encode_frame: FPRD 0x0130 + LRW over IPv4/UDP
    "ffffffffffff02000000000008004500003c000000004011f65fc0a80102c0a801ff88a488a400280000"
    "1e1004070110300102800000000001000c080000010004000000616263640300"
)
SDO_PAYLOADS = [
    bytes.fromhex(h)
    for h in (
        "00202f60600008000000",  # download expedited
        "0020210020010a000000303132333435363738",  # download normal
        "00201961626300000000",  # download segment
        "00300168656c6c6f20776f726c64",  # upload segment response
        "0080010000000100",  # OD list request
        "0080040000001810230004096964",  # object description response
        "008006000000181001000700200007005678",  # entry description response
        "0080070000000000020600",  # SDO info error
        "0010308111010203040500",  # emergency
    )
]


def _corpus_seeds(limit: int = 40) -> list[bytes]:
    seeds: list[bytes] = []
    for path in PCAPS:
        if "sdo-error" in path.name or "dual-lan9252" in path.name or "sii-el2004" in path.name:
            seeds.extend(read_packets(path)[200 : 200 + limit])
    return seeds


def _mutate(rng: random.Random, data: bytes) -> bytes:
    buf = bytearray(data)
    kind = rng.randrange(5)
    if kind == 0 and buf:  # bit flips
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(buf))
            buf[i] ^= 1 << rng.randrange(8)
    elif kind == 1:  # truncation
        del buf[rng.randrange(len(buf) + 1) :]
    elif kind == 2 and len(buf) >= 2:  # corrupt a plausible length field
        spots = [i for i in (0, 14, 16, 22, 24, 28, 30) if i + 2 <= len(buf)]
        i = rng.choice(spots)
        buf[i : i + 2] = rng.randrange(0x10000).to_bytes(2, "little")
    elif kind == 3:  # splice random bytes
        i = rng.randrange(len(buf) + 1)
        buf[i:i] = rng.randbytes(rng.randint(1, 8))
    else:  # random bytes with a real prefix
        buf = buf[: rng.randrange(len(buf) + 1)] + bytearray(rng.randbytes(rng.randint(0, 40)))
    return bytes(buf)


def _only_wire_errors(data: bytes) -> None:
    for decode in DECODERS:
        try:
            decode(data)
        except WireError:
            pass
    try:
        frame = decode_frame(data)
    except WireError:
        return
    assert encode_frame(frame) == data


def test_random_bytes_raise_only_wire_error() -> None:
    rng = random.Random(20261122)
    for _ in range(6000):
        _only_wire_errors(rng.randbytes(rng.randint(0, 80)))


def test_mutated_real_frames_raise_only_wire_error() -> None:
    rng = random.Random(88)
    seeds = PINNED + [UDP_FRAME] + _corpus_seeds()
    for _ in range(10000):
        _only_wire_errors(_mutate(rng, rng.choice(seeds)))


def test_mutated_coe_payloads_raise_only_wire_error() -> None:
    rng = random.Random(301)
    for _ in range(4000):
        _only_wire_errors(_mutate(rng, rng.choice(SDO_PAYLOADS)))


def test_udp_seed_is_valid() -> None:
    frame = decode_any(UDP_FRAME)
    assert frame.udp is not None and frame.udp.ip_checksum is None
    assert [d.mnemonic for d in frame.datagrams] == ["FPRD", "LRW"]
