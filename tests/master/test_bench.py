"""The bench verbs' library (lolacli.master.bench) in process against the emulated LOLA
chain (ChainTransport): what it reads is what each emulated ESC holds; EEPROM writes land
in the emulated EEPROM; states walk as the ESCs' AL state machines allow."""

from __future__ import annotations

import pytest

from lolacli.emulator.run import EmulateOptions, make_chain
from lolacli.errors import InputError, UsageError
from lolacli.files import load_eni
from lolacli.master import bench
from lolacli.master.transport import ChainTransport
from lolacli.wire.registers import AlState, Register, parse_register
from lolacli.wire.sii import crc8_sii, decode_sii_header
from tests.live import LOLA


@pytest.fixture(scope="module")
def eni():
    return load_eni(LOLA)


def _bus(eni, **faults):
    chain = make_chain(eni, EmulateOptions(**faults))
    return chain, bench.BenchBus(ChainTransport(chain))


@pytest.mark.parametrize(
    ("text", "span"),
    [
        ("al_status", (0x0130, 2, "al_status")),
        ("AL_STATUS:6", (0x0130, 6, "al_status")),
        ("0x300", (0x0300, 8, "rx_error_counter")),
        ("sm3", (0x0818, 8, "sm3")),
        ("fmmu15", (0x06F0, 16, "fmmu15")),
        ("0x1000:0x10", (0x1000, 16, "process_ram")),
        ("0x0131", (0x0131, 1, None)),
        ("0xFFFF", (0xFFFF, 1, None)),
    ],
)
def test_registers_by_number_and_name(text: str, span: tuple) -> None:
    got = parse_register(text)
    assert (got.address, got.length, got.name) == span


@pytest.mark.parametrize("text", ["0x10000", "0xFFFF:2", "al_stattus", "sm16", "0x10:0", "-1", ""])
def test_registers_outside_the_esc_are_usage_errors(text: str) -> None:
    with pytest.raises(UsageError):
        parse_register(text)


@pytest.mark.parametrize(
    ("current", "target", "steps"),
    [
        (AlState.INIT, AlState.OP, ["PREOP", "SAFEOP", "OP"]),
        (AlState.OP, AlState.PREOP, ["PREOP"]),
        (AlState.OP, AlState.BOOT, ["INIT", "BOOT"]),
        (AlState.BOOT, AlState.SAFEOP, ["INIT", "PREOP", "SAFEOP"]),
        (AlState.BOOT, AlState.INIT, ["INIT"]),
        (AlState.SAFEOP, AlState.SAFEOP, []),
    ],
)
def test_paths_follow_the_al_state_machine(current, target, steps) -> None:
    assert [s.name for s in bench.path(current, target)] == steps


def test_state_names() -> None:
    assert bench.parse_state_name("safe-op") is AlState.SAFEOP
    assert bench.parse_state_name("Bootstrap") is AlState.BOOT
    with pytest.raises(UsageError, match="does not exist"):
        bench.parse_state_name("OPERATIONAL")


def test_images_read_are_what_the_escs_hold(eni) -> None:
    chain, bus = _bus(eni)
    for s in bus.slaves:
        image = bench.read_image(bus, s)
        assert image == bytes(chain.slaves[s.position - 1].sii[: len(image)])
        doc = bench.describe_sii(image)
        want = eni.slaves[s.position - 1]
        assert doc["general"]["name"] == want.name and doc["checksum_ok"]
        assert doc["identity"]["product_code"] == want.identity.product_code
        bits = sum(p["bits"] for p in doc["rx_pdos"] if p["sync_manager"] is not None)
        assert bits == want.outputs_bits, s.position


def test_alias_lands_in_the_eeprom_with_its_checksum(eni) -> None:
    chain, bus = _bus(eni)
    s = bus.slaves[6]
    change = bench.set_alias(bus, s, 0xBEEF)
    sii = bytes(chain.slaves[6].sii)
    header = decode_sii_header(sii)
    assert (header.station_alias, header.checksum_ok) == (0xBEEF, True)
    assert change.register == 0xBEEF and change.previous == 0
    assert bench.read_register(bus, s, parse_register("station_alias")) == b"\xef\xbe"


