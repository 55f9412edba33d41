"""One drive's configuration over SDO at startup (blocking, before the control loop runs).

`configure_drive` checks the drive's own supported modes (0x6502), maps one RPDO and one TPDO,
both synchronous (type 1), sets the drive's heartbeat producer (0x1017) and its consumer of our
heartbeat (0x1016), the following error window in the drive's increments, the EMCY COB-ID, the
SYNC COB-ID, the communication cycle, the interpolation period and the mode of operation, then
waits until the drive shows that mode (0x6061).

COB-IDs (0x1014, PDO communication sub 1) and PDO mappings follow CiA 301's procedures
(`pdo_mapping`): the identifier changes only while bit 31 says "not valid", a mapping only while
its PDO is not valid and its count is 0. Each COB-ID is first written back with bit 31 set and its
identifier as it is, then with the new identifier (and the mapping, for a PDO: count 0, entries,
count) still not valid, and last valid: a drive that refuses a write out of that order (SDO abort
0x06090030 for a COB-ID, commonly 0x06010000 for a mapping) accepts every step, and a refused
step is an error naming the node, the step, the object and the abort code.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import canopen
import numpy as np
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from orccadd.drivers.canopen.capabilities import MODE_CODES, MODES, consumer_entry, mode_name
from orccadd.drivers.canopen.pdo_mapping import (
    SYNCHRONOUS,
    PdoPlan,
    check_described,
    cob_id_steps,
    disable_steps,
    mapping_steps,
    read_value,
    run_steps,
)
from orccadd.drivers.canopen.settings import CanopenSettings
from orccadd.errors import ResourceError

CONTROLLER_NODE_ID = 0x7F  # our heartbeat's producer id (drives consume it)
MODE_POLL_S = 0.001  # between two reads of 0x6061 while the drive switches mode


@dataclass(frozen=True)
class DriveSetup:
    """What the startup established on one drive, for the cyclic exchange."""

    has_torque_actual: bool  # the TPDO carries 0x6077
    consumer_ok: bool  # the drive watches our heartbeat
    rx_objects: tuple[int, ...]  # the RPDO's targets after the controlword


def configure_drive(
    node: canopen.RemoteNode, s: CanopenSettings, i: int, name: str, period_s: float, warnings: list[str]
) -> DriveSetup:
    """Configure axis `i` (joint `name`) of `s` through `node`'s SDO client; warnings appended,
    `ResourceError` for what makes the drive unfit (a missing mode, no consumer entry left for
    our heartbeat, a mode it never shows)."""
    who = f"node {node.id} ({name})"
    od = node.object_dictionary
    _check_supported_mode(node, who, s.mode)
    has_tq, rx = _map_pdos(node, who, s.eds_paths[i], s.axes[i].node_id, s.mode)
    node.sdo[0x1017].raw = s.heartbeat_ms
    consumer_ok = _watch_our_heartbeat(node, who, s, s.eds_paths[i], warnings)
    _set_following_error(node, s, i)
    if _writable(od.get(0x1014)):  # some descriptions fix it (e35: 0xA0 for all)
        write_cob_id(node, 0x1014, 0, 0x80 + s.axes[i].node_id, who)
    if 0x1005 in od:
        node.sdo[0x1005].raw = 0x80
    if 0x1006 in od:
        node.sdo[0x1006].raw = round(period_s * 1e6)
    _set_interpolation_period(node, who, period_s, warnings)
    _set_mode(node, who, MODE_CODES[s.mode], s.mode_display_timeout_s)
    return DriveSetup(has_torque_actual=has_tq, consumer_ok=consumer_ok, rx_objects=tuple(rx[1:]))


def write_cob_id(node: canopen.RemoteNode, index: int, sub: int, cob_id: int, who: str = "") -> None:
    """Set the COB-ID at `index`[`sub`] (sub ignored for a plain variable such as 0x1014) to
    `cob_id`, valid, the CiA 301 way: bit 31 set first, then the new identifier, then valid.
    Nothing is written when it already has that value. `ResourceError` naming the step refused."""
    who = who or f"node {node.id}"
    what = f"COB-ID 0x{index:04X}"
    run_steps(node, who, cob_id_steps(what, index, sub, read_value(node, who, what, index, sub), cob_id))


def _check_supported_mode(node: canopen.RemoteNode, who: str, mode: str) -> None:
    if 0x6502 not in node.object_dictionary:
        return
    supported = int(node.sdo[0x6502].raw)
    if not supported >> MODES[mode][2] & 1:
        raise ResourceError(
            f"{who}: the drive reports supported drive modes 0x{supported:X} (0x6502) without {mode}: "
            "it cannot run this config"
        )


def _map_pdos(
    node: canopen.RemoteNode, who: str, source: str, node_id: int, mode: str
) -> tuple[bool, list[int]]:
    """RPDO1: controlword, the mode's target and the one it may switch with; TPDO1: statusword,
    position and torque actual; both synchronous, on 0x200/0x180 + node id; every other PDO not
    valid. Each by CiA 301's steps (`pdo_mapping`). (has torque actual, RPDO objects)."""
    od = node.object_dictionary

    def mappable(index: int) -> bool:
        var = od.get(index)
        return isinstance(var, ODVariable) and bool(var.pdo_mappable)

    has_tq = mappable(0x6077)
    target = MODES[mode][0]
    # the mode's target, and the one it may switch with at run time: torque, or from torque, position
    partner = 0x607A if target == 0x6071 else 0x6071
    rx = [0x6040, target] + ([partner] if mappable(partner) else [])
    tx = [0x6041, 0x6064] + ([0x6077] if has_tq else [])
    _set_pdos(node, who, source, "RPDO", 0x1400, 0x200 + node_id, rx)
    _set_pdos(node, who, source, "TPDO", 0x1800, 0x180 + node_id, tx)
    return has_tq, rx


