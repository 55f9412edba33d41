"""CoE complete access (ETG.1000.6 5.6.2): a whole array or record in one SDO transfer.

The request names sub-index 0 (sub-index 0 included) or 1 (left out). The data are the entries
one after the other, each in its data type's bytes (little-endian, no alignment), except that
sub-index 0 (UNSIGNED8) takes a 16-bit slot: its byte, then one padding byte. That is the layout
SOEM reads (`ec_PDOassignt`, `ec_PDOdesct`, `ec_SMcommtypet`: `uint8 n; uint8 nu1;` then the
entries) and writes (`ecx_SDOwrite` with CA).

Which entries: on upload, the existing sub-indices 1..value of sub-index 0 (the number of entries
now, e.g. a PDO mapping's count; a record's highest sub-index), a gap in the sub-indices skipped.
On download with sub-index 0, the value written in its slot says how many (the data must hold
exactly those entries); from sub-index 1, the data say it (whole entries, in order, from 1).

A download writes as CiA 301 configures a PDO: sub-index 0 set to 0 first (when it is writable and
not 0), then the entries, then sub-index 0; a read-only sub-index 0 may be "written" with its own
value. Each entry goes through `ObjectStore.write` (its access, length, limits and hooks); an abort
stops the transfer where it is: entries written before it keep their new values.

Entries of a variable size (strings, domains) are not served: abort 0x06010004.
"""

from __future__ import annotations

from canopen.objectdictionary import ODVariable

from orccadd.drivesim.objects import (
    ABORT_LENGTH,
    ABORT_READ_ONLY,
    ABORT_UNSUPPORTED_ACCESS,
    VARIABLE_SIZE,
    ObjectStore,
    SdoAbortError,
)

ABORT_CA_VARIABLE_SIZE = 0x06010004  # ETG.1000.6: complete access to an object of variable size
SUB0_SLOT = 2  # bytes: sub-index 0's byte and its padding byte


def read_complete(store: ObjectStore, index: int, sub: int) -> bytes:
    """Object `index` packed for a complete-access upload starting at `sub` (0 or 1)."""
    check_complete(store, index, sub)
    count = int(store.get(index, 0))
    out = bytearray()
    if sub == 0:
        out += store.read(index, 0).ljust(SUB0_SLOT, b"\x00")
    for s in _entries(store, index, count):
        out += store.read(index, s)
    return bytes(out)


def write_complete(store: ObjectStore, index: int, sub: int, data: bytes) -> None:
    """Object `index` written from a complete-access download's `data` starting at `sub` (0 or 1).
    Aborts 0x06070010 when the data do not hold whole entries (or, from sub-index 0, exactly the
    count it says), 0x06010002 for a read-only sub-index 0 given another value."""
    check_complete(store, index, sub)
    if sub == 0:
        if len(data) < SUB0_SLOT:
            raise SdoAbortError(ABORT_LENGTH)
        count: int | None = data[0]
        body = data[SUB0_SLOT:]
    else:
        count, body = None, data
    sub0 = store.var(index, 0)
    if count is not None and not sub0.writable and store.get(index, 0) != count:
        raise SdoAbortError(ABORT_READ_ONLY)
    chunks = _split(store, index, count, body)
    set_count = count is not None and sub0.writable
    if set_count and store.get(index, 0) != 0:
        store.write(index, 0, _sub0_bytes(sub0, 0))
    for s, chunk in chunks:
        store.write(index, s, chunk)
    if set_count and count is not None:
        store.write(index, 0, _sub0_bytes(sub0, count))


def check_complete(store: ObjectStore, index: int, sub: int) -> None:
    """Aborts unless `index` is an array or record complete access can start at `sub`: 0x06020000
    (no object), 0x06010000 (a simple variable, or a sub-index other than 0 or 1)."""
    store.var(index, 0)  # 0x06020000 if there is no such object
    if isinstance(store.od[index], ODVariable) or sub > 1:
        raise SdoAbortError(ABORT_UNSUPPORTED_ACCESS)


def _entries(store: ObjectStore, index: int, count: int) -> list[int]:
    """The existing sub-indices 1..count, in order; aborts for one of variable size."""
    subs = sorted(s for i, s in store.vars if i == index and 1 <= s <= count)
    for s in subs:
        if store.vars[(index, s)].data_type in VARIABLE_SIZE:
            raise SdoAbortError(ABORT_CA_VARIABLE_SIZE)
    return subs


def _split(store: ObjectStore, index: int, count: int | None, body: bytes) -> list[tuple[int, bytes]]:
    """`body` cut into (sub-index, bytes): the entries 1..count, or as many whole ones as it holds."""
    chunks: list[tuple[int, bytes]] = []
    at = 0
    for s in _entries(store, index, 255 if count is None else count):
        if count is None and at == len(body):
            break
        size = len(store.vars[(index, s)]) // 8
        if at + size > len(body):
            raise SdoAbortError(ABORT_LENGTH)
        chunks.append((s, body[at : at + size]))
        at += size
    if at != len(body):
        raise SdoAbortError(ABORT_LENGTH)
    return chunks


def _sub0_bytes(var: ODVariable, value: int) -> bytes:
    data: bytes = var.encode_raw(value)
    return data
