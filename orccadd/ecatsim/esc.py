"""One EtherCAT Slave Controller: its memory as the master sees it through datagrams.

The ESC's 64 KiB address space — registers below 0x1000, process data RAM above — is one byte
array; a datagram reads and writes it, with the ESC's rules on top (Beckhoff's ESC datasheet,
section II; ETG.1000.4):

- registers: writes reach only the bits the master may write (a mask per byte); writing the AL
  control asks for a state change (`AlState` rules and AL status codes, the error indicator kept
  until acknowledged), writing the EEPROM control runs the command at once (reads of 8 bytes
  from the SII image), writing 0x0900 latches the receive times, 0x0910 compares a system time
  (the difference in 0x092C), 0x0981 starts or stops SYNC0; reading 0x0910 gives the system time
  (local time + the offset 0x0920);
- sync managers: a mailbox written full is handed to the application and the master cannot
  write it again until it was taken; the send mailbox can be read only when full (the master's
  read of its last byte empties it; a repeat request puts the last message back); a buffered
  (3-buffer) output area written up to its last byte is handed to the application; accesses an
  SM refuses do not count in the working counter;
- FMMUs map logical addresses to physical ones for LRD/LWR/LRW, byte-aligned (bit-granular
  FMMUs, which digital I/O terminals use, are not simulated);
- the SM watchdog: outputs not written for its time in OP take the slave to SAFE-OP with AL
  status code 0x001B, as the firmware of a drive does.

The application behind the PDI (`EscApplication`) says which state changes it accepts and gets
the mailbox and outputs; it writes inputs and posts mailbox messages through `write_inputs` and
`post_mailbox`. Times are nanoseconds on the simulator's clock (`time.monotonic_ns`).
"""

from __future__ import annotations

import struct
from collections import deque
from typing import Protocol

from orccadd.ecatsim import registers as r
from orccadd.ecatsim.registers import AL_ERROR, AL_STATE_MASK, ALLOWED, AlState, AlStatusCode

MEMORY_BYTES = 0x10000
WATCHDOG_DIVIDER_DEFAULT = 2498  # (2498 + 2) × 40 ns = 100 µs
WATCHDOG_SM_DEFAULT = 1000  # × 100 µs = 100 ms


class EscApplication(Protocol):
    """The slave's firmware as the ESC sees it."""

    def state_change(self, current: AlState, requested: AlState) -> int:
        """0 to take the change, else the AL status code to refuse it with (the ESC has checked
        the mailbox configuration already)."""
        ...

    def mailbox_received(self, data: bytes) -> None:
        """The master filled the receive mailbox (SM0): its whole buffer."""
        ...

    def outputs_received(self, data: bytes, now_ns: int) -> None:
        """The master wrote the output buffer (SM2) up to its last byte."""
        ...

    def watchdog_expired(self) -> None:
        """No outputs for the SM watchdog's time: outputs to their safe state."""
        ...


def _writable_mask() -> bytearray:
    """Per register byte, the bits the master may write."""
    mask = bytearray(r.REGISTERS_END)

    def allow(address: int, size: int, value: int = 0xFF) -> None:
        mask[address : address + size] = bytes([value]) * size

    allow(r.STATION_ADDRESS, 2)
    allow(r.DL_CONTROL, 4)
    allow(r.AL_CONTROL, 2)
    allow(r.ECAT_EVENT_MASK, 2)
    allow(r.AL_EVENT_MASK, 4)
    allow(r.WATCHDOG_DIVIDER, 2)
    allow(r.WATCHDOG_PDI, 2)
    allow(r.WATCHDOG_SM, 2)
    allow(r.EEPROM_CONFIG, 1, 0x03)
    allow(r.EEPROM_CONTROL, 2, 0x07)  # command bits 8-10 (byte 0x0503) and write enable (bit 0)
    mask[r.EEPROM_CONTROL] = 0x01
    allow(r.EEPROM_ADDRESS, 4)
    allow(r.EEPROM_DATA, 8)
    allow(r.FMMU0, 16 * 16)
    for sm in range(16):  # start, length, control and activate; status and PDI control are the ESC's
        base = r.SM0 + 8 * sm
        allow(base, 5)
        mask[base + 5] = 0x00
        mask[base + 6] = 0xC3
        mask[base + 7] = 0x00
    allow(r.DC_SYSTEM_TIME_OFFSET, 8)
    allow(r.DC_SYSTEM_TIME_DELAY, 4)
    allow(r.DC_SPEED_COUNTER_START, 2)
    allow(r.DC_TIME_FILTER, 2)
    allow(r.DC_CYCLIC_UNIT_CONTROL, 2)
    allow(r.DC_START_TIME, 8)
    allow(r.DC_SYNC0_CYCLE, 8)
    return mask


