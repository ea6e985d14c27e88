"""Acceptance, CANopen: ``lolacli sdo`` in one process, a canopen LocalNode serving an EDS in
another (``lolacli sdo serve``), joined by python-can's udp_multicast bus in a private
network namespace (see tests/sdo/multicast.py).

For every corpus EDS, every readable object with a default value is read back as that
value (one ``sdo check`` run per EDS; canopen's own LocalNode.get_data in this process is
the oracle of what the node answers); single ``sdo read`` runs cover the usual objects;
the gateway's sensor nodes take writes and give the three aborts in human and JSON form.
"""

from __future__ import annotations

import json
import time

import pytest

from lolacli.sdo.node import example_eds
from tests.conftest import corpus_files, corpus_ids
from tests.sdo.multicast import CAN, namespace, run, serving

pytestmark = [pytest.mark.root]

EDS = corpus_files("eds")
NODE = 5


@pytest.fixture(scope="module")
def ns():
    with namespace() as name:
        yield name


def _expected(path) -> tuple[list[dict], dict[str, bytes]]:
    """Check-file reads for every readable entry with a default, and the bytes canopen's
    LocalNode (the node of the other process) answers for each."""
    import canopen
    from canopen.objectdictionary import ODVariable
    from canopen.sdo.exceptions import SdoAbortedError

    from lolacli.sdo.client import json_value

    od = canopen.objectdictionary.import_od(str(path), NODE)
    node = canopen.LocalNode(NODE, od)
    reads, raw = [], {}
    for index in od:
        obj = od[index]
        variables = [obj] if isinstance(obj, ODVariable) else [obj[s] for s in obj.subindices]
        for var in variables:
            default = var.value if var.value is not None else var.default
            if not var.readable or default is None:
                continue
            where = f"0x{var.index:04X}:{var.subindex:02X}"
            item: dict = {"object": where}
            try:
                data = node.get_data(var.index, var.subindex, check_readable=True)
            except SdoAbortedError as exc:
                item["expect_abort"] = f"0x{exc.code:08X}"
            except Exception:  # the server answers any other failure with a general error
                item["expect_abort"] = "0x08000000"
            else:
                if not data:
                    item["expect_abort"] = "0x08000024"  # no data available
                else:
                    raw[where] = data
                    item["expect"] = json_value(
                        bytes(default) if isinstance(default, bytearray) else default
                    )
            reads.append(item)
    return reads, raw


@pytest.mark.parametrize("path", EDS, ids=corpus_ids(EDS))
def test_every_default_of_every_corpus_eds_reads_back(ns, path, tmp_path, corpus) -> None:
    reads, raw = _expected(path)
    assert len(raw) >= 50, "too few objects with defaults to mean anything"
    check = tmp_path / "check.json"
    check.write_text(json.dumps({"slave": NODE, "reads": reads}))
    with serving(ns, "--eds", str(path), "--node", str(NODE)):
        code, out, err = run(ns, "sdo", "check", str(check), *CAN, "--eds", str(path), "-f", "json")
    doc = json.loads(out)
    failed = [r for r in doc["results"] if not r["ok"]]
    assert code == 0 and not failed, (err, failed[:5])
    assert doc["checks"] == len(reads)
    for result in doc["results"]:
        if result["object"] in raw:
            assert bytes.fromhex(result["raw_hex"]) == raw[result["object"]], result


@pytest.mark.parametrize("path", EDS, ids=corpus_ids(EDS))
def test_single_reads_of_the_usual_objects(ns, path, corpus) -> None:
    """0x1000, 0x1018:01, the device name where the EDS gives them defaults, and one object
    longer than 4 bytes (a segmented upload), each a `lolacli sdo read --can` process, as
    a CI script calls it."""
    _reads, raw = _expected(path)
    wanted = [w for w in ("0x1000:00", "0x1018:01", "0x1008:00") if w in raw]
    wanted += [w for w, data in raw.items() if len(data) > 4][:1]
    wanted = wanted or list(raw)[:2]
    with serving(ns, "--eds", str(path), "--node", str(NODE)):
        for where in wanted:
            code, out, err = run(
                ns, "sdo", "read", str(NODE), where, *CAN, "--eds", str(path), "-f", "json"
            )
            assert code == 0, err
            doc = json.loads(out)
            assert bytes.fromhex(doc["raw_hex"]) == raw[where]
            assert doc["schema"] == "lolacli.sdo/1" and doc["slave"] == str(NODE)


def test_gateway_sensor_nodes(ns) -> None:
    imu, fts = str(example_eds("lola_imu.eds")), str(example_eds("lola_fts.eds"))
    with serving(ns, "--gateway"):
        code, out, _ = run(ns, "sdo", "read", "16", "0x1008", *CAN, "-f", "json")
        assert code == 0 and json.loads(out)["value"] == "LOLA IMU (CAN gateway)"
        code, out, _ = run(ns, "sdo", "read", "18", "0x2021:03", *CAN, "--eds", fts)
        assert code == 0 and "REAL32 = 1500.0" in out
        code, out, _ = run(ns, "sdo", "read", "17", "0x6020:01", *CAN, "--eds", fts, "-f", "json")
        assert code == 0 and abs(json.loads(out)["value"]) <= 100.0
        # write, then read back in another process
        assert run(ns, "sdo", "write", "16", "0x2000", "500", *CAN, "--eds", imu)[0] == 0
        code, out, _ = run(ns, "sdo", "read", "16", "0x2000", *CAN, "--eds", imu, "-f", "json")
        assert code == 0 and json.loads(out)["value"] == 500
        # the three aborts, human (stderr) and JSON (stdout)
        for args, abort in (
            (("read", "16", "0x2345"), "0x06020000"),
            (("write", "16", "0x1000", "1"), "0x06010002"),
            (("write", "16", "0x2000", "1", "--type", "UNSIGNED32"), "0x06070010"),
        ):
            code, out, err = run(ns, "sdo", *args, *CAN)
            assert code == 1 and abort in err, (args, err)
            code, out, err = run(ns, "sdo", *args, *CAN, "-f", "json")
            doc = json.loads(out)
            assert code == 1 and doc["error"]["abort_code"] == abort
            assert doc["error"]["message"] and doc["schema"] == "lolacli.sdo/1"


def test_a_node_that_does_not_answer_is_exit_4(ns) -> None:
    with serving(ns, "--gateway"):
        start = time.monotonic()
        code, _out, err = run(ns, "sdo", "read", "99", "0x1000", *CAN, "--timeout", "0.3")
        assert code == 4 and "no answer" in err
        assert time.monotonic() - start < 10
