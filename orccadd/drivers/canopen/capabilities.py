"""What a drive can do, read from its object dictionary (EDS/DCF) before anything starts.

A cyclic synchronous mode needs its target object and its actual value mapped into PDOs:

    csp  0x607A target position  -> 0x6064 position actual value
    csv  0x60FF target velocity  -> 0x606C velocity actual value
    cst  0x6071 target torque    -> 0x6077 torque actual value

plus 0x6040 controlword, 0x6041 statusword and 0x6060/0x6061 modes of operation. A description
that lacks one of them cannot do that mode: `require` says so with the file and the object.
0x6502 (supported drive modes) is only a hint here (its default in an EDS is often stale); the
driver reads the drive's own value at startup.

`consumer_entry` finds the heartbeat consumer entry (0x1016) the controller's heartbeat can take
in a description, or says what the description lacks for it.
"""

from __future__ import annotations

import copy
import functools
import os
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen.objectdictionary import ODArray, ODRecord

from orccadd.drivers.canopen.cia402 import MODE_CSP, MODE_CST, MODE_CSV

MODES: dict[str, tuple[int, int, int]] = {  # name -> (target, actual, 0x6502 bit)
    "csp": (0x607A, 0x6064, 7),
    "csv": (0x60FF, 0x606C, 8),
    "cst": (0x6071, 0x6077, 9),
}
MODE_NAMES = {
    "csp": "cyclic synchronous position",
    "csv": "cyclic synchronous velocity",
    "cst": "cyclic synchronous torque",
}
MODE_CODES = {"csp": MODE_CSP, "csv": MODE_CSV, "cst": MODE_CST}  # modes of operation (0x6060)
COMMON = {
    0x6040: "controlword",
    0x6041: "statusword",
    0x6060: "modes of operation",
    0x6061: "modes of operation display",
}
STANDARD_NAMES = {
    0x607A: "target position",
    0x6064: "position actual value",
    0x60FF: "target velocity",
    0x606C: "velocity actual value",
    0x6071: "target torque",
    0x6077: "torque actual value",
    **COMMON,
}


@dataclass(frozen=True)
class DriveCapabilities:
    source: str
    modes: frozenset[str]
    missing: dict[str, tuple[int, ...]]  # mode -> objects the description lacks (or cannot map)
    supported_modes_hint: int | None  # 0x6502 default in the description, if any
    heartbeat_consumer: bool  # 0x1016
    rpdos: int
    tpdos: int

    def require(self, mode: str) -> None:
        """Raise ValueError (a sentence naming the description and the objects) if `mode` is impossible."""
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r} (modes: {', '.join(MODES)})")
        if mode in self.modes:
            return
        lacks = ", ".join(f"0x{i:04X} {STANDARD_NAMES.get(i, '')}".strip() for i in self.missing[mode])
        can = ", ".join(sorted(self.modes)) or "no cyclic synchronous mode"
        raise ValueError(
            f"{MODE_NAMES[mode]} ({mode}) is not possible with {self.source}: it lacks {lacks} "
            f"(this drive can do: {can})"
        )

    def hint_excludes(self, mode: str) -> bool:
        """The description's 0x6502 default says the mode is unsupported (a warning, not a refusal)."""
        hint = self.supported_modes_hint
        return hint is not None and not hint >> MODES[mode][2] & 1


def object_dictionary(path: str | Path, node_id: int) -> canopen.ObjectDictionary:
    """`canopen.import_od(path, node_id)`, parsed once per file version and node: a startup reads
    each axis's description twice (its capabilities as the config loads, the node's dictionary as
    the bus starts), and parsing one takes 0.03-0.15 s. A copy of its own to each caller (a
    node's dictionary is changed through it)."""
    st = os.stat(path)
    return copy.deepcopy(_parsed(str(path), node_id, (st.st_mtime_ns, st.st_size)))


@functools.lru_cache(maxsize=16)
def _parsed(path: str, node_id: int, version: tuple[int, int]) -> canopen.ObjectDictionary:
    return canopen.import_od(path, node_id)


def read_capabilities(path: str | Path, node_id: int = 1) -> DriveCapabilities:
    od = object_dictionary(path, node_id)
    missing: dict[str, tuple[int, ...]] = {}
    modes = set()
    for mode, (target, actual, _bit) in MODES.items():
        lacks = tuple(i for i in (*COMMON, target, actual) if not _mappable(od, i, i in COMMON))
        missing[mode] = lacks
        if not lacks:
            modes.add(mode)
    hint = od.get(0x6502)
    default = getattr(hint, "default", None)
    return DriveCapabilities(
        source=Path(path).name,
        modes=frozenset(modes),
        missing=missing,
        supported_modes_hint=int(default) if isinstance(default, int) else None,
        heartbeat_consumer=0x1016 in od,
        rpdos=sum(1 for i in range(0x1600, 0x1800) if i in od),
        tpdos=sum(1 for i in range(0x1A00, 0x1C00) if i in od),
    )


def _mappable(od: canopen.ObjectDictionary, index: int, sdo_ok: bool) -> bool:
    """Present, and PDO-mappable unless it may be reached by SDO (modes of operation)."""
    if index not in od:
        return False
    var = od[index]
    if not isinstance(var, canopen.objectdictionary.ODVariable):
        return False
    return sdo_ok or index in (0x6060, 0x6061) or bool(var.pdo_mappable)


def mode_name(code: int) -> str:
    """A mode of operation (0x6060/0x6061 value) by its name here, else its number."""
    return next((name for name, c in MODE_CODES.items() if c == code), str(code))


def consumer_entry(od: canopen.ObjectDictionary, producer_id: int) -> int:
    """The sub-index of 0x1016 (consumer heartbeat time) that can watch `producer_id`: one that
    already does, else the first unused one (0) among the description's number of entries (sub 0).
    ValueError saying what is missing when there is none: an entry beyond the number of entries
    is never watched by the drive, and entries watching other producers are not ours to take."""
    consumer = od.get(0x1016)
    if not isinstance(consumer, ODArray | ODRecord):
        raise ValueError("it has no heartbeat consumer object 0x1016")
    count = _od_value(consumer, 0)
    if count is None or count < 1:
        raise ValueError(f"0x1016 has {count or 0} consumer heartbeat entries (number of entries, sub 0)")
    missing = [sub for sub in range(1, count + 1) if sub not in consumer]
    if missing:
        raise ValueError(
            f"0x1016 counts {count} consumer heartbeat entries (sub 0) but describes no sub-index "
            f"{', '.join(str(m) for m in missing)}"
        )
    entries = {sub: _od_value(consumer, sub) or 0 for sub in range(1, count + 1)}
    for sub, entry in entries.items():
        if entry >> 16 & 0x7F == producer_id:
            return sub
    for sub, entry in entries.items():
        if entry >> 16 & 0x7F == 0 or entry & 0xFFFF == 0:
            return sub
    others = ", ".join(f"sub {sub} watches node {e >> 16 & 0x7F}" for sub, e in entries.items())
    raise ValueError(f"all {count} consumer heartbeat entries of 0x1016 are taken ({others})")


def _od_value(obj: ODArray | ODRecord, sub: int) -> int | None:
    """A sub-object's value as the description sets it (a DCF's ParameterValue, else the default)."""
    if sub not in obj:
        return None
    var = obj[sub]
    value = var.value if var.value is not None else var.default
    return int(value) if isinstance(value, int) else None
