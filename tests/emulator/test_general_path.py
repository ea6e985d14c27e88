"""The chain's general path against the reference order: every slave in line processes
every datagram as the frame passes it (slave-major), each through ``Esc.process``.

The general path runs a frame datagram by datagram and sends a single-slave datagram
straight to its slave (configured addresses from a cached map); it must give the same
reply bytes and leave the same slave memories for any frame, addresses written in the
same frame included.
"""

from __future__ import annotations

import functools
import random
import struct
from collections.abc import Callable

import pytest

from lolacli.emulator.chain import Chain
from lolacli.emulator.core import core_available
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from tests.emulator.bus import EXAMPLES

_SINGLE_AUTO = {C.APRD, C.APWR, C.APRW}
_SINGLE_CONFIGURED = {C.FPRD, C.FPWR, C.FPRW}


def reference_process(chain: Chain, frame: bytes, t_ns: int) -> bytes:
    """Slave-major: each slave in line order runs every datagram through Esc.process."""
    decoded = decode_frame(frame)
    buf = bytearray(frame)
    pos = 16
    slots = []
    for d in decoded.datagrams:
        slots.append([pos, d.cmd, d.adp, d.ado, len(d.data), 0, False])
        pos += 12 + len(d.data)
    view = memoryview(buf)
    for esc, port in zip(chain._active, chain._port_offsets, strict=False):
        esc.frame_t_ns = t_ns
        esc.port_offsets = port
        for slot in slots:
            header, cmd, adp, ado, n = slot[:5]
            data = view[header + 10 : header + 10 + n]
            if cmd in _SINGLE_CONFIGURED:
                # the first slave in line that has the address when the frame reaches it
                if slot[6] or not esc.addressed_configured(adp):
                    continue
                slot[6] = True
            slot[2], added = esc.process(cmd, adp, ado, data, t_ns + port.port0_ns)
            slot[5] += added
    for header, _cmd, adp, _ado, n, added, _taken in slots:
        struct.pack_into("<H", buf, header + 2, adp)
        (wkc,) = struct.unpack_from("<H", buf, header + 10 + n)
        struct.pack_into("<H", buf, header + 10 + n, (wkc + added) & 0xFFFF)
    view.release()
    chain.tick(t_ns)
    chain.run_deferred_cycles()
    if any(s[1] in (C.LRD, C.LWR, C.LRW) for s in slots):
        for esc in chain._active:
            esc.cycle(t_ns)
    buf[6] |= 0x02
    return bytes(buf)


_REGISTERS = [0x0000, 0x0010, 0x0012, 0x0100, 0x0103, 0x0110, 0x0130, 0x0134, 0x0300]
_REGISTERS += [0x0502, 0x0508, 0x0600, 0x0800, 0x0805, 0x080D, 0x0900, 0x0910, 0x0920, 0x0F00]
_REGISTERS += [0x0308, 0x030C, 0x0310, 0x0400, 0x0410, 0x0420, 0x0440]  # counters, watchdogs


def _random_frame(rng: random.Random, slaves: int, stations: list[int]) -> bytes:
    datagrams = []
    for _ in range(rng.randrange(1, 5)):
        cmd = rng.choice(
            [C.APRD, C.APWR, C.APRW, C.FPRD, C.FPWR, C.FPRW, C.BRD, C.BWR, C.BRW, C.ARMW, C.FRMW]
        )
        ado = rng.choice(_REGISTERS) + rng.randrange(0, 4)
        length = rng.choice([1, 2, 4, 8, 16])
        if cmd in (C.APWR, C.FPWR, C.BWR, C.APRW, C.FPRW, C.BRW) and ado in (0x0120, 0x0121):
            ado = 0x0F00  # leave the AL state alone: the bring-up decides it
        data: bytes | int = rng.randbytes(length) if cmd not in (C.APRD, C.FPRD, C.BRD) else length
        if cmd in _SINGLE_AUTO or cmd == C.ARMW:
            adp = (-rng.randrange(0, slaves + 2)) & 0xFFFF
        elif cmd in _SINGLE_CONFIGURED or cmd == C.FRMW:
            adp = rng.choice(stations + [0x7777])
        else:
            adp = rng.randrange(0, 3)
        datagrams.append(Datagram.physical(cmd, adp, ado, data))
    return encode_frame(make_frame(datagrams), pad=rng.random() < 0.5)