def _set_pdos(
    node: canopen.RemoteNode, who: str, source: str, kind: str, comm0: int, cob_id: int, objs: list[int]
) -> None:
    """The first PDO of `kind` (communication parameters at `comm0`, mapping at `comm0` + 0x200)
    mapped to `objs` on `cob_id`, synchronous; every other one the description has not valid."""
    od = node.object_dictionary
    if comm0 not in od or comm0 + 0x200 not in od:
        raise ResourceError(f"{who}: {source} has no {kind}1 (0x{comm0:04X}, 0x{comm0 + 0x200:04X})")
    for n in range(512):
        comm, mapping = comm0 + n, comm0 + 0x200 + n
        if comm not in od or mapping not in od:
            continue
        name = f"{kind}{n + 1}"
        current = read_value(node, who, f"{name} COB-ID", comm, 1)
        if n > 0:
            run_steps(node, who, disable_steps(name, comm, current))
            continue
        entries = tuple((index, 0, len(od[index])) for index in objs)
        plan = PdoPlan(name, comm, mapping, cob_id, entries, _trans_type(node, who, name, comm))
        steps = mapping_steps(plan, current)
        check_described(od, who, source, steps)
        run_steps(node, who, steps)


def _trans_type(node: canopen.RemoteNode, who: str, name: str, comm: int) -> int | None:
    """The transmission type to write (synchronous), or None where the description fixes it (then
    the drive's must be synchronous already) or lacks it."""
    record = node.object_dictionary.get(comm)
    if not isinstance(record, ODRecord | ODArray) or 2 not in record:
        return None
    if record[2].writable:
        return SYNCHRONOUS
    fixed = read_value(node, who, f"{name} transmission type", comm, 2)
    if fixed != SYNCHRONOUS:
        raise ResourceError(
            f"{who}: {name} transmission type 0x{comm:04X}:02 is {fixed}, fixed (not writable in its "
            f"description): the cyclic exchange needs {SYNCHRONOUS} (every SYNC)"
        )
    return None