_WRITABLE = _writable_mask()


class SyncManagerState:
    """What the ESC keeps of one sync manager beyond its registers."""

    __slots__ = ("full", "last_message", "written_ns")

    def __init__(self) -> None:
        self.full = False  # mailbox: a message waits to be taken
        self.last_message = b""  # send mailbox: for a repeat request
        self.written_ns = 0  # buffered outputs: when last written completely


class Esc:
    def __init__(
        self, sii_image: bytes, app: EscApplication, *, ram_kib: int = 8, has_dc: bool = True
    ) -> None:
        self.sii = bytearray(sii_image)
        self.app = app
        self.mem = bytearray(MEMORY_BYTES)
        self.ram_end = r.REGISTERS_END + ram_kib * 1024
        self.has_dc = has_dc
        self.local_origin_ns = 0  # local time = clock - origin: each ESC powered up at its own instant
        self.sm = [SyncManagerState() for _ in range(8)]
        self.outbox: deque[bytes] = deque()  # mailbox messages waiting for SM1 to empty
        self.al_requested = AlState.INIT
        self.sync0_next_ns = 0  # system time of the next SYNC0 (0: SYNC0 off)
        self.arrival_ns = 0  # this frame at port 0 (set by the chain before each datagram)
        self.return_ns = 0  # this frame back at port 1, from the slaves after this one
        self.clock_ns = 0  # the time of the access being served
        self.power_on()

    # ---- power-on state -------------------------------------------------------------------
    def power_on(self) -> None:
        m = self.mem
        m[:] = bytes(MEMORY_BYTES)
        m[r.TYPE], m[r.REVISION] = 0x11, 0x00  # as an ET1100 reports itself
        struct.pack_into("<H", m, r.BUILD, 0x0002)
        m[r.FMMUS], m[r.SYNC_MANAGERS] = 8, 8
        m[r.RAM_SIZE] = (self.ram_end - r.REGISTERS_END) // 1024
        m[r.PORT_DESCRIPTOR] = 0x0F  # ports 0 and 1 MII, 2 and 3 not implemented
        struct.pack_into("<H", m, r.FEATURES, 0x000C if self.has_dc else 0x0000)
        pdi, _pdi_config, pulse, _config2, alias = struct.unpack_from("<5H", self.sii, 0)
        struct.pack_into("<H", m, r.STATION_ALIAS, alias)
        m[r.PDI_CONTROL] = pdi & 0xFF
        struct.pack_into("<H", m, r.DC_PULSE_LENGTH, pulse)
        struct.pack_into("<H", m, r.AL_STATUS, AlState.INIT)
        struct.pack_into("<H", m, r.WATCHDOG_DIVIDER, WATCHDOG_DIVIDER_DEFAULT)
        struct.pack_into("<H", m, r.WATCHDOG_SM, WATCHDOG_SM_DEFAULT)
        m[r.WATCHDOG_SM_STATUS] = 0x01
        struct.pack_into("<H", m, r.EEPROM_CONTROL, r.EEPROM_READ_8_BYTES)
        self.sm = [SyncManagerState() for _ in range(8)]
        self.outbox.clear()
        self.al_requested = AlState.INIT
        self.sync0_next_ns = 0

    # ---- what the chain sees ----------------------------------------------------------------
    @property
    def station_address(self) -> int:
        return int(struct.unpack_from("<H", self.mem, r.STATION_ADDRESS)[0])

    @property
    def al_state(self) -> AlState:
        return AlState(self.mem[r.AL_STATUS] & AL_STATE_MASK)

    @property
    def al_status_code(self) -> int:
        return int(struct.unpack_from("<H", self.mem, r.AL_STATUS_CODE)[0])

    def set_dl_status(self, port1_open: bool) -> None:
        """The link as the chain is wired: port 0 towards the master, port 1 to the next slave."""
        status = 0x0010 | 0x0200  # link on port 0, its loop open and communicating
        status |= 0x0020 | 0x0800 if port1_open else 0x0400  # port 1: on to the next, or closed
        status |= 0x5000  # ports 2 and 3: loops closed
        struct.pack_into("<H", self.mem, r.DL_STATUS, status)

    def local_time_ns(self, clock_ns: int) -> int:
        return clock_ns - self.local_origin_ns

    def system_time_ns(self, clock_ns: int) -> int:
        offset = int(struct.unpack_from("<q", self.mem, r.DC_SYSTEM_TIME_OFFSET)[0])
        return (self.local_time_ns(clock_ns) + offset) & 0xFFFFFFFFFFFFFFFF

    # ---- physical access (APxx, FPxx, BRx, xRMW) ---------------------------------------------
    def read(self, offset: int, data: bytearray, clock_ns: int, merge: bool = False) -> bool:
        """Put bytes `offset…` into `data` (ORed in with `merge`, as a broadcast read does);
        False if a sync manager refused the access (it does not count)."""
        n = len(data)
        self.clock_ns = clock_ns
        if offset + n > MEMORY_BYTES:
            return False
        if offset < r.DC_SYSTEM_TIME + 8 and offset + n > r.DC_SYSTEM_TIME:
            struct.pack_into("<Q", self.mem, r.DC_SYSTEM_TIME, self.system_time_ns(clock_ns))
        sm = self._mailbox_in_at(offset, n)
        if sm is not None and not self.sm[sm].full:
            return False
        chunk = self.mem[offset : offset + n]
        if merge:
            for i in range(n):
                data[i] |= chunk[i]
        else:
            data[:] = chunk
        if sm is not None:
            start, length = self._sm_area(sm)
            if offset <= start + length - 1 < offset + n:  # its last byte read: empty
                self.sm[sm].full = False
                self._set_sm_status(sm)
                self._deliver_outbox()
        return True

    def write(self, offset: int, data: bytes, clock_ns: int) -> bool:
        """Write `data` at `offset`; False if a sync manager refused it (a full mailbox)."""
        n = len(data)
        self.clock_ns = clock_ns
        if offset + n > MEMORY_BYTES:
            return False
        end = offset + n
        sm = self._mailbox_out_at(offset, n)
        if sm is not None and self.sm[sm].full:
            return False
        if offset < r.REGISTERS_END:
            self._write_registers(offset, data, clock_ns)
        if end > r.REGISTERS_END:
            at = max(offset, r.REGISTERS_END)
            self.mem[at:end] = data[at - offset :]
            self._ram_written(at, end, clock_ns)
        return True

    def _write_registers(self, offset: int, data: bytes, clock_ns: int) -> None:
        end = min(offset + len(data), r.REGISTERS_END)
        m = self.mem
        for at in range(offset, end):
            keep = _WRITABLE[at]
            if keep:
                m[at] = (m[at] & ~keep) | (data[at - offset] & keep)

        def touched(address: int, size: int = 1) -> bool:
            return offset < address + size and end > address

        if touched(r.RX_ERROR_COUNTERS, 0x14):
            m[r.RX_ERROR_COUNTERS : r.RX_ERROR_COUNTERS + 0x14] = bytes(0x14)
        if touched(r.EEPROM_CONTROL, 2):
            self._eeprom_command()
        if touched(r.SM0, 8 * 8):
            self._sync_managers_written(offset, end)
        if touched(r.DC_RECEIVE_TIME_PORT0):
            self.latch_receive_times(self.arrival_ns or clock_ns, self.return_ns or clock_ns)
        if touched(r.DC_SYSTEM_TIME, 4) and offset <= r.DC_SYSTEM_TIME:
            written = struct.unpack_from("<I", bytes(data[r.DC_SYSTEM_TIME - offset :][:4]).ljust(4, b"\0"))[
                0
            ]
            own = self.system_time_ns(clock_ns) & 0xFFFFFFFF
            diff = (written - own + (1 << 31)) % (1 << 32) - (1 << 31)
            struct.pack_into(
                "<I", m, r.DC_SYSTEM_TIME_DIFFERENCE, min(abs(diff), 0x7FFFFFFF) | (diff < 0) << 31
            )
        if touched(r.DC_ACTIVATION):
            self._sync_activation(clock_ns, data[r.DC_ACTIVATION - offset])
        if touched(r.AL_CONTROL, 2):
            self._al_control(int(struct.unpack_from("<H", m, r.AL_CONTROL)[0]))

    # ---- logical access (LRD, LWR, LRW) through the FMMUs -----------------------------------------
    def logical(self, address: int, data: bytearray, read: bool, write: bool, clock_ns: int) -> int:
        """Serve a logical datagram in place; the working counter's increment (1 read, 2 write)."""
        self.clock_ns = clock_ns
        wkc_read = wkc_write = False
        end = address + len(data)
        written: list[tuple[int, int]] = []
        for f in range(8):
            log_start, length, _sbit, _ebit, phys, _pbit, kind, active = r.FMMU.unpack_from(
                self.mem, r.FMMU0 + 16 * f
            )
            if not active & 1 or not length:
                continue
            lo, hi = max(address, log_start), min(end, log_start + length)
            if lo >= hi:
                continue
            p = phys + lo - log_start
            d = lo - address
            if read and kind & 1:
                data[d : d + hi - lo] = self.mem[p : p + hi - lo]
                wkc_read = True
            if write and kind & 2:
                self.mem[p : p + hi - lo] = data[d : d + hi - lo]
                written.append((p, p + hi - lo))
                wkc_write = True
        for lo, hi in written:
            self._ram_written(lo, hi, clock_ns)
        return int(wkc_read) + 2 * int(wkc_write)

    # ---- sync managers ------------------------------------------------------------------------
    def _sm_registers(self, sm: int) -> tuple[int, int, int, int, int, int]:
        return r.SYNC_MANAGER.unpack_from(self.mem, r.SM0 + 8 * sm)  # type: ignore[return-value]

    def _sm_area(self, sm: int) -> tuple[int, int]:
        start, length, *_ = self._sm_registers(sm)
        return start, length

    def sm_enabled(self, sm: int) -> bool:
        return bool(self.mem[r.SM0 + 8 * sm + 6] & r.SM_ENABLE) and self._sm_area(sm)[1] > 0

    def _sm_kind(self, sm: int) -> tuple[bool, bool]:
        """(mailbox, the master writes) of an SM."""
        control = self.mem[r.SM0 + 8 * sm + 4]
        mailbox = control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX
        return mailbox, control & r.SM_DIRECTION_MASK == r.SM_DIRECTION_WRITE

    def _mailbox_out_at(self, offset: int, n: int) -> int | None:
        return self._sm_at(offset, n, mailbox=True, master_writes=True)

    def _mailbox_in_at(self, offset: int, n: int) -> int | None:
        return self._sm_at(offset, n, mailbox=True, master_writes=False)

    def _sm_at(self, offset: int, n: int, mailbox: bool, master_writes: bool) -> int | None:
        if offset + n <= r.REGISTERS_END:
            return None
        for sm in range(8):
            if not self.sm_enabled(sm) or self._sm_kind(sm) != (mailbox, master_writes):
                continue
            start, length = self._sm_area(sm)
            if offset < start + length and offset + n > start:
                return sm
        return None

    def _ram_written(self, lo: int, hi: int, clock_ns: int) -> None:
        for sm in range(8):
            if not self.sm_enabled(sm):
                continue
            mailbox, master_writes = self._sm_kind(sm)
            start, length = self._sm_area(sm)
            if not master_writes or not lo <= start + length - 1 < hi:
                continue  # a buffer is complete once its last byte is written
            data = bytes(self.mem[start : start + length])
            if mailbox:
                self.sm[sm].full = True
                self._set_sm_status(sm)
                self.app.mailbox_received(data)
                self.sm[sm].full = False  # the firmware took it
                self._set_sm_status(sm)
            else:
                self.sm[sm].written_ns = clock_ns
                self.mem[r.WATCHDOG_SM_STATUS] = 0x01
                self.app.outputs_received(data, clock_ns)

    def _set_sm_status(self, sm: int) -> None:
        at = r.SM0 + 8 * sm + 5
        self.mem[at] = (self.mem[at] & ~r.SM_STATUS_MAILBOX_FULL) | (
            r.SM_STATUS_MAILBOX_FULL if self.sm[sm].full else 0
        )

    def _sync_managers_written(self, lo: int, hi: int) -> None:
        for sm in range(8):
            base = r.SM0 + 8 * sm
            if not (lo < base + 8 and hi > base):
                continue
            state = self.sm[sm]
            mailbox, master_writes = self._sm_kind(sm)
            if not self.sm_enabled(sm):  # disabled: whatever it held is gone
                state.full = False
                state.last_message = b""
                self._set_sm_status(sm)
                continue
            if mailbox and not master_writes and not state.full:
                self._deliver_outbox()
            if mailbox and not master_writes:
                repeat = self.mem[base + 6] & r.SM_REPEAT_REQUEST
                if repeat != self.mem[base + 7] & r.SM_PDI_REPEAT_ACK and state.last_message:
                    self._place_mailbox(sm, state.last_message)  # the repeat: the last message again
                    self.mem[base + 7] = (self.mem[base + 7] & ~r.SM_PDI_REPEAT_ACK) | repeat

    # ---- the application's side (PDI) -------------------------------------------------------------
    def post_mailbox(self, message: bytes) -> None:
        """A message for the master: into the send mailbox (SM1) now, or when it empties."""
        self.outbox.append(message)
        self._deliver_outbox()

    def _mailbox_in(self) -> int | None:
        for sm in range(8):
            if self.sm_enabled(sm) and self._sm_kind(sm) == (True, False):
                return sm
        return None

    def _deliver_outbox(self) -> None:
        sm = self._mailbox_in()
        if sm is None or self.sm[sm].full or not self.outbox:
            return
        self._place_mailbox(sm, self.outbox.popleft())

    def _place_mailbox(self, sm: int, message: bytes) -> None:
        start, length = self._sm_area(sm)
        self.mem[start : start + length] = message[:length].ljust(length, b"\x00")
        self.sm[sm].full = True
        self.sm[sm].last_message = message
        self._set_sm_status(sm)

    def write_inputs(self, sm: int, data: bytes) -> None:
        """The firmware's inputs into a buffered read SM's area (SM3)."""
        start, length = self._sm_area(sm)
        self.mem[start : start + min(length, len(data))] = data[:length]

    def outputs_area(self, sm: int) -> bytes:
        start, length = self._sm_area(sm)
        return bytes(self.mem[start : start + length])

    def sm_config(self, sm: int) -> tuple[int, int, int, int]:
        """(start, length, control, activate) of SM `sm` as the master configured it."""
        start, length, control, _status, activate, _pdi = self._sm_registers(sm)
        return start, length, control, activate

    def al_error(self, state: AlState, code: int) -> None:
        """The firmware leaves for `state` on an error (the SM watchdog, a lost SYNC)."""
        self._set_al(state, code)

    # ---- the application layer's state machine ----------------------------------------------------
    def _al_control(self, value: int) -> None:
        requested_bits, ack = value & AL_STATE_MASK, bool(value & AL_ERROR)
        status = self.mem[r.AL_STATUS]
        current = AlState(status & AL_STATE_MASK)
        if status & AL_ERROR:
            if not ack:
                return  # an error stays until the master acknowledges it
            self._set_al(current, 0)
        try:
            requested = AlState(requested_bits)
        except ValueError:
            self._set_al(current, AlStatusCode.UNKNOWN_STATE)
            return
        self.al_requested = requested
        if requested == current:
            return
        if requested is AlState.BOOT:
            self._set_al(current, AlStatusCode.BOOTSTRAP_NOT_SUPPORTED)
            return
        if (current, requested) not in ALLOWED:
            self._set_al(current, AlStatusCode.INVALID_STATE_CHANGE)
            return
        if current is AlState.INIT and requested is AlState.PRE_OP and not self._mailbox_configured():
            self._set_al(current, AlStatusCode.INVALID_MAILBOX_CONFIGURATION)
            return
        code = self.app.state_change(current, requested)
        if code:
            self._set_al(current, code)
            return
        if requested is AlState.INIT:
            self.outbox.clear()
            for state in self.sm:
                state.full = False
                state.last_message = b""
        if requested is AlState.OP:  # the watchdog counts from here
            self.mem[r.WATCHDOG_SM_STATUS] = 0x01
            for state in self.sm:
                state.written_ns = max(state.written_ns, self.clock_ns)
        self._set_al(requested, 0)

    def _set_al(self, state: AlState, code: int) -> None:
        struct.pack_into("<H", self.mem, r.AL_STATUS, state | (AL_ERROR if code else 0))
        struct.pack_into("<H", self.mem, r.AL_STATUS_CODE, code)

    def _mailbox_configured(self) -> bool:
        """SM0 and SM1 as the SII's standard mailboxes: offsets, sizes, mailbox mode, enabled."""
        out_offset, out_size, in_offset, in_size = struct.unpack_from("<4H", self.sii, 0x18 * 2)
        want = ((out_offset, out_size, r.SM_DIRECTION_WRITE), (in_offset, in_size, r.SM_DIRECTION_READ))
        for sm, (offset, size, direction) in enumerate(want):
            start, length, control, activate = self.sm_config(sm)
            if (start, length) != (offset, size) or not activate & r.SM_ENABLE:
                return False
            if control & r.SM_MODE_MASK != r.SM_MODE_MAILBOX or control & r.SM_DIRECTION_MASK != direction:
                return False
        return True

    # ---- EEPROM (SII) ---------------------------------------------------------------------------
    def _eeprom_command(self) -> None:
        m = self.mem
        control = int(struct.unpack_from("<H", m, r.EEPROM_CONTROL)[0])
        command = control & r.EEPROM_COMMAND_MASK
        (word,) = struct.unpack_from("<I", m, r.EEPROM_ADDRESS)
        status = r.EEPROM_READ_8_BYTES
        if command == r.EEPROM_READ:
            at = word * 2
            if at >= len(self.sii):
                status |= r.EEPROM_ERROR_ACK
            else:
                m[r.EEPROM_DATA : r.EEPROM_DATA + 8] = bytes(self.sii[at : at + 8]).ljust(8, b"\xff")
        elif command == r.EEPROM_WRITE:
            at = word * 2
            if not control & r.EEPROM_WRITE_ENABLE or at + 2 > len(self.sii):
                status |= r.EEPROM_ERROR_ACK
            else:
                self.sii[at : at + 2] = m[r.EEPROM_DATA : r.EEPROM_DATA + 2]
        elif command == r.EEPROM_RELOAD:
            struct.pack_into("<H", m, r.STATION_ALIAS, struct.unpack_from("<H", self.sii, 8)[0])
        elif command:
            status |= r.EEPROM_ERROR_COMMAND
        struct.pack_into("<H", m, r.EEPROM_CONTROL, status)  # done at once: never busy

    # ---- distributed clocks ---------------------------------------------------------------------
    def latch_receive_times(self, arrived_ns: int, returned_ns: int) -> None:
        """A write to 0x0900 passed: port 0's receive time (on the way out), port 1's (on the way
        back, where the frame went on to further slaves), the processing unit's 64-bit one."""
        m = self.mem
        struct.pack_into("<I", m, r.DC_RECEIVE_TIME_PORT0, self.local_time_ns(arrived_ns) & 0xFFFFFFFF)
        struct.pack_into("<I", m, r.DC_RECEIVE_TIME_PORT0 + 4, self.local_time_ns(returned_ns) & 0xFFFFFFFF)
        struct.pack_into("<Q", m, r.DC_RECEIVE_TIME_PU, self.local_time_ns(arrived_ns) & 0xFFFFFFFFFFFFFFFF)

    def _sync_activation(self, clock_ns: int, value: int) -> None:
        if value & 0x03 != 0x03 or not self.has_dc:
            self.sync0_next_ns = 0
            return
        start = int(struct.unpack_from("<Q", self.mem, r.DC_START_TIME)[0])
        self.sync0_next_ns = start if start > 0 else self.system_time_ns(clock_ns)

    @property
    def sync0_cycle_ns(self) -> int:
        return int(struct.unpack_from("<I", self.mem, r.DC_SYNC0_CYCLE)[0])

    @property
    def sync0_active(self) -> bool:
        return self.sync0_next_ns > 0

    def sync0_due(self, clock_ns: int) -> int:
        """SYNC0 pulses since the last call (0 or 1 when called every cycle; more after a gap)."""
        if not self.sync0_next_ns:
            return 0
        now = self.system_time_ns(clock_ns)
        if now < self.sync0_next_ns:
            return 0
        cycle = self.sync0_cycle_ns
        if cycle <= 0:  # single shot
            self.sync0_next_ns = 0
            return 1
        pulses = (now - self.sync0_next_ns) // cycle + 1
        self.sync0_next_ns += pulses * cycle
        return int(pulses)

    # ---- the SM watchdog --------------------------------------------------------------------------
    def poll(self, clock_ns: int) -> None:
        """Between frames: the process data watchdog."""
        self.clock_ns = clock_ns
        if self.al_state is not AlState.OP:
            return
        for sm in range(8):
            if not self.sm_enabled(sm):
                continue
            _start, _length, control, _activate = self.sm_config(sm)
            watched = control & r.SM_WATCHDOG and control & r.SM_DIRECTION_MASK == r.SM_DIRECTION_WRITE
            if watched and clock_ns - self.sm[sm].written_ns > self.watchdog_ns:
                self.mem[r.WATCHDOG_SM_STATUS] = 0x00
                self.app.watchdog_expired()
                self._set_al(AlState.SAFE_OP, AlStatusCode.SYNC_MANAGER_WATCHDOG)
                return

    @property
    def watchdog_ns(self) -> int:
        (divider,) = struct.unpack_from("<H", self.mem, r.WATCHDOG_DIVIDER)
        (units,) = struct.unpack_from("<H", self.mem, r.WATCHDOG_SM)
        return int(units * (divider + 2) * 40) if units else 1 << 62