_SINGLE = [C.APRD, C.APWR, C.FPRD, C.FPWR, C.APRD, C.APWR, C.FPRD, C.FPWR, C.BRD, C.BWR]
_WRITES = (C.APWR, C.FPWR, C.BWR)


def _eeprom_command(rng: random.Random) -> bytes:
    """SII control and address as a master writes them to 0x0502: mostly reads (the
    address inside the image or past it), sometimes no command, a write, a reload, an
    invalid command."""
    command = rng.choice([1, 1, 1, 1, 0, 2, 4, 3])
    address = rng.choice([rng.randrange(0, 0x100), rng.randrange(0, 1 << 32)])
    return struct.pack("<BBI", rng.randrange(0, 256) & 0x41, command, address)


def _single_slave_frame(
    rng: random.Random,
    slaves: int,
    stations: list[int],
    *,
    al_control: bool = False,
    addressing: bool = False,
) -> bytes:
    """Up to 15 APRD/FPRD/APWR/FPWR, BRD and BWR of registers, as a start-up's SM/FMMU
    set-up, SII reads and status polls (the C core's register path): FMMU and SM registers
    (mailbox SMs too), EEPROM commands, read-only bytes, registers with side effects, the
    DC system time, no data, unknown stations and positions past the end; with
    ``al_control``, AL state requests too; with ``addressing``, station addresses, aliases
    and the alias enable written (stations of the list given to other slaves, twice, or
    none), FPxx after them in the same frame."""
    datagrams = []
    for _ in range(rng.randrange(1, 16)):
        cmd = rng.choice(_SINGLE)
        area = rng.random()
        if cmd in _WRITES and area < 0.15:
            adp = _adp(rng, cmd, slaves, stations)
            datagrams.append(Datagram.physical(cmd, adp, 0x0502, _eeprom_command(rng)))
            continue
        if al_control and cmd in _WRITES and area < 0.22:  # a state request, acknowledged or not
            adp = _adp(rng, cmd, slaves, stations)
            request = rng.choice([1, 2, 4, 8, 3, 0x11, 0x12, 0x14, 0])
            datagrams.append(Datagram.physical(cmd, adp, 0x0120, bytes([request, 0])))
            continue
        if addressing and cmd in _WRITES and area < 0.3:
            adp = _adp(rng, cmd, slaves, stations)
            ado = rng.choice([0x0010, 0x0010, 0x0012, 0x0103, 0x0100, 0x0011])
            value = rng.choice(stations + [0x7777, 0])
            data = {
                0x0010: struct.pack("<H", value),
                0x0012: struct.pack("<H", value),
                0x0103: bytes([rng.randrange(0, 2)]),
                0x0100: bytes(rng.randrange(0, 2) for _ in range(4)),  # DL control
                0x0011: bytes([value & 0xFF]),
            }[ado]
            datagrams.append(Datagram.physical(cmd, adp, ado, data))
            continue
        if area < 0.35:
            ado, length = 0x0800 + 8 * rng.randrange(0, 17), rng.choice([1, 2, 8, 8, 16])
            if rng.random() < 0.2:
                ado += rng.randrange(0, 8)
        elif area < 0.6:
            ado, length = 0x0600 + 16 * rng.randrange(0, 16), rng.choice([16, 16, 4, 32])
        elif area < 0.7:
            ado, length = rng.randrange(0, 0x1000), rng.randrange(0, 24)
        else:
            ado, length = rng.choice(_REGISTERS) + rng.randrange(0, 4), rng.choice([1, 2, 4, 8])
        if cmd in _WRITES and 0x0120 <= ado + length and ado <= 0x0121:
            ado = 0x0F00  # leave the AL state alone: the bring-up decides it
        if cmd in _WRITES and ado <= 0x0011 < ado + length and not addressing:
            ado = 0x0F00  # and the station addresses
        if 0x0800 <= ado < 0x0880 and cmd in _WRITES and rng.random() < 0.5:
            data: bytes | int = bytes(length)  # an SM disabled: its mailbox full flag clears
        else:
            data = rng.randbytes(length) if cmd in _WRITES else length
        datagrams.append(Datagram.physical(cmd, _adp(rng, cmd, slaves, stations), ado, data))
    return encode_frame(make_frame(datagrams), pad=rng.random() < 0.5)


