"""CiA 301's procedures for a drive's PDOs and COB-IDs: SDO steps planned first (pure), then run.

A PDO's mapping changes in five steps, in this order (CiA 301, PDO mapping parameter); a strict
drive refuses a mapping written out of it:

    a  the PDO not valid: bit 31 of its COB-ID (0x1400+n / 0x1800+n sub 1) set, the identifier
       as it is; then the new identifier, still not valid (a valid COB-ID keeps its identifier);
       the transmission type (sub 2) while it is not valid
    b  the mapping count (0x1600+n / 0x1A00+n sub 0) to 0
    c  the entries, sub 1..k: index << 16 | sub-index << 8 | bits
    d  the count to k
    e  the PDO valid: bit 31 clear

A PDO left unused is only made not valid (step a): a PDO that is not valid is neither sent nor
taken, whatever its mapping. Each step is an `SdoStep` (what it is for, the object, the value);
`run_steps` runs them in order and turns a refusal into a `ResourceError` naming the node, the
step, the object, the value and the drive's abort code with its CiA 301 meaning. Nothing here may
be called from a tick (blocking SDO through the `canopen` library, before the loop runs).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import canopen
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from orccadd.errors import ResourceError

COB_INVALID = 1 << 31  # CiA 301: bit 31 of a COB-ID, 1 = not valid
COB_RTR_NOT_ALLOWED = 1 << 30  # PDO COB-IDs
COB_IDENTIFIER = 0x3FFFFFFF  # bits 0-29: what may change only while not valid
SYNCHRONOUS = 1  # transmission type: every SYNC


@dataclass(frozen=True)
class SdoStep:
    """One SDO download of a procedure: what it is for, where, what."""

    what: str
    index: int
    sub: int
    value: int

    @property
    def where(self) -> str:
        return f"0x{self.index:04X}:{self.sub:02X}"


@dataclass(frozen=True)
class PdoPlan:
    """One PDO as the master wants it."""

    name: str  # "RPDO1", "TPDO1"
    comm: int  # 0x1400 + n or 0x1800 + n
    mapping: int  # 0x1600 + n or 0x1A00 + n
    cob_id: int  # its identifier (11 bits)
    entries: tuple[tuple[int, int, int], ...]  # (index, sub-index, bits)
    trans_type: int | None = SYNCHRONOUS  # None: left as the drive has it


def cob_id_steps(what: str, index: int, sub: int, current: int, cob_id: int) -> list[SdoStep]:
    """`cob_id` (valid) at `index`:`sub`, which holds `current`: bit 31 set first (the identifier
    as it is), then the new identifier (not valid), then valid. Nothing when it is there already."""
    if current == cob_id:
        return []
    steps = []
    if not current & COB_INVALID:
        steps.append(
            SdoStep(f"{what}: not valid (bit 31 set), identifier as it is", index, sub, current | COB_INVALID)
        )
    if (current ^ cob_id) & COB_IDENTIFIER:
        steps.append(SdoStep(f"{what}: the new identifier, not valid yet", index, sub, cob_id | COB_INVALID))
    steps.append(SdoStep(f"{what}: valid", index, sub, cob_id))
    return steps


def mapping_steps(plan: PdoPlan, current_cob_id: int) -> list[SdoStep]:
    """Steps a-e for `plan` on a drive whose COB-ID for it (sub 1) is `current_cob_id`; its RTR bit
    (30) is kept as the drive has it."""
    what = f"{plan.name} mapping"
    target = plan.cob_id | current_cob_id & COB_RTR_NOT_ALLOWED
    steps = []
    if not current_cob_id & COB_INVALID:
        steps.append(
            SdoStep(
                f"{what}, step a: the PDO not valid (bit 31 set)", plan.comm, 1, current_cob_id | COB_INVALID
            )
        )
    if (current_cob_id ^ target) & COB_IDENTIFIER:
        steps.append(
            SdoStep(f"{what}, step a: its new COB-ID, not valid yet", plan.comm, 1, target | COB_INVALID)
        )
    if plan.trans_type is not None:
        steps.append(
            SdoStep(f"{what}, step a: transmission type {plan.trans_type}", plan.comm, 2, plan.trans_type)
        )
    steps.append(SdoStep(f"{what}, step b: mapping count to 0", plan.mapping, 0, 0))
    for k, (index, sub, bits) in enumerate(plan.entries, 1):
        entry = index << 16 | sub << 8 | bits
        steps.append(
            SdoStep(
                f"{what}, step c: entry {k}, 0x{index:04X}:{sub:02X} ({bits} bits)", plan.mapping, k, entry
            )
        )
    count = len(plan.entries)
    steps.append(SdoStep(f"{what}, step d: mapping count to {count}", plan.mapping, 0, count))
    steps.append(SdoStep(f"{what}, step e: the PDO valid", plan.comm, 1, target))
    return steps


def disable_steps(name: str, comm: int, current_cob_id: int) -> list[SdoStep]:
    """An unused PDO not valid (bit 31 set, identifier as it is); nothing if it is not already."""
    if current_cob_id & COB_INVALID:
        return []
    return [SdoStep(f"{name}: unused, not valid (bit 31 set)", comm, 1, current_cob_id | COB_INVALID)]


def check_described(od: canopen.ObjectDictionary, who: str, source: str, steps: Iterable[SdoStep]) -> None:
    """Every step's object in the description and writable there, else `ResourceError` (before
    anything is sent)."""
    for step in steps:
        var = _described(od, step.index, step.sub)
        if var is None:
            raise ResourceError(f"{who}: {step.what}: {source} has no {step.where}")
        if not var.writable:
            raise ResourceError(
                f"{who}: {step.what}: {step.where} is {var.access_type} in {source} (a fixed "
                "mapping or parameter): the drive cannot take this config"
            )


def run_steps(node: canopen.RemoteNode, who: str, steps: Sequence[SdoStep]) -> None:
    """Each step's SDO download in order; a refusal or silence is a `ResourceError` naming it."""
    for step in steps:
        try:
            _variable(node, step.index, step.sub).raw = step.value
        except canopen.SdoAbortedError as e:
            raise ResourceError(
                f"{who}: {step.what}: {step.where} = 0x{step.value:X} refused, {abort_text(e.code)}"
            ) from None
        except canopen.SdoCommunicationError as e:
            raise ResourceError(f"{who}: {step.what}: {step.where} = 0x{step.value:X}: {e}") from None


