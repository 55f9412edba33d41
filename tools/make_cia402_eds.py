"""Write configs/eds/orccadd-cia402.eds: the description of a generic CiA 402 servo drive (CiA 306
EDS format), the one the shipped CANopen configs name.

A real drive comes with its vendor's EDS/DCF (put it next to the robot config, or in a folder of
$ORCCADD_EDS_PATH, and name it in `axes[].eds`). This one describes what orccadd needs of a drive
and what the simulated drives (`python -m orccadd.drivesim`) then provide: the CiA 301
communication objects (heartbeat producer and two consumer entries, SYNC, EMCY, four RPDOs and
four TPDOs of up to eight mapped objects each) and the CiA 402 objects of cyclic synchronous
position, velocity and torque (CSP, CSV, CST). The tests keep using public descriptions written by
others (../shared/testdata/eds/) so that the driver is never checked only against our own file.

    python tools/make_cia402_eds.py          # rewrite the file
    python tools/make_cia402_eds.py --check  # exit 1 if it is out of date
"""

from __future__ import annotations

import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "configs" / "eds" / "orccadd-cia402.eds"

U8, U16, U32, I8, I16, I32, VSTR = 0x5, 0x6, 0x7, 0x2, 0x3, 0x4, 0x9

# (index, name, data type, access, default, PDO mappable, low, high)
VARS: list[tuple[int, str, int, str, str, bool, str, str]] = [
    (0x1000, "Device Type", U32, "ro", "0x00020192", False, "", ""),  # CiA 402, servo drive
    (0x1001, "Error Register", U8, "ro", "0", True, "", ""),
    (0x1005, "COB-ID SYNC", U32, "rw", "0x00000080", False, "", ""),
    (0x1006, "Communication Cycle Period", U32, "rw", "0", False, "", ""),
    (0x1014, "COB-ID EMCY", U32, "rw", "$NODEID+0x80", False, "", ""),
    (0x1017, "Producer Heartbeat Time", U16, "rw", "0", False, "", ""),
    (0x603F, "Error Code", U16, "ro", "0", True, "", ""),
    (0x6040, "Controlword", U16, "rw", "0", True, "", ""),
    (0x6041, "Statusword", U16, "ro", "0", True, "", ""),
    (0x605A, "Quick Stop Option Code", I16, "rw", "2", False, "-32768", "32767"),
    (0x6060, "Modes of Operation", I8, "rw", "8", True, "-128", "127"),
    (0x6061, "Modes of Operation Display", I8, "ro", "8", True, "", ""),
    (0x6064, "Position Actual Value", I32, "ro", "0", True, "", ""),
    (0x6065, "Following Error Window", U32, "rw", "0xFFFFFFFF", False, "", ""),
    (0x6066, "Following Error Time Out", U16, "rw", "0", False, "", ""),
    (0x606C, "Velocity Actual Value", I32, "ro", "0", True, "", ""),
    (0x6071, "Target Torque", I16, "rw", "0", True, "-32768", "32767"),
    (0x6076, "Motor Rated Torque", U32, "rw", "1000", False, "", ""),  # mN·m
    (0x6077, "Torque Actual Value", I16, "ro", "0", True, "", ""),
    (0x607A, "Target Position", I32, "rw", "0", True, "-2147483648", "2147483647"),
    (0x6085, "Quick Stop Deceleration", U32, "rw", "100000", False, "", ""),
    (0x60B2, "Torque Offset", I16, "rw", "0", True, "-32768", "32767"),
    (0x60FF, "Target Velocity", I32, "rw", "0", True, "-2147483648", "2147483647"),
    (0x6502, "Supported Drive Modes", U32, "ro", "0x00000380", False, "", ""),  # CSP, CSV, CST
]
DEFAULT_RPDO = {
    1: ["0x60400010", "0x607A0020"],
    2: ["0x60400010", "0x60FF0020"],
    3: ["0x60400010", "0x60710010"],
}
DEFAULT_TPDO = {
    1: ["0x60410010", "0x60640020"],
    2: ["0x60410010", "0x606C0020"],
    3: ["0x60410010", "0x60770010"],
}


def var(index: int, sub: int | None, name: str, dtype: int, access: str, default: str, pdo: bool,
        low: str = "", high: str = "") -> list[str]:  # fmt: skip
    head = f"[{index:04X}]" if sub is None else f"[{index:04X}sub{sub:X}]"
    lines = [head, f"ParameterName={name}", "ObjectType=0x7", f"DataType=0x{dtype:04X}",
             f"AccessType={access}", f"DefaultValue={default}", f"PDOMapping={int(pdo)}"]  # fmt: skip
    if low:
        lines.append(f"LowLimit={low}")
    if high:
        lines.append(f"HighLimit={high}")
    return [*lines, ""]


def record(index: int, name: str, subs: list[list[str]], object_type: int = 0x9) -> list[str]:
    return [f"[{index:04X}]", f"ParameterName={name}", f"ObjectType=0x{object_type:X}",
            f"SubNumber={len(subs)}", "", *(line for s in subs for line in s)]  # fmt: skip