def _dc_frame(rng: random.Random, slaves: int, stations: list[int]) -> bytes:
    """Up to 6 datagrams of a master's DC set-up, as SOEM's and KickCAT's: the receive-time
    latch (a write into 0x0900-0x0903, by BWR to all or to one slave), the receive times
    and local times read back, the system time offset and delay written (small values and
    any 64-bit ones), the system time written to one or all (1-8 bytes, from 0x0910 or
    into it), writes across several of these at once, and other registers among them."""
    datagrams = []
    for _ in range(rng.randrange(1, 7)):
        cmd = rng.choice([C.BWR, C.BWR, C.APWR, C.FPWR, C.FPRD, C.APRD, C.BRD])
        kind = rng.random()
        if cmd in _WRITES:
            if kind < 0.3:
                ado, length = 0x0900 + rng.randrange(0, 4), rng.choice([1, 2, 4, 4])
                if rng.random() < 0.1:
                    ado, length = 0x08FE, 4  # from an SM's last registers into the latch
            elif kind < 0.6:
                ado = 0x0910 + rng.choice([0, 0, 0, 1, 4, 7])
                length = rng.choice([1, 2, 4, 4, 8, 8])
            elif kind < 0.85:
                ado, length = rng.choice([(0x0920, 8), (0x0928, 4), (0x0920, 12), (0x0924, 4)])
            else:
                ado, length = rng.choice([(0x0900, 48), (0x0910, 32), (0x08F8, 32)])
            value = rng.choice([rng.randbytes(length), bytes(length), b"\xff" * length])
            if ado <= 0x0920 < ado + length and rng.random() < 0.7:  # an offset of a few ms
                offset = struct.pack("<q", rng.randrange(-5_000_000, 5_000_000))
                at = 0x0920 - ado
                value = value[:at] + offset[: length - at] + value[at + 8 :]
            data: bytes | int = value[:length]
        else:
            ado, length = rng.choice([(0x0900, 16), (0x0918, 8), (0x092C, 4), (0x0920, 12)])
            data = length
        datagrams.append(Datagram.physical(cmd, _adp(rng, cmd, slaves, stations), ado, data))
    return encode_frame(make_frame(datagrams), pad=rng.random() < 0.5)


def _adp(rng: random.Random, cmd: int, slaves: int, stations: list[int]) -> int:
    if cmd in (C.APRD, C.APWR):
        return (-rng.randrange(0, slaves + 2)) & 0xFFFF
    if cmd in (C.FPRD, C.FPWR):
        return rng.choice(stations + [0x7777, 0])  # 0: the alias, where enabled
    return rng.randrange(0, 3)


def count_register_frames(chain: Chain) -> list[int]:
    """[frames the C core's register path answered] for ``chain``, counted from now."""
    taken = [0]
    core = chain._core
    if core is None:
        return taken
    answer = core.register_frame

    def counted(frame: bytes, t_ns: int):  # type: ignore[no-untyped-def]
        got = answer(frame, t_ns)
        taken[0] += got is not None
        return got

    core.register_frame = counted  # type: ignore[method-assign]
    return taken


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="no C core")),
    ],
)
@pytest.mark.parametrize("name", ["lola.xml", "ek1100_io.xml"])
def test_general_path_answers_like_the_slave_major_reference(name: str, engine: str) -> None:
    """(With the C core holding the slaves between cyclic frames: tests/emulator/test_core.py,
    ``register_traffic``.)"""
    _against_the_reference(name, engine, random.Random(11), _random_frame)


