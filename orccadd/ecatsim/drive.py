"""One simulated EtherCAT CiA 402 drive: an ESC, the firmware behind its PDI, a CoE dictionary,
and the same `drivesim.axis.Axis` (state machine, cyclic modes, quick stop, faults) on the same
arm as the CANopen drive simulator.

The firmware (`DriveSlave`, the ESC's application):

- the CoE mailbox (SDO over `CoeServer`; emergencies from the axis go out through it);
- the PDO configuration of ETG.1000.6 5.6.7: the mapping objects (0x16xx, 0x1Axx) and the
  assignments (0x1C12, 0x1C13) are written in PRE-OP only (abort 0x08000022 otherwise), their
  entries only while sub-index 0 is 0 (abort 0x06010003), a mapping's entries must exist and be
  mappable (0x06020000, 0x06040041), an assignment names a PDO of its direction (0x06090030);
  padding entries (index 0) are gaps;
- the state changes: SAFE-OP needs SM2 and SM3 set as the mapping says (start, length, buffered,
  direction; AL status codes 0x001D, 0x001E), and for DC synchronisation (0x1C32:01 = 2) SYNC0
  activated with a cycle the drive can do (0x0030, 0x0035); OP needs outputs received in SAFE-OP
  (0x0019) and, with DC, a SYNC0 pulse seen (0x002D: the first comes at the start time the
  master chose, ~0.1 s on with SOEM); leaving OP, or the SM watchdog expiring, while the power
  stage is on is a fault of the axis (EMCY 0x8130, as a lost heartbeat on CANopen) with its
  controlled stop;
- the cycle: outputs applied and inputs latched at SYNC0 (DC), at each output frame
  (SM-synchronous), or every millisecond (free run); below OP the outputs are not applied.

Process data are byte-aligned here (every object the CiA 402 profile maps is); a mapping with a
bit-sized entry is refused at SAFE-OP (0x001D / 0x001E).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from canopen.objectdictionary import ODVariable

from orccadd.drivesim.axis import ERR_REG_COMM, Axis, AxisUnits
from orccadd.drivesim.objects import (
    ABORT_DEVICE_STATE,
    ABORT_NO_OBJECT,
    ABORT_NOT_MAPPABLE,
    ABORT_PDO_LENGTH,
    ABORT_VALUE_RANGE,
    ObjectStore,
    SdoAbortError,
)
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.ecatsim import registers as r
from orccadd.ecatsim import sii
from orccadd.ecatsim.coe import CoeServer
from orccadd.ecatsim.esc import Esc
from orccadd.ecatsim.registers import AlState, AlStatusCode

ABORT_SUBINDEX_0_NOT_ZERO = 0x06010003  # "sub-index cannot be written, SI0 must be 0 for write access"
EMCY_COMMUNICATION = 0x8130  # the master's cycle lost (CiA 301: life guard / heartbeat error)
SYNC_FREE_RUN, SYNC_SM, SYNC_DC = 0, 1, 2
FREE_RUN_CYCLE_NS = 1_000_000
MAILBOX_OUT, MAILBOX_IN, OUTPUTS, INPUTS = 0x1000, 0x1080, 0x1100, 0x1180  # physical addresses
MAILBOX_BYTES = 128
_FORMATS = {8: "B", 16: "H", 32: "I", 64: "Q"}
_SIGNED = {2, 3, 4, 0x15}


@dataclass(frozen=True)
class DriveSpec:
    """One drive: its identity (in its SII), its dictionary and its units."""

    vendor_id: int
    product_code: int
    revision: int
    eds: str
    units: AxisUnits
    name: str = "orccadd CiA 402 drive (simulated)"


def slave_info(spec: DriveSpec, serial: int) -> sii.SlaveInfo:
    return sii.SlaveInfo(
        vendor_id=spec.vendor_id,
        product_code=spec.product_code,
        revision=spec.revision,
        serial=serial,
        name=spec.name,
        mailbox_out=(MAILBOX_OUT, MAILBOX_BYTES),
        mailbox_in=(MAILBOX_IN, MAILBOX_BYTES),
        sync_managers=(
            sii.SyncManagerEntry(MAILBOX_OUT, MAILBOX_BYTES, 0x26, 0x01, sii.SM_MAILBOX_OUT),
            sii.SyncManagerEntry(MAILBOX_IN, MAILBOX_BYTES, 0x22, 0x01, sii.SM_MAILBOX_IN),
            sii.SyncManagerEntry(OUTPUTS, 0, 0x64, 0x01, sii.SM_OUTPUTS),  # buffered, written, watchdog
            sii.SyncManagerEntry(INPUTS, 0, 0x20, 0x01, sii.SM_INPUTS),
        ),
    )


class CoeNode(ObjectStore):
    """The drive's dictionary, with what `Axis` asks of a node (`drivesim.axis`) and the PDO
    configuration rules of EtherCAT."""

    def __init__(self, eds: str, position: int) -> None:
        super().__init__(eds, position)
        self.now_s = 0.0
        self.silent = False
        self.heartbeat_silent = False
        self.on_heartbeat_lost: Any = lambda producer: None
        self.on_reset_node: Any = lambda: None
        self.al_state = AlState.INIT
        self.coe: CoeServer | None = None

    def emergency(self, code: int, register: int, manufacturer: bytes = b"") -> None:
        if self.coe is not None and self.al_state is not AlState.INIT:
            self.coe.emergency(code, register, manufacturer)

    def _before_store(self, var: ODVariable, value: Any) -> None:
        index, sub = var.index, var.subindex
        mapping = 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF
        assignment = index in (0x1C12, 0x1C13)
        if not (mapping or assignment):
            return
        if self.al_state is not AlState.PRE_OP:
            raise SdoAbortError(ABORT_DEVICE_STATE)
        if sub > 0:
            if self.values.get((index, 0), 0):
                raise SdoAbortError(ABORT_SUBINDEX_0_NOT_ZERO)
            if assignment:
                low = 0x1600 if index == 0x1C12 else 0x1A00
                if not low <= int(value) < low + 0x200 or (int(value), 0) not in self.vars:
                    raise SdoAbortError(ABORT_VALUE_RANGE)
            return
        count = int(value)
        if mapping:
            bits = 0
            for k in range(1, count + 1):
                bits += self._check_entry(int(self.values.get((index, k), 0)), transmit=index >= 0x1A00)
            if bits > 8 * (MAILBOX_BYTES * 8):
                raise SdoAbortError(ABORT_PDO_LENGTH)
        elif any((index, k) not in self.vars for k in range(1, count + 1)):
            raise SdoAbortError(ABORT_VALUE_RANGE)

    def _check_entry(self, entry: int, transmit: bool) -> int:
        index, sub, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
        if index == 0:
            return bits  # a gap
        var = self.vars.get((index, sub))
        if var is None:
            raise SdoAbortError(ABORT_NO_OBJECT)
        if not var.pdo_mappable or len(var) != bits or (transmit and not var.readable):
            raise SdoAbortError(ABORT_NOT_MAPPABLE)
        return bits

    def pdo_layout(self, assignment: int) -> list[tuple[tuple[int, int] | None, str, int]] | None:
        """The process data of SM2 (0x1C12) or SM3 (0x1C13): per entry its object (None: a gap),
        struct code and byte length; None if an entry is not whole bytes."""
        out: list[tuple[tuple[int, int] | None, str, int]] = []
        for k in range(1, int(self.values.get((assignment, 0), 0)) + 1):
            pdo = int(self.values.get((assignment, k), 0))
            for e in range(1, int(self.values.get((pdo, 0), 0)) + 1):
                entry = int(self.values.get((pdo, e), 0))
                index, sub, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
                if bits % 8 or bits not in _FORMATS:
                    if index == 0 and bits % 8 == 0:
                        out.append((None, f"{bits // 8}x", bits // 8))
                        continue
                    return None
                if index == 0:
                    out.append((None, f"{bits // 8}x", bits // 8))
                    continue
                code = _FORMATS[bits]
                if self.vars[(index, sub)].data_type in _SIGNED:
                    code = code.lower()
                out.append(((index, sub), code, bits // 8))
        return out


class DriveSlave:
    """The ESC of drive `position` (1-based on the chain) and the firmware behind it."""

    def __init__(self, position: int, spec: DriveSpec, arm: DriveTrainArm) -> None:
        self.position = position
        self.spec = spec
        self.node = CoeNode(spec.eds, position)
        self._identity()
        self.esc = Esc(sii.build_image(slave_info(spec, serial=position)), self)
        self.esc.local_origin_ns = 7_919_000 * position  # powered up at its own instant
        self.coe = CoeServer(self.node, self.esc.post_mailbox, MAILBOX_BYTES)
        self.node.coe = self.coe
        self.axis = Axis(self.node, position - 1, arm, spec.units)  # type: ignore[arg-type]
        self.axis.boot()
        self._rx: list[tuple[tuple[int, int] | None, str, int]] = []
        self._tx: list[tuple[tuple[int, int] | None, str, int]] = []
        self._rx_format = struct.Struct("<")
        self._tx_format = struct.Struct("<")
        self._outputs: bytes | None = None  # the last outputs, not yet applied
        self._outputs_since_safe_op = False
        self._synced_since_safe_op = False  # a SYNC0 cycle ran since SAFE-OP (DC)
        self._next_free_run_ns = 0
        self.cycles = 0

    @property
    def sync_type(self) -> int:
        return int(self.node.values.get((0x1C32, 1), SYNC_SM))

    # ---- EscApplication ---------------------------------------------------------------------
    def state_change(self, current: AlState, requested: AlState) -> int:
        code = 0
        if current is AlState.PRE_OP and requested is AlState.SAFE_OP:
            code = self._check_process_data() or self._check_sync()
        elif current is AlState.SAFE_OP and requested is AlState.OP:
            if not self._outputs_since_safe_op:
                code = AlStatusCode.NO_VALID_OUTPUTS
            elif self.sync_type == SYNC_DC and not self._synced_since_safe_op:
                code = AlStatusCode.NO_SYNC
        if code:
            return int(code)
        if current is AlState.OP:
            self._lost_cycle()
        if requested is AlState.INIT:
            self.coe.reset()
        if requested is AlState.SAFE_OP:
            self._outputs_since_safe_op = False
            self._synced_since_safe_op = False
        self.node.al_state = requested
        return 0

    def mailbox_received(self, data: bytes) -> None:
        if self.node.al_state is not AlState.INIT:
            self.coe.on_mailbox(data)

    def outputs_received(self, data: bytes, now_ns: int) -> None:
        self._outputs = data
        self._outputs_since_safe_op = True
        if self.sync_type == SYNC_SM:
            self.cycle(now_ns, period_ns=int(self.node.values.get((0x1C32, 2), FREE_RUN_CYCLE_NS)))

    def watchdog_expired(self) -> None:
        self._lost_cycle()
        self.node.al_state = AlState.SAFE_OP

    # ---- the drive's time -------------------------------------------------------------------
    def tick(self, clock_ns: int) -> None:
        """Between frames: SYNC0 (DC) or the free-run cycle, the axis's own cycle, the watchdog."""
        self.node.now_s = clock_ns * 1e-9
        self.esc.poll(clock_ns)
        self.node.al_state = self.esc.al_state
        if self.esc.al_state not in (AlState.SAFE_OP, AlState.OP):
            self.axis.poll(self.node.now_s)
            return
        sync = self.sync_type
        if sync == SYNC_DC:
            if self.esc.sync0_due(clock_ns):
                self._synced_since_safe_op = True
                self.cycle(clock_ns, self.esc.sync0_cycle_ns)
        elif sync == SYNC_FREE_RUN and clock_ns >= self._next_free_run_ns:
            self._next_free_run_ns = clock_ns + FREE_RUN_CYCLE_NS
            self.cycle(clock_ns, FREE_RUN_CYCLE_NS)
        self.axis.poll(self.node.now_s)

    def cycle(self, clock_ns: int, period_ns: int) -> None:
        """The drive's cycle: outputs applied (in OP), the axis run, inputs latched."""
        self.node.now_s = clock_ns * 1e-9
        outputs, self._outputs = self._outputs, None
        if outputs is not None and self.esc.al_state is AlState.OP:
            self._apply(outputs)
        self.axis.cycle(self.node.now_s, max(period_ns, 1) * 1e-9)
        self.esc.write_inputs(3, self._pack_inputs())
        self.cycles += 1

    def _apply(self, data: bytes) -> None:
        if len(data) < self._rx_format.size:
            return
        values = self._rx_format.unpack_from(data)
        node = self.node
        for (key, _code, _n), value in zip((e for e in self._rx if e[0] is not None), values, strict=True):
            assert key is not None
            check = node.checks.get(key)
            if check is not None:
                try:
                    check(value)
                except SdoAbortError:
                    continue  # refused: the object keeps its value
            node.values[key] = value
            hook = node.on_write.get(key)
            if hook is not None:
                hook(value)

    def _pack_inputs(self) -> bytes:
        values = self.node.values
        return self._tx_format.pack(*(int(values.get(key, 0)) for key, _c, _n in self._tx if key is not None))

    def _lost_cycle(self) -> None:
        """The master's cycle is gone (OP left, or no outputs for the watchdog's time)."""
        if self.axis.sm.power_stage_on:
            self.axis.fault(EMCY_COMMUNICATION, ERR_REG_COMM)

    # ---- SAFE-OP checks ---------------------------------------------------------------------
    def _check_process_data(self) -> int:
        rx, tx = self.node.pdo_layout(0x1C12), self.node.pdo_layout(0x1C13)
        if rx is None:
            return AlStatusCode.INVALID_OUTPUT_CONFIGURATION
        if tx is None:
            return AlStatusCode.INVALID_INPUT_CONFIGURATION
        for sm, layout, control, code in (
            (2, rx, r.SM_DIRECTION_WRITE, AlStatusCode.INVALID_OUTPUT_CONFIGURATION),
            (3, tx, r.SM_DIRECTION_READ, AlStatusCode.INVALID_INPUT_CONFIGURATION),
        ):
            size = sum(n for _k, _c, n in layout)
            start, length, ctrl, activate = self.esc.sm_config(sm)
            if not size:
                continue
            want_start = OUTPUTS if sm == 2 else INPUTS
            if (start, length) != (want_start, size) or not activate & r.SM_ENABLE:
                return code
            if ctrl & r.SM_MODE_MASK != r.SM_MODE_BUFFERED or ctrl & r.SM_DIRECTION_MASK != control:
                return code
        self._rx, self._tx = rx, tx
        self._rx_format = struct.Struct("<" + "".join(c for _k, c, _n in rx))
        self._tx_format = struct.Struct("<" + "".join(c for _k, c, _n in tx))
        self.esc.write_inputs(3, self._pack_inputs())
        return 0

    def _check_sync(self) -> int:
        if self.sync_type != SYNC_DC:
            return 0
        if not self.esc.sync0_active:
            return AlStatusCode.INVALID_DC_SYNC_CONFIGURATION
        cycle = self.esc.sync0_cycle_ns
        if cycle < int(self.node.values.get((0x1C32, 5), 0)):
            return AlStatusCode.DC_INVALID_SYNC_CYCLE_TIME
        for index in (0x1C32, 0x1C33):
            if (index, 2) in self.node.values:
                self.node.values[(index, 2)] = cycle
        return 0

    def _identity(self) -> None:
        """0x1018 says what the SII says."""
        s = self.spec
        for sub, value in enumerate((s.vendor_id, s.product_code, s.revision, self.position), 1):
            if self.node.has(0x1018, sub):
                self.node.set(0x1018, sub, value)

    # ---- faults ------------------------------------------------------------------------------
    def leave_op(self, code: int) -> None:
        """The firmware's own error: SAFE-OP + ERROR with AL status `code` (the drive's power stage
        off with a fault if it was on, as for a lost cycle)."""
        if self.esc.al_state is AlState.OP:
            self._lost_cycle()
            self.esc.al_error(AlState.SAFE_OP, code)
            self.node.al_state = AlState.SAFE_OP

    def power_cycle(self) -> None:
        """Power off and on: the ESC at its power-on state, the dictionary at its defaults."""
        self.esc.power_on()
        self.node.defaults(comm_only=False)
        self._identity()
        self.node.al_state = AlState.INIT
        self.coe.reset()
        self.axis.reset()