def read_value(node: canopen.RemoteNode, who: str, what: str, index: int, sub: int) -> int:
    """An integer object read by SDO upload; a refusal or silence is a `ResourceError` naming it."""
    where = f"0x{index:04X}:{sub:02X}"
    try:
        return int(_variable(node, index, sub).raw)
    except canopen.SdoAbortedError as e:
        raise ResourceError(f"{who}: reading {what} ({where}) refused, {abort_text(e.code)}") from None
    except canopen.SdoCommunicationError as e:
        raise ResourceError(f"{who}: reading {what} ({where}): {e}") from None


def abort_text(code: int) -> str:
    """`SDO abort 0x06010000 (Unsupported access to an object)`, CiA 301's words for the code."""
    meaning = canopen.SdoAbortedError.CODES.get(code, "not a code of CiA 301")
    return f"SDO abort 0x{code:08X} ({meaning})"


def _variable(node: canopen.RemoteNode, index: int, sub: int) -> canopen.sdo.base.SdoVariable:
    obj = node.sdo[index]
    return obj if isinstance(obj, canopen.sdo.base.SdoVariable) else obj[sub]


def _described(od: canopen.ObjectDictionary, index: int, sub: int) -> ODVariable | None:
    obj = od.get(index)
    if isinstance(obj, ODRecord | ODArray):
        return obj.get(sub)
    return obj if isinstance(obj, ODVariable) else None