def pdo_comm(index: int, name: str, cob: str, transmit: bool) -> list[str]:
    subs = [
        var(index, 0, "Highest sub-index supported", U8, "ro", "5" if transmit else "2", False),
        var(index, 1, "COB-ID", U32, "rw", cob, False),
        var(index, 2, "Transmission Type", U8, "rw", "1", False),  # synchronous, every SYNC
    ]
    if transmit:
        subs += [
            var(index, 3, "Inhibit Time", U16, "rw", "0", False),
            var(index, 5, "Event Timer", U16, "rw", "0", False),
        ]
    return record(index, name, subs)


def pdo_map(index: int, name: str, defaults: list[str]) -> list[str]:
    subs = [var(index, 0, "Number of mapped objects", U8, "rw", str(len(defaults)), False, "0", "8")]
    for k in range(1, 9):
        subs.append(
            var(
                index,
                k,
                f"Mapped object {k}",
                U32,
                "rw",
                defaults[k - 1] if k <= len(defaults) else "0",
                False,
            )
        )
    return record(index, name, subs)


def eds() -> str:
    lines = [
        "; Written by tools/make_cia402_eds.py (see its docstring): a generic CiA 402 servo drive.",
        "[FileInfo]", "FileName=orccadd-cia402.eds", "FileVersion=1", "FileRevision=0", "EDSVersion=4.0",
        "Description=Generic CiA 402 servo drive (CSP, CSV, CST) for orccadd's shipped CANopen configs",
        "CreatedBy=orccadd", "",
        "[DeviceInfo]", "VendorName=orccadd", "VendorNumber=0x00000000", "ProductName=Generic CiA 402 drive",
        "ProductNumber=0x00000402", "RevisionNumber=0x00000001", "OrderCode=orccadd-cia402",
        *(f"BaudRate_{b}=1" for b in (125, 250, 500, 1000)), "SimpleBootUpMaster=0", "SimpleBootUpSlave=1",
        "Granularity=8", "DynamicChannelsSupported=0", "GroupMessaging=0", "NrOfRXPDO=4", "NrOfTXPDO=4",
        "LSS_Supported=0", "",
        "[DummyUsage]", *(f"Dummy{d:04X}=0" for d in range(1, 8)), "",
        "[Comments]", "Lines=0", "",
    ]  # fmt: skip
    objects: list[list[str]] = []
    for index, name, dtype, access, default, pdo, low, high in VARS:
        objects.append(var(index, None, name, dtype, access, default, pdo, low, high))
    consumer = [var(0x1016, 0, "Number of entries", U8, "ro", "2", False)] + [
        var(0x1016, k, f"Consumer Heartbeat Time {k}", U32, "rw", "0", False, "0", "0x007FFFFF")
        for k in (1, 2)
    ]
    objects.append(record(0x1016, "Consumer Heartbeat Time", consumer, object_type=0x8))
    identity = [var(0x1018, 0, "Highest sub-index supported", U8, "ro", "4", False)] + [
        var(0x1018, k, n, U32, "ro", "0", False)
        for k, n in ((1, "Vendor-ID"), (2, "Product code"), (3, "Revision number"), (4, "Serial number"))
    ]
    objects.append(record(0x1018, "Identity Object", identity))
    interp = [var(0x60C2, 0, "Highest sub-index supported", U8, "ro", "2", False),
              var(0x60C2, 1, "Interpolation time period value", U8, "rw", "1", False),
              var(0x60C2, 2, "Interpolation time index", I8, "rw", "-3", False, "-128", "63")]  # fmt: skip
    objects.append(record(0x60C2, "Interpolation Time Period", interp))
    for n in range(4):
        objects.append(
            pdo_comm(
                0x1400 + n, f"RPDO {n + 1} communication parameter", f"$NODEID+0x{0x200 + 0x100 * n:X}", False
            )
        )
        objects.append(pdo_map(0x1600 + n, f"RPDO {n + 1} mapping parameter", DEFAULT_RPDO.get(n + 1, [])))
        objects.append(
            pdo_comm(
                0x1800 + n, f"TPDO {n + 1} communication parameter", f"$NODEID+0x{0x180 + 0x100 * n:X}", True
            )
        )
        objects.append(pdo_map(0x1A00 + n, f"TPDO {n + 1} mapping parameter", DEFAULT_TPDO.get(n + 1, [])))
    indices = sorted({int(obj[0][1:5], 16) for obj in objects})
    mandatory = [0x1000, 0x1001, 0x1018]
    optional = [i for i in indices if i < 0x2000 and i not in mandatory]
    profile = [i for i in indices if i >= 0x6000]
    for title, group in (("MandatoryObjects", mandatory), ("OptionalObjects", [*optional, *profile])):
        lines += [
            f"[{title}]",
            f"SupportedObjects={len(group)}",
            *(f"{k}=0x{i:04X}" for k, i in enumerate(group, 1)),
            "",
        ]
    lines += ["[ManufacturerObjects]", "SupportedObjects=0", ""]
    for obj in sorted(objects, key=lambda o: o[0]):
        lines += obj
    return "\n".join(lines)


def main() -> int:
    text = eds()
    if "--check" in sys.argv[1:]:
        return 0 if OUT.exists() and OUT.read_text() == text else 1
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