def _against_the_reference(
    name: str,
    engine: str,
    rng: random.Random,
    make: Callable[[random.Random, int, list[int]], bytes],
) -> int:
    """1500 frames of ``make`` through a chain of ``engine`` and the slave-major reference,
    after station addresses as a master gives them (``Chain.keep_warm`` now and then): the
    same replies, and every 100 frames the same memories, AL states and clocks. The frames
    the C core's register path took."""
    eni = load_eni(EXAMPLES / name)
    fast = build_chain(eni, drift_ppb=10, engine=engine)
    slow = build_chain(eni, drift_ppb=10, engine="python")
    fast.planner.plan_after = slow.planner.plan_after = 0
    stations = [s.station_address for s in eni.slaves]
    for chain in (fast, slow):  # station addresses first, as a master gives them
        for i, station in enumerate(stations):
            d = Datagram.physical(C.APWR, (-i) & 0xFFFF, 0x0010, struct.pack("<H", station))
            chain.process(encode_frame(make_frame([d]), pad=True), 0)
    taken = count_register_frames(fast)
    t_ns = 1_000_000
    for k in range(1500):
        frame = make(rng, len(eni.slaves), stations)
        t_ns += rng.randrange(1000, 200_000)
        if k % 10 == 5:
            fast.keep_warm()  # a quiet server's: it changes nothing
        got, _ = fast.process(frame, t_ns)
        want = reference_process(slow, frame, t_ns)
        assert got == want, f"frame {k}: {frame.hex()}"
        if k % 100 == 0:
            for i, (a, b) in enumerate(zip(fast.slaves, slow.slaves, strict=True)):
                assert a.mem == b.mem, f"frame {k}, slave {i}"
                assert a.al_state == b.al_state and a.clock == b.clock, f"frame {k}, slave {i}"
                mailbox = ("_mailbox_pending", "_mailbox_queue", "_last_mailbox_in")
                assert [getattr(a, m) for m in mailbox] == [getattr(b, m) for m in mailbox]
                assert a.current_watchdog_timeout_ns() == b.current_watchdog_timeout_ns()
    return taken[0]


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="no C core")),
    ],
)
@pytest.mark.parametrize("name", ["lola.xml", "ek1100_io.xml"])
def test_single_slave_register_frames_answer_like_the_slave_major_reference(
    name: str, engine: str
) -> None:
    """Frames of single-slave register datagrams only: with the C core, most of them take
    its register path (``ChainCore.register_frame``), the rest the Python general path."""
    taken = _against_the_reference(name, engine, random.Random(5), _single_slave_frame)
    if engine == "c":
        assert 300 < taken < 1400  # both paths ran
    with_requests = functools.partial(_single_slave_frame, al_control=True)
    taken = _against_the_reference(name, engine, random.Random(6), with_requests)
    if engine == "c":
        assert 300 < taken < 1400
    readdressed = functools.partial(_single_slave_frame, addressing=True)
    taken = _against_the_reference(name, engine, random.Random(7), readdressed)
    if engine == "c":
        assert 300 < taken < 1400


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="no C core")),
    ],
)
@pytest.mark.parametrize("name", ["lola.xml", "single_drive.xml"])
def test_dc_register_frames_answer_like_the_slave_major_reference(name: str, engine: str) -> None:
    """A master's DC set-up (latch, receive times, offsets and delays, system time written
    to one or all): with the C core, the register path answers the frames of them with
    the clocks of the slaves Python holds given to it and their corrections taken back
    (the slaves it holds: tests/emulator/test_core.py, ``register_traffic``)."""
    taken = _against_the_reference(name, engine, random.Random(9), _dc_frame)
    if engine == "c":
        assert taken > 1200  # all but the rare frame with a read of the system time


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="no C core")),
    ],
)
def test_a_sync_manager_disabled_forgets_its_full_mailbox_buffer(engine: str) -> None:
    """A master may make any SM a mailbox: written full, it stays full (the firmware serves
    the SII's mailbox SMs only) until the master disables it, which the register path
    does too."""
    eni = load_eni(EXAMPLES / "lola.xml")
    fast = build_chain(eni, engine=engine)
    slow = build_chain(eni, engine="python")
    station = eni.slaves[0].station_address
    taken = count_register_frames(fast)
    sm2 = struct.pack("<HHBBBB", 0x1C00, 4, 0x06, 0, 0x01, 0)  # mailbox, master writes
    steps = [
        Datagram.physical(C.APWR, 0, 0x0010, struct.pack("<H", station)),
        Datagram.physical(C.FPWR, station, 0x0810, sm2),
        Datagram.physical(C.FPWR, station, 0x1C00, b"\x01\x02\x03\x04"),  # full now
        Datagram.physical(C.FPRD, station, 0x0815, 1),
        Datagram.physical(C.FPWR, station, 0x0816, b"\x00"),  # disabled
        Datagram.physical(C.FPRD, station, 0x0815, 1),
    ]
    replies = []
    for k, d in enumerate(steps):
        frame = encode_frame(make_frame([d]), pad=True)
        got, _ = fast.process(frame, 1000 * k)
        assert got == reference_process(slow, frame, 1000 * k), f"step {k}"
        replies.append(decode_frame(got).datagrams[0].data)
    assert (replies[3][0] & 0x08, replies[5][0] & 0x08) == (0x08, 0)
    if engine == "c":
        assert taken[0] == 5  # all but the process RAM write


