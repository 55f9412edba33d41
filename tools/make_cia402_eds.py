"""Write configs/eds/orccadd-cia402.eds: the description of a generic CiA 402 servo drive (CiA 306
EDS format), the one the shipped CANopen configs name; and configs/eds/orccadd-cia402-ecat.eds,
the same drive's CoE object dictionary on EtherCAT (the shipped EtherCAT configs).

The EtherCAT drive has no CANopen communication objects (SYNC, EMCY and heartbeat COB-IDs, PDO
communication parameters): its process data are the sync managers' (ETG.1000.6 5.6.7): the
communication types of the sync managers (0x1C00), the PDO assignment of SM2 and SM3 (0x1C12,
0x1C13), the synchronisation of each (0x1C32, 0x1C33: free run, SM-synchronous or DC SYNC0, the
cycle time) and one RxPDO and one TxPDO carrying every cyclic mode's target and the actual values
(the layout of common CiA 402 EtherCAT drives): controlword, target position, target velocity,
target torque, mode of operation; statusword, position, velocity and torque actual values, mode
display, error code.

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
OUT_ECAT = OUT.with_name("orccadd-cia402-ecat.eds")

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
CANOPEN_ONLY = frozenset({0x1005, 0x1006, 0x1014, 0x1017})
ECAT_RXPDO = ["0x60400010", "0x607A0020", "0x60FF0020", "0x60710010", "0x60600008", "0x00000008"]
ECAT_TXPDO = [
    *("0x60410010", "0x60640020", "0x606C0020", "0x60770010", "0x60610008", "0x00000008", "0x603F0010")
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


def sync_manager_objects() -> list[list[str]]:
    """0x1C00, 0x1C12, 0x1C13, 0x1C32, 0x1C33 of an EtherCAT CoE slave."""
    types = [var(0x1C00, 0, "Number of sync managers", U8, "ro", "4", False)] + [
        var(0x1C00, k + 1, f"Communication type SM{k}", U8, "ro", str(k + 1), False) for k in range(4)
    ]
    out = [record(0x1C00, "Sync manager communication type", types, object_type=0x8)]
    for index, what, pdo in ((0x1C12, "RxPDO", "0x1600"), (0x1C13, "TxPDO", "0x1A00")):
        subs = [var(index, 0, "Number of assigned PDOs", U8, "rw", "1", False, "0", "1"),
                var(index, 1, "PDO assigned 1", U16, "rw", pdo, False)]  # fmt: skip
        out.append(record(index, f"Sync manager {what} assign", subs, object_type=0x8))
    for index, what in ((0x1C32, "output"), (0x1C33, "input")):
        subs = [var(index, 0, "Highest sub-index supported", U8, "ro", "6", False),
                var(index, 1, "Synchronization type", U16, "rw", "1", False, "0", "2"),  # 1: SM-synchronous
                var(index, 2, "Cycle time", U32, "rw", "1000000", False),  # ns
                var(index, 3, "Shift time", U32, "ro", "0", False),
                var(index, 4, "Synchronization types supported", U16, "ro", "0x0007", False),
                var(index, 5, "Minimum cycle time", U32, "ro", "250000", False),
                var(index, 6, "Calc and copy time", U32, "ro", "0", False)]  # fmt: skip
        out.append(record(index, f"Sync manager {what} parameter", subs))
    return out


def eds(ethercat: bool = False) -> str:
    name = "orccadd-cia402-ecat.eds" if ethercat else "orccadd-cia402.eds"
    bus = "EtherCAT (CoE)" if ethercat else "CANopen"
    lines = [
        "; Written by tools/make_cia402_eds.py (see its docstring): a generic CiA 402 servo drive.",
        "[FileInfo]", f"FileName={name}", "FileVersion=1", "FileRevision=0", "EDSVersion=4.0",
        f"Description=Generic CiA 402 servo drive (CSP, CSV, CST) for orccadd's shipped {bus} configs",
        "CreatedBy=orccadd", "",
        "[DeviceInfo]", "VendorName=orccadd", "VendorNumber=0x00000000", "ProductName=Generic CiA 402 drive",
        "ProductNumber=0x00000402", "RevisionNumber=0x00000001", "OrderCode=orccadd-cia402",
        *(f"BaudRate_{b}=1" for b in (125, 250, 500, 1000)), "SimpleBootUpMaster=0", "SimpleBootUpSlave=1",
        "Granularity=8", "DynamicChannelsSupported=0", "GroupMessaging=0",
        f"NrOfRXPDO={1 if ethercat else 4}", f"NrOfTXPDO={1 if ethercat else 4}",
        "LSS_Supported=0", "",
        "[DummyUsage]", *(f"Dummy{d:04X}=0" for d in range(1, 8)), "",
        "[Comments]", "Lines=0", "",
    ]  # fmt: skip
    objects: list[list[str]] = []
    for index, title, dtype, access, default, pdo, low, high in VARS:
        if not (ethercat and index in CANOPEN_ONLY):
            objects.append(var(index, None, title, dtype, access, default, pdo, low, high))
    consumer = [var(0x1016, 0, "Number of entries", U8, "ro", "2", False)] + [
        var(0x1016, k, f"Consumer Heartbeat Time {k}", U32, "rw", "0", False, "0", "0x007FFFFF")
        for k in (1, 2)
    ]
    if not ethercat:
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
    if ethercat:
        objects.append(pdo_map(0x1600, "RxPDO 1 mapping", ECAT_RXPDO))
        objects.append(pdo_map(0x1A00, "TxPDO 1 mapping", ECAT_TXPDO))
        objects += sync_manager_objects()
    for n in range(0 if ethercat else 4):
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
    for out, text in ((OUT, eds()), (OUT_ECAT, eds(ethercat=True))):
        if "--check" in sys.argv[1:]:
            if not out.exists() or out.read_text() != text:
                return 1
            continue
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