def _watch_our_heartbeat(
    node: canopen.RemoteNode, who: str, s: CanopenSettings, source: str, warnings: list[str]
) -> bool:
    """0x1016: the drive watches our heartbeat, with 3 periods' grace. Refused (ResourceError) for
    a description whose 0x1016 has no entry left for it: the drive would never watch us. A drive
    without 0x1016, or whose description caps the entry below a producer id, is a warning."""
    od = node.object_dictionary
    consumer = od.get(0x1016)
    if consumer is None:
        warnings.append(f"{who}: its description has no heartbeat consumer (0x1016)")
        return False
    try:
        sub = consumer_entry(od, CONTROLLER_NODE_ID)
    except ValueError as e:
        raise ResourceError(
            f"{who}: {source}: {e}: the drive would never watch the controller's heartbeat "
            f"(node 0x{CONTROLLER_NODE_ID:X}); refused. Add a free entry to 0x1016 (a sub-index set "
            "to 0, counted in sub 0)"
        ) from None
    entry = CONTROLLER_NODE_ID << 16 | 3 * s.controller_heartbeat_ms
    limit = _sub_max(consumer, sub)
    if limit is not None and entry > limit:
        warnings.append(
            f"{who}: its description caps heartbeat consumer entries (0x1016:{sub:02X}) at 0x{limit:X}, "
            "no room for a producer id: the drive cannot watch our heartbeat"
        )
        return False
    try:
        node.sdo[0x1016][sub].raw = entry
    except (canopen.SdoAbortedError, ValueError, KeyError) as e:
        warnings.append(f"{who}: cannot watch our heartbeat (0x1016: {e})")
        return False
    return True


def _set_following_error(node: canopen.RemoteNode, s: CanopenSettings, i: int) -> None:
    """CSP following error window (0x6065, in the drive's increments) and time-out (0x6066)."""
    ax = s.axes[i]
    counts_per_rad = ax.counts_per_rev * ax.gear_ratio / (2 * np.pi)
    for index, value in (
        (0x6065, round(s.following_error_rad * counts_per_rad)),
        (0x6066, s.following_error_timeout_ms),
    ):
        if _writable(node.object_dictionary.get(index)):
            node.sdo[index].raw = min(value, 0xFFFFFFFE)


def _set_interpolation_period(
    node: canopen.RemoteNode, who: str, period_s: float, warnings: list[str]
) -> None:
    interpolation = node.object_dictionary.get(0x60C2)
    if not isinstance(interpolation, ODRecord) or not {1, 2} <= set(interpolation.subindices):
        return
    try:  # the drive interpolates (and derives its CSP velocity feed-forward) over this time
        value, exponent = interpolation_time_period(period_s)
        node.sdo[0x60C2][1].raw = value
        node.sdo[0x60C2][2].raw = exponent
    except ValueError as e:
        warnings.append(f"{who}: interpolation time period left as it is: {e}")


def _set_mode(node: canopen.RemoteNode, who: str, code: int, timeout_s: float) -> None:
    """0x6060, then 0x6061 read until it shows the mode (drives take a few ms to switch)."""
    node.sdo[0x6060].raw = code
    end = time.monotonic() + timeout_s
    shown = int(node.sdo[0x6061].raw)
    while shown != code and time.monotonic() < end:
        time.sleep(MODE_POLL_S)
        shown = int(node.sdo[0x6061].raw)
    if shown != code:
        raise ResourceError(mode_not_shown(who, code, shown, timeout_s))


def mode_not_shown(who: str, asked: int, shown: int | None, timeout_s: float) -> str:
    """The error of a drive that does not switch to the mode asked."""
    display = "nothing" if shown is None else mode_name(shown)
    if shown is not None and display != str(shown):
        display += f" ({shown})"
    return (
        f"{who}: asked mode {mode_name(asked)} (0x6060 = {asked}), the drive still shows {display} "
        f"(0x6061) after {timeout_s:g} s"
    )


def interpolation_time_period(period_s: float) -> tuple[int, int]:
    """0x60C2 as (value, exponent): value × 10^exponent s = `period_s`, value ≤ 255, the
    coarsest exponent first (2 ms is (2, -3), 250 µs is (25, -5))."""
    for exponent in range(-3, -7, -1):
        value = period_s / 10.0**exponent
        if abs(value - round(value)) < 1e-6 and 1 <= round(value) <= 255:
            return round(value), exponent
    raise ValueError(f"a period of {period_s * 1e3:g} ms has no 0x60C2 encoding (value 1-255 × 10^-3..-6 s)")


def _writable(obj: object) -> bool:
    return isinstance(obj, ODVariable) and obj.writable


def _sub_max(obj: object, sub: int) -> int | None:
    """The description's upper bound of `obj`[sub], if it has one."""
    if isinstance(obj, ODArray | ODRecord) and sub in obj:
        hi = obj[sub].max
        return int(hi) if hi is not None else None
    return None
