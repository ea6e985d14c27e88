#!/usr/bin/env python3
"""Write the EDS files of the LOLA CAN gateway's sensors (lolacli/eds_examples/*.eds).

Behind the chain's CAN gateway (ENI slave "CAN Gateway (IMU, FTS)") sit an IMU and two
foot force/torque sensors, each a CANopen node. Their process values here are the ones
the gateway maps to EtherCAT (0x6010:01–09 IMU, 0x6020:01–06 force/torque), so the same
names and types are seen from both sides. Run by hand after a change; output is
deterministic and committed:

    python tools/make_gateway_eds.py            # writes the files
    python tools/make_gateway_eds.py --check    # exits 1 if a committed file differs

Format: CiA 306 (EDS), objects as ``[IIII]`` / ``[IIIIsubN]`` sections.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

OUT_DIR = Path(__file__).resolve().parent.parent / "lolacli" / "eds_examples"
VENDOR = 0xE0000001  # the gateway's (private) vendor ID in lola.xml

U8, U16, U32, REAL32, STRING = 0x0005, 0x0006, 0x0007, 0x0008, 0x0009


@dataclass(frozen=True)
class Var:
    name: str
    data_type: int
    access: str = "ro"
    default: str | None = None
    pdo: bool = False


@dataclass(frozen=True)
class Obj:
    index: int
    name: str
    subs: tuple[Var, ...] = ()  # empty: a VAR given by ``var``
    var: Var | None = None
    array: bool = False


def _identity(product: int) -> Obj:
    return Obj(
        0x1018,
        "Identity object",
        (
            Var("Highest sub-index supported", U8, "const", "4"),
            Var("Vendor-ID", U32, "ro", f"0x{VENDOR:08X}"),
            Var("Product code", U32, "ro", f"0x{product:08X}"),
            Var("Revision number", U32, "ro", "0x00010000"),
            Var("Serial number", U32, "ro", "0x00002001"),
        ),
    )


def _communication(device_type: int, name: str, product: int) -> list[Obj]:
    return [
        Obj(0x1000, "Device type", var=Var("Device type", U32, "ro", f"0x{device_type:08X}")),
        Obj(0x1001, "Error register", var=Var("Error register", U8, "ro", "0", True)),
        Obj(
            0x1008,
            "Manufacturer device name",
            var=Var("Manufacturer device name", STRING, "const", name),
        ),
        Obj(
            0x1009,
            "Manufacturer hardware version",
            var=Var("Manufacturer hardware version", STRING, "const", "1.0"),
        ),
        Obj(
            0x100A,
            "Manufacturer software version",
            var=Var("Manufacturer software version", STRING, "const", "lolacli sensor node 1.0"),
        ),
        Obj(0x1017, "Producer heartbeat time", var=Var("Producer heartbeat time", U16, "rw", "0")),
        _identity(product),
        Obj(
            0x1200,
            "SDO server parameter",
            (
                Var("Highest sub-index supported", U8, "const", "2"),
                Var("COB-ID client to server", U32, "ro", "$NODEID+0x600"),
                Var("COB-ID server to client", U32, "ro", "$NODEID+0x580"),
            ),
        ),
    ]


def _tpdo(number: int, entries: list[int]) -> list[Obj]:
    comm = Obj(
        0x1800 + number,
        f"TPDO{number + 1} communication parameter",
        (
            Var("Highest sub-index supported", U8, "const", "5"),
            Var("COB-ID used by TPDO", U32, "rw", f"$NODEID+0x{0x180 + 0x100 * number:X}"),
            Var("Transmission type", U8, "rw", "0xFE"),
            Var("Inhibit time", U16, "rw", "0"),
            Var("Reserved", U8, "rw", "0"),
            Var("Event timer", U16, "rw", "1"),
        ),
    )
    mapping = Obj(
        0x1A00 + number,
        f"TPDO{number + 1} mapping parameter",
        (Var("Number of mapped objects", U8, "rw", str(len(entries))),)
        + tuple(
            Var(f"Mapped object {k + 1}", U32, "rw", f"0x{e:08X}") for k, e in enumerate(entries)
        ),
    )
    return [comm, mapping]


def _measured(index: int, name: str, names: list[str]) -> Obj:
    subs = (Var("Highest sub-index supported", U8, "const", str(len(names))),)
    subs += tuple(Var(n, REAL32, "ro", None, True) for n in names)
    return Obj(index, name, subs)


def _status() -> list[Obj]:
    return [
        Obj(0x6000, "Sensor status", var=Var("Sensor status", U16, "ro", "0", True)),
        Obj(0x6001, "Sample counter", var=Var("Sample counter", U16, "ro", None, True)),
    ]


IMU_VALUES = [
    "Angular rate X",
    "Angular rate Y",
    "Angular rate Z",
    "Acceleration X",
    "Acceleration Y",
    "Acceleration Z",
    "Roll",
    "Pitch",
    "Yaw",
]
FTS_VALUES = ["Force X", "Force Y", "Force Z", "Torque X", "Torque Y", "Torque Z"]


def imu() -> tuple[str, list[Obj]]:
    objects = _communication(0x0000019A, "LOLA IMU (CAN gateway)", 0x00000C11)
    objects += _tpdo(0, [0x60100120, 0x60100220]) + _tpdo(1, [0x60100320, 0x60100420])
    objects += [
        Obj(0x2000, "Sample rate", var=Var("Sample rate", U16, "rw", "1000")),
        Obj(
            0x2001,
            "Filter cut-off frequency",
            var=Var("Filter cut-off frequency", U16, "rw", "100"),
        ),
        Obj(0x2002, "Reset orientation", var=Var("Reset orientation", U8, "wo")),
        Obj(
            0x2010,
            "Gyro bias",
            (Var("Highest sub-index supported", U8, "const", "3"),)
            + tuple(Var(f"Gyro bias {a}", REAL32, "rw", "0") for a in "XYZ"),
            array=True,
        ),
        Obj(
            0x2100,
            "Serial number text",
            var=Var("Serial number text", STRING, "const", "LOLA-IMU-0001"),
        ),
    ]
    objects += _status()
    objects.append(_measured(0x6010, "IMU", IMU_VALUES))
    return "LOLA IMU behind the CAN gateway", objects


def fts() -> tuple[str, list[Obj]]:
    objects = _communication(0x00000194, "LOLA foot force/torque sensor (CAN gateway)", 0x00000C12)
    objects += _tpdo(0, [0x60200120, 0x60200220]) + _tpdo(1, [0x60200320, 0x60200420])
    matrix = tuple(
        Var(f"Calibration matrix {row + 1}{col + 1}", REAL32, "ro", "1.0" if row == col else "0.0")
        for row in range(6)
        for col in range(6)
    )
    ranges = ["500.0", "500.0", "1500.0", "50.0", "50.0", "50.0"]
    objects += [
        Obj(0x2000, "Sample rate", var=Var("Sample rate", U16, "rw", "1000")),
        Obj(
            0x2001,
            "Filter cut-off frequency",
            var=Var("Filter cut-off frequency", U16, "rw", "200"),
        ),
        Obj(0x2002, "Tare", var=Var("Tare", U8, "wo")),
        Obj(
            0x2020,
            "Calibration matrix",
            (Var("Highest sub-index supported", U8, "const", "36"),) + matrix,
            array=True,
        ),
        Obj(
            0x2021,
            "Full-scale range",
            (Var("Highest sub-index supported", U8, "const", "6"),)
            + tuple(
                Var(f"Range {n}", REAL32, "ro", r) for n, r in zip(FTS_VALUES, ranges, strict=True)
            ),
        ),
        Obj(
            0x2100,
            "Serial number text",
            var=Var("Serial number text", STRING, "const", "LOLA-FTS-0001"),
        ),
    ]
    objects += _status()
    objects.append(_measured(0x6020, "Force/torque", FTS_VALUES))
    return "LOLA foot force/torque sensor behind the CAN gateway", objects


def _var_lines(section: str, v: Var, object_type: int = 0x7) -> list[str]:
    lines = [
        f"[{section}]",
        f"ParameterName={v.name}",
        f"ObjectType=0x{object_type:X}",
        f"DataType=0x{v.data_type:04X}",
        f"AccessType={v.access}",
    ]
    if v.default is not None:
        lines.append(f"DefaultValue={v.default}")
    lines += [f"PDOMapping={1 if v.pdo else 0}", ""]
    return lines


def render(file_name: str, description: str, product: str, objects: list[Obj]) -> str:
    by_area = {"Mandatory": [], "Optional": [], "Manufacturer": []}
    for o in objects:
        if o.index in (0x1000, 0x1001, 0x1018):
            by_area["Mandatory"].append(o.index)
        elif 0x2000 <= o.index < 0x6000:
            by_area["Manufacturer"].append(o.index)
        else:
            by_area["Optional"].append(o.index)
    out = [
        "[FileInfo]",
        f"FileName={file_name}",
        "FileVersion=1",
        "FileRevision=0",
        "EDSVersion=4.0",
        f"Description={description}",
        "CreatedBy=lolacli tools/make_gateway_eds.py",
        "",
        "[DeviceInfo]",
        "VendorName=lolacli",
        f"VendorNumber=0x{VENDOR:08X}",
        f"ProductName={product}",
        "BaudRate_1000=1",
        "SimpleBootUpMaster=0",
        "SimpleBootUpSlave=1",
        "Granularity=8",
        "NrOfRXPDO=0",
        "NrOfTXPDO=2",
        "LSS_Supported=0",
        "",
    ]
    for area, indexes in by_area.items():
        out.append(f"[{area}Objects]")
        out.append(f"SupportedObjects={len(indexes)}")
        out += [f"{k + 1}=0x{i:04X}" for k, i in enumerate(indexes)]
        out.append("")
    for o in objects:
        if o.var is not None:
            out += _var_lines(f"{o.index:04X}", o.var)
            continue
        out += [
            f"[{o.index:04X}]",
            f"ParameterName={o.name}",
            f"ObjectType=0x{0x8 if o.array else 0x9:X}",
            f"SubNumber={len(o.subs)}",
            "",
        ]
        for sub, v in enumerate(o.subs):
            out += _var_lines(f"{o.index:04X}sub{sub:X}", v)
    return "\r\n".join(out)


FILES = {"lola_imu.eds": (imu, "LOLA IMU"), "lola_fts.eds": (fts, "LOLA FTS")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a file differs")
    args = parser.parse_args()
    differ = 0
    for name, (make, product) in FILES.items():
        description, objects = make()
        text = render(name, description, product, objects)
        path = OUT_DIR / name
        if args.check:
            if not path.exists() or path.read_bytes() != text.encode("ascii"):
                print(f"{path} differs")
                differ = 1
            continue
        path.write_bytes(text.encode("ascii"))
        print(f"{path}: {len(objects)} objects")
    return differ


if __name__ == "__main__":
    sys.exit(main())
