"""The SDO client API against canopen LocalNodes on python-can's virtual bus (one process):
typed reads and writes, segmented transfers, aborts, timeouts, and the CLI on the same bus."""

from __future__ import annotations

import itertools
import json
import math
import re

import pytest

from lolacli.errors import SdoAbortError, TransportError, UsageError
from lolacli.sdo import read, write
from lolacli.sdo.canopen_client import CanopenNetwork
from lolacli.sdo.files import load_eds
from lolacli.sdo.node import (
    FTS_LEFT_NODE,
    IMU_NODE,
    NodeServer,
    NodeSpec,
    example_eds,
    gateway_nodes,
)
from lolacli.wire.datatypes import DataType

_channels = itertools.count()


@pytest.fixture
def channel() -> str:
    return f"lolacli-test-{next(_channels)}"


@pytest.fixture
def gateway(channel: str):
    with NodeServer(channel, gateway_nodes(), interface="virtual") as server:
        yield server


@pytest.fixture
def network(channel: str, gateway):
    with CanopenNetwork(channel, interface="virtual", timeout_s=0.5) as net:
        yield net


def test_typed_reads_from_the_eds(network) -> None:
    fts = network.client(FTS_LEFT_NODE)
    od = load_eds(example_eds("lola_fts.eds"), FTS_LEFT_NODE)
    device_type = read(fts, 0x1000, 0, dictionary=od)
    assert (device_type.value, device_type.data_type, device_type.type_source) == (
        0x194,
        "UNSIGNED32",
        "eds",
    )
    name = read(fts, 0x1008, 0, dictionary=od)  # 43 bytes: segmented
    assert name.value == "LOLA foot force/torque sensor (CAN gateway)"
    assert read(fts, 0x2020, 1, dictionary=od).value == 1.0
    assert read(fts, 0x2021, 3, dictionary=od).value == 1500.0
    # $NODEID+0x600 resolved for this node
    assert read(fts, 0x1200, 1, dictionary=od).value == 0x600 + FTS_LEFT_NODE
    force = read(fts, 0x6020, 3, dictionary=od)
    assert force.data_type == "REAL32" and -100.0 <= force.value <= 100.0


def test_types_without_a_dictionary(network) -> None:
    imu = network.client(IMU_NODE)
    standard = read(imu, 0x1018, 2)  # CiA 301 identity: known without an EDS
    assert (standard.value, standard.type_source) == (0xC11, "cia301")
    guessed = read(imu, 0x2000, 0)
    assert (guessed.value, guessed.data_type, guessed.type_source) == (1000, "UNSIGNED16", "guess")
    assert "typed as UNSIGNED16 from its 2 bytes; give --type to choose" in guessed.note
    explicit = read(imu, 0x6010, 1, data_type=DataType.REAL32)
    assert explicit.type_source == "--type" and isinstance(explicit.value, float)
    text = read(imu, 0x2100, 0)  # printable bytes of a length no number has
    assert (text.value, text.data_type) == ("LOLA-IMU-0001", "VISIBLE_STRING")


def test_write_then_read(network) -> None:
    imu = network.client(IMU_NODE)
    od = load_eds(example_eds("lola_imu.eds"), IMU_NODE)
    written = write(imu, 0x2001, 0, "0x40", dictionary=od)
    assert (written.value, written.raw) == (64, b"\x40\x00")
    assert read(imu, 0x2001, 0, dictionary=od).value == 64
    write(imu, 0x2010, 2, "-0.25", dictionary=od)
    assert read(imu, 0x2010, 2, dictionary=od).value == -0.25
    with pytest.raises(UsageError, match="out of range for UNSIGNED16"):
        write(imu, 0x2001, 0, "70000", dictionary=od)
    with pytest.raises(UsageError, match="not known: give --type"):
        write(imu, 0x2001, 0, "1")  # no dictionary, not a standard object


@pytest.mark.parametrize(
    ("call", "code", "text"),
    [
        (lambda c: c.upload(0x2345, 0), 0x06020000, "object does not exist"),
        (lambda c: c.upload(0x1018, 9), 0x06090011, "subindex does not exist"),
        (lambda c: c.upload(0x2002, 0), 0x06010001, "write-only"),
        (lambda c: c.download(0x1000, 0, b"\0\0\0\0"), 0x06010002, "is read-only"),
        (lambda c: c.download(0x2001, 0, b"\0\0\0\0"), 0x06070010, "length mismatch"),
    ],
)
def test_aborts_carry_code_and_text(network, call, code, text) -> None:
    with pytest.raises(SdoAbortError) as exc:
        call(network.client(IMU_NODE))
    assert exc.value.code == code
    assert text in exc.value.text and f"0x{code:08X}" in str(exc.value)


def test_no_answer_is_a_transport_error(network) -> None:
    with pytest.raises(TransportError, match=r"node 99 .*no answer \(timeout 0.5 s\)"):
        network.client(99).upload(0x1000, 0)


def test_complete_access_is_refused_on_canopen(network) -> None:
    with pytest.raises(UsageError, match="complete access"):
        read(network.client(IMU_NODE), 0x1018, 0, complete_access=True)


def test_sensor_values_move(network) -> None:
    import time

    imu = network.client(IMU_NODE)
    first = read(imu, 0x6010, 1, data_type=DataType.REAL32).value
    time.sleep(0.05)
    second = read(imu, 0x6010, 1, data_type=DataType.REAL32).value
    assert first != second and all(math.isfinite(v) and abs(v) <= 10.0 for v in (first, second))