def test_image_checks(eni) -> None:
    _chain, bus = _bus(eni)
    current = bench.read_image(bus, bus.slaves[0])
    bench.check_image(current, current)
    aliased = bench.with_alias(current, 7)
    assert crc8_sii(aliased[:14]) == aliased[14]
    bench.check_image(aliased, current)
    bad = bytearray(current)
    bad[14] ^= 1
    with pytest.raises(InputError, match="checksum"):
        bench.check_image(bytes(bad), current)
    bench.check_image(bytes(bad), current, force=True)
    with pytest.raises(InputError, match="not an SII image"):
        bench.check_image(current[:100], current, force=True)
    other = bench.read_image(bus, bus.slaves[23])  # the GPIO terminal
    with pytest.raises(InputError, match="identity"):
        bench.check_image(other, current)


def test_states_up_down_and_a_refusal(eni) -> None:
    chain, bus = _bus(eni, stuck_safeop=(5,))
    results = bench.request_states(bus, bus.slaves, AlState.OP)
    refused = [(r.slave.position, r.refused, r.al_status_code) for r in results if not r.ok]
    assert refused == [(5, "SAFEOP -> OP", 0x0019)]
    assert [chain.slaves[k].al_state for k in range(25) if k != 4] == [AlState.OP] * 24
    down = bench.request_states(bus, bus.slaves, AlState.INIT)
    assert all(r.ok for r in down)
    assert {chain.slaves[k].al_state for k in range(25)} == {AlState.INIT}


class _LaggingFirmware:
    """The chain as a real-time emulator answers it: frames first, the slaves' firmware
    (AL control requests among it) only after every ``lag``-th frame."""

    def __init__(self, chain, lag: int) -> None:
        self.chain, self.lag, self.frames = chain, lag, 0

    def process(self, frame: bytes, t_ns: int):
        answer = self.chain.process(frame, t_ns, defer_cycles=True)
        self.frames += 1
        if self.frames % self.lag == 0:
            self.chain.run_deferred_cycles()
        return answer


@pytest.mark.parametrize("lag", [1, 2, 5])
def test_an_acknowledged_error_still_showing_is_no_refusal(eni, lag: int) -> None:
    """A refusal leaves INIT+ERR; the next request acknowledges it, and until the
    firmware takes the request in, the status still reads INIT+ERR: no second refusal."""
    chain = make_chain(eni, EmulateOptions())
    bus = bench.BenchBus(ChainTransport(_LaggingFirmware(chain, lag)))
    gpio = [s for s in bus.slaves if eni.slaves[s.position - 1].mailbox is None]
    boot = bench.request_states(bus, gpio, AlState.BOOT)
    assert [(r.refused, r.al_status_code) for r in boot] == [("INIT -> BOOT", 0x0013)] * len(gpio)
    again = bench.request_states(bus, gpio, AlState.INIT)
    assert [(r.ok, r.refused) for r in again] == [(True, None)] * len(gpio)
    assert set(chain.al_statuses()[s.position - 1] for s in gpio) == {AlState.INIT}
    bench.request_states(bus, gpio, AlState.BOOT)
    twice = bench.request_states(bus, gpio, AlState.BOOT)  # refused again: no change shows
    assert [r.refused for r in twice] == ["INIT -> BOOT"] * len(gpio)
    assert not any(r.timed_out for r in twice)


def test_a_configuration_register_of_a_running_slave_needs_force(eni) -> None:
    _chain, bus = _bus(eni)
    s = bus.slaves[2]
    bench.request_states(bus, [s], AlState.SAFEOP)
    bus.refresh([s])
    span = parse_register("sm2")
    before = bench.read_register(bus, s, span)
    with pytest.raises(UsageError, match="--force"):
        bench.write_register(bus, s, span, bytes(8))
    assert bench.read_register(bus, s, span) == before
    assert bench.write_register(bus, s, parse_register("0x0F80:2"), b"\x12\x34") == b"\x12\x34"
    fields = bench.decode_registers(Register.AL_STATUS, b"\x04\x00\x00\x00\x1b\x00")
    assert [(f.name, f.text) for f in fields] == [
        ("al_status", "SAFEOP"), ("al_status_code", "0x001B Sync manager watchdog")
    ]  # fmt: skip
