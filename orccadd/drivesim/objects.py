"""A CANopen object dictionary's values, read and written as a SDO server does it, whatever the bus.

`ObjectStore` holds the objects an EDS/DCF file describes (`vars`, one `ODVariable` per index and
sub-index) and their current values (`values`, Python values as canopen decodes them). `read` and
`write` take the bytes a SDO carries, little-endian in the description's data type, and apply
CiA 301's checks, raising `SdoAbortError` with the abort code; the bus's own protocol (CAN's SDO
frames in `slave.SlaveNode`, EtherCAT's CoE mailbox in `ecatsim.coe`) stays with its server.

Rules of a particular slave hook in two ways: the owner's per-object `checks` (refuse a value before
it is stored) and `on_write` (react after), and a subclass's `_before_store` / `_after_store`.
No I/O, no clock: every method may be called from a tick.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import canopen
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from orccadd.drivers.canopen.capabilities import object_dictionary

log = logging.getLogger("orccadd.drivesim")

# SDO abort codes (CiA 301, 7.2.4.3.17)
ABORT_TOGGLE = 0x05030000
ABORT_COMMAND = 0x05040001
ABORT_UNSUPPORTED_ACCESS = 0x06010000
ABORT_WRITE_ONLY = 0x06010001
ABORT_READ_ONLY = 0x06010002
ABORT_NO_OBJECT = 0x06020000
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_LENGTH = 0x06070010
ABORT_TOO_LONG = 0x06070012  # data type does not match, length of service parameter too high
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030
ABORT_VALUE_HIGH = 0x06090031
ABORT_VALUE_LOW = 0x06090032
ABORT_DEVICE_STATE = 0x08000022
ABORT_GENERAL = 0x08000000

VARIABLE_SIZE = frozenset(
    {
        canopen.objectdictionary.VISIBLE_STRING,
        canopen.objectdictionary.OCTET_STRING,
        canopen.objectdictionary.UNICODE_STRING,
        canopen.objectdictionary.DOMAIN,
    }
)
_EMPTY: dict[int, Any] = {
    canopen.objectdictionary.VISIBLE_STRING: "",
    canopen.objectdictionary.UNICODE_STRING: "",
    canopen.objectdictionary.OCTET_STRING: b"",
    canopen.objectdictionary.DOMAIN: b"",
}


class SdoAbortError(Exception):
    """A SDO access refused, with its 32-bit abort code (CiA 301; ETG.1000.6 adds a few)."""

    def __init__(self, code: int) -> None:
        super().__init__(f"SDO abort 0x{code:08X}")
        self.code = code


class ObjectStore:
    """The objects of an EDS/DCF file (with `$NODEID` resolved for `node_id`) and their values,
    which start at the description's defaults."""

    def __init__(self, eds: str, node_id: int) -> None:
        self.node_id = node_id
        self.od = object_dictionary(eds, node_id)
        self.vars: dict[tuple[int, int], ODVariable] = {}
        for obj in self.od.values():
            if isinstance(obj, ODVariable):
                self.vars[(obj.index, 0)] = obj
            elif isinstance(obj, ODRecord | ODArray):
                for sub in obj.values():
                    self.vars[(sub.index, sub.subindex)] = sub
        self.values: dict[tuple[int, int], Any] = {}
        self.on_write: dict[tuple[int, int], Callable[[Any], None]] = {}
        # raise SdoAbortError to refuse a value before it is stored (SDO: aborted; RPDO: ignored)
        self.checks: dict[tuple[int, int], Callable[[Any], None]] = {}
        self.unsized_logged: set[tuple[int, int]] = set()  # objects an unsized download was logged for
        self._load_defaults(comm_only=False)

    # ---- values from the drive's side ------------------------------------------------------------
    def get(self, index: int, sub: int = 0) -> Any:
        return self.values[(index, sub)]

    def set(self, index: int, sub: int, value: Any) -> None:
        """Set a value from the drive's side (no hooks, no access check)."""
        self.values[(index, sub)] = value

    def has(self, index: int, sub: int = 0) -> bool:
        return (index, sub) in self.values

    def defaults(self, comm_only: bool) -> None:
        """Values back to the description's defaults: all of them, or only the communication
        profile's (0x1000-0x1FFF, CiA 301's reset communication)."""
        self._load_defaults(comm_only)

    def _load_defaults(self, comm_only: bool) -> None:
        for key, var in self.vars.items():
            if comm_only and not 0x1000 <= key[0] <= 0x1FFF:
                continue
            default = var.value if var.value is not None else var.default
            if default is None:
                default = _EMPTY.get(var.data_type or 0, 0)
            self.values[key] = default

    # ---- SDO access ------------------------------------------------------------------------------
    def var(self, index: int, sub: int) -> ODVariable:
        """The description of one object entry; `SdoAbortError` 0x06020000 (no such object) or
        0x06090011 (the object exists, not that sub-index)."""
        var = self.vars.get((index, sub))
        if var is None:
            raise SdoAbortError(
                ABORT_NO_SUBINDEX if any(k[0] == index for k in self.vars) else ABORT_NO_OBJECT
            )
        return var

    def read(self, index: int, sub: int) -> bytes:
        """An entry's value as a SDO upload carries it: its data type's bytes, little-endian.
        Aborts 0x06020000 / 0x06090011 (missing), 0x06010001 (write-only)."""
        var = self.var(index, sub)
        if not var.readable:
            raise SdoAbortError(ABORT_WRITE_ONLY)
        data: bytes = var.encode_raw(self.values[(index, sub)])
        return data

    def write(self, index: int, sub: int, data: bytes) -> None:
        """An entry written from a SDO download's bytes. Aborts 0x06020000 / 0x06090011 (missing),
        0x06010002 (read-only), then as `_store`."""
        var = self.var(index, sub)
        if not var.writable:
            raise SdoAbortError(ABORT_READ_ONLY)
        self._store(var, data)

    def _store(self, var: ODVariable, data: bytes) -> None:
        """Decode and store a value whose access was checked: the length (0x06070010 unless the
        type has a variable size), the subclass's rules (`_before_store`), the description's
        limits (0x06090031 above HighLimit, 0x06090032 below LowLimit), the owner's `checks`;
        then `_after_store` and the owner's `on_write` hook."""
        if var.data_type not in VARIABLE_SIZE and len(data) != len(var) // 8:
            raise SdoAbortError(ABORT_LENGTH)
        value = var.decode_raw(data)
        key = (var.index, var.subindex)
        self._before_store(var, value)
        if isinstance(value, int | float):
            if var.max is not None and value > var.max:
                raise SdoAbortError(ABORT_VALUE_HIGH)
            if var.min is not None and value < var.min:
                raise SdoAbortError(ABORT_VALUE_LOW)
        check = self.checks.get(key)
        if check is not None:
            check(value)
        self.values[key] = value
        self._after_store(var, value)
        hook = self.on_write.get(key)
        if hook is not None:
            hook(value)

    def _before_store(self, var: ODVariable, value: Any) -> None:
        """A subclass's own rules, checked before the description's limits: raise SdoAbortError."""

    def _after_store(self, var: ODVariable, value: Any) -> None:
        """A subclass's reaction to a stored value, before the owner's `on_write` hook."""

    def unsized(self, var: ODVariable, data: bytes) -> bytes:
        """An expedited download without a size indication (e = 1, s = 0, allowed by CiA 301): the
        object's own size taken from the 4 bytes, logged once per object. Bytes beyond it other than
        padding (zeros, or the sign extension of a negative value) would be lost: aborted."""
        size = 4 if var.data_type in VARIABLE_SIZE else len(var) // 8
        if size > 4:  # more than an expedited transfer carries
            raise SdoAbortError(ABORT_LENGTH)
        value, rest = data[:size], data[size:]
        negative = var.data_type in canopen.objectdictionary.SIGNED_TYPES and bool(value[-1] & 0x80)
        if rest.strip(b"\x00") and not (negative and not rest.strip(b"\xff")):
            raise SdoAbortError(ABORT_TOO_LONG)
        key = (var.index, var.subindex)
        if key not in self.unsized_logged:
            self.unsized_logged.add(key)
            log.warning(
                "node %d: expedited SDO download to 0x%04X:%02X without a size indication (e=1, s=0): "
                "taken as the object's %d bytes (%s); logged once per object",
                self.node_id,
                var.index,
                var.subindex,
                size,
                value.hex(" "),
            )
        return value