# --- the CLI, in process, on the same virtual bus ---------------------------------------------


def _can(channel: str) -> list[str]:
    return ["--can", channel, "--interface", "virtual", "--timeout", "0.5"]


def test_cli_read_json_and_human(cli, channel, gateway) -> None:
    eds = str(example_eds("lola_imu.eds"))
    code, out, _ = cli("sdo", "read", "16", "0x1008", *_can(channel), "--eds", eds, "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["schema"] == "lolacli.sdo/1"
    assert (doc["slave"], doc["index"], doc["subindex"]) == ("16", 0x1008, 0)
    assert doc["value"] == "LOLA IMU (CAN gateway)" and doc["data_type"] == "VISIBLE_STRING"
    assert bytes.fromhex(doc["raw_hex"]) == b"LOLA IMU (CAN gateway)"
    code, out, _ = cli("sdo", "read", "16", "1018:02", *_can(channel))
    assert code == 0
    assert "0x1018:02" in out and "UNSIGNED32 = 3089 (0x00000C11)" in out


def test_cli_abort_exit_1_human_and_json(cli, channel, gateway) -> None:
    code, out, err = cli("sdo", "read", "16", "0x2345", *_can(channel), "-f", "json")
    assert code == 1
    doc = json.loads(out)
    assert doc["error"] == {
        "abort_code": "0x06020000",
        "message": "object does not exist",
    }
    code, out, err = cli("sdo", "write", "16", "0x1000", "5", *_can(channel))
    assert code == 1 and out == ""
    assert "0x06010002" in err and "object is read-only" in err
    code, _out, err = cli("sdo", "write", "16", "0x2001", "5", "--type", "u32", *_can(channel))
    assert code == 1 and "0x06070010" in err


def test_cli_usage_and_transport_codes(cli, channel, gateway) -> None:
    assert cli("sdo", "read", "16", "0xZZ", *_can(channel))[0] == 2
    assert cli("sdo", "read", "200", "0x1000", *_can(channel))[0] == 2  # node ID > 127
    assert cli("sdo", "read", "16", "0x1000", *_can(channel), "--node", "17")[0] == 2
    assert cli("sdo", "read", "16", "0x1000", *_can(channel), "--type", "nope")[0] == 2
    assert cli("sdo", "read", "16", "0x1000", *_can(channel), "--complete")[0] == 2
    code, out, err = cli("sdo", "read", "42", "0x1000", *_can(channel), "-f", "json")
    assert code == 4
    assert json.loads(out)["error"]["abort_code"] is None and "no answer" in err + out
    code, _out, err = cli("sdo", "read", "16", "0x1000", "--can", "x", "--interface", "nosuch")
    assert code == 2 and "nosuch" in err


def test_cli_list_from_eds_needs_no_bus(cli) -> None:
    code, out, _ = cli("sdo", "list", "17", "--eds", str(example_eds("lola_fts.eds")), "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["schema"] == "lolacli.sdo-list/1" and doc["source"] == "eds"
    matrix = next(o for o in doc["objects"] if o["index"] == 0x2020)
    assert matrix["object_code"] == "ARRAY" and len(matrix["entries"]) == 37
    cob = next(o for o in doc["objects"] if o["index"] == 0x1200)["entries"][1]
    assert cob["default"] == 0x611 and cob["data_type"] == "UNSIGNED32"


def test_node_server_refuses_a_bad_eds_before_the_bus(tmp_path) -> None:
    from lolacli.errors import InputError

    bad = tmp_path / "bad.eds"
    bad.write_text("this is not an EDS\n")
    with pytest.raises(InputError, match="bad.eds"):
        NodeServer("unused", [NodeSpec(bad, 1)], interface="virtual")


def test_cli_options_of_the_other_bus_are_usage_errors(cli, channel, gateway, tmp_path) -> None:
    code, _out, err = cli("sdo", "list", "16", *_can(channel))
    assert code == 2 and "give --eds" in err
    code, _out, err = cli("sdo", "read", "16", "0x1000", *_can(channel), "--esi", str(tmp_path))
    assert code == 2 and "EtherCAT" in err
    code, _out, err = cli("sdo", "read", "1", "0x1000", "--backend", "soem")
    assert code == 2 and "--iface" in err
    code, _out, err = cli("sdo", "read", "1", "0x1000", "--backend", "twincat")
    assert code == 2 and "unknown --backend" in err


def test_node_specs_refuse_what_sdo_serve_cannot_serve(cli) -> None:
    from lolacli.sdo.node import example_eds, node_specs

    imu = example_eds("lola_imu.eds")
    assert [s.node_id for s in node_specs([imu], [5], gateway=True)] == [5, 16, 17, 18]
    for eds, ids, gateway, said in (
        ([imu], [], False, "1 --eds but 0 --node"),
        ([], [], False, "nothing to serve"),
        ([imu], [16], True, "node IDs given twice: [16, 16, 17, 18]"),
    ):
        with pytest.raises(UsageError, match=re.escape(said)):
            node_specs(eds, ids, gateway=gateway)
    code, out, err = cli("sdo", "serve", "--can", "x", "--interface", "virtual")
    assert (code, out) == (2, "")
    assert err == "lolacli: error: nothing to serve: give --eds FILE --node N, or --gateway\n"