@pytest.mark.skipif(not core_available(), reason="no C core")
def test_eeprom_reads_of_four_bytes_in_the_register_path() -> None:
    """ESCs that read 4 bytes a command (SII status bit 6 clear): the register path's
    EEPROM reads, single and broadcast, give what the Python path gives."""
    from lolacli.emulator.esc import Esc
    from lolacli.emulator.esc.memory import EscConfig
    from lolacli.emulator.sii import SiiSpec, build_sii

    def chain(engine: str) -> Chain:
        config = EscConfig(eeprom_8_byte_reads=False)
        images = [build_sii(SiiSpec(f"s{p}", 2, p, 1, serial=p)) for p in (7, 8)]
        return Chain([Esc(image, config=config) for image in images], engine=engine)

    fast, slow = chain("c"), chain("python")
    taken = count_register_frames(fast)
    rng = random.Random(3)
    for k in range(200):
        cmd = rng.choice([C.APWR, C.BWR])
        adp = (-rng.randrange(0, 2)) & 0xFFFF if cmd == C.APWR else 0
        frame = encode_frame(
            make_frame(
                [
                    Datagram.physical(cmd, adp, 0x0502, _eeprom_command(rng)),
                    Datagram.physical(C.APRD, adp, 0x0502, 14),
                    Datagram.physical(C.BRD, 0, 0x0508, 8),
                ]
            ),
            pad=True,
        )
        got, _ = fast.process(frame, 1000 * k)
        assert got == slow.process(frame, 1000 * k)[0], f"frame {k}"
    assert [e.mem for e in fast.slaves] == [e.mem for e in slow.slaves]
    assert 100 < taken[0] < 200  # writes and reloads go to Python


@pytest.mark.skipif(not core_available(), reason="no C core")
def test_the_register_path_reads_an_sii_image_given_later() -> None:
    """``Chain.use_sii`` gives a slave another image: the register path's EEPROM reads
    (its line of SII images) read the new one, as the Python path does."""
    from lolacli.emulator.sii import SiiSpec, build_sii

    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    fast, slow = build_chain(eni, engine="c"), build_chain(eni, engine="python")
    taken = count_register_frames(fast)

    def read_word(chain: Chain, word: int) -> bytes:
        frame = encode_frame(
            make_frame(
                [
                    Datagram.physical(C.APWR, 0xFFFF, 0x0502, struct.pack("<BBI", 0, 1, word)),
                    Datagram.physical(C.APRD, 0xFFFF, 0x0508, 8),
                ]
            ),
            pad=True,
        )
        got, _ = chain.process(frame, 0)
        return decode_frame(got).datagrams[1].data

    before = read_word(fast, 0x0A)  # product code
    assert before == read_word(slow, 0x0A)
    image = build_sii(SiiSpec("other", 2, 0x12345678, 1))
    for chain in (fast, slow):
        chain.use_sii(2, image)
    after = read_word(fast, 0x0A)
    assert after == read_word(slow, 0x0A) != before
    assert after[:4] == struct.pack("<I", 0x12345678)
    assert taken[0] == 2
