"""The controller's side of an EtherCAT line of CiA 402 drives, through SOEM (pysoem).

Startup (`EcatMaster.start`, before the control loop runs; blocking): the interface checked (it
exists and is up), the line scanned (`config_init`: as many slaves as joints, each one's identity
as the config says: vendor id, product code, revision), PRE-OP, each drive configured over CoE
SDO (the PDO mapping of `pdo.layout_for` in `rx_pdo`/`tx_pdo` and their assignment to SM2/SM3,
the mode of operation, the interpolation period, the following error window, the quick stop
deceleration (the config's safe stop's), the sync managers' synchronisation: DC SYNC0 or
SM-synchronous), the distributed clocks (`config_dc`, SYNC0 at the
control period on every slave), the process data image (`config_map`), SAFE-OP. Every state
change waits `state_timeout_s` and a refusal names the slave, its joint and its AL status code.
OP comes from the resource, once the cyclic exchange runs (a slave takes OP only with outputs,
and with DC once SYNC0 runs).

Cyclic part (no thread, no waiting beyond the frame): `receive` at the start of a tick takes the
frame `transmit` sent at the end of the last one (one LRW through every slave; with DC one FRMW of
the reference clock's time behind it), checks its working counter against the expected one (a
frame that did not come back, or came back short, is counted; `lost_frames` in a row is a lost
line, naming where the count stops) and decodes each drive's inputs; `transmit` packs each
drive's outputs (controlword, the mode's target, the mode) and sends the next frame. SOEM waits
for a frame with the interpreter released (`always_release_gil`).
"""

from __future__ import annotations

import fcntl
import logging
import os
import socket
import struct
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pysoem

from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.capabilities import MODE_CODES, object_dictionary
from orccadd.drivers.canopen.cia402 import CycleReport
from orccadd.drivers.canopen.startup import interpolation_time_period
from orccadd.drivers.ethercat.pdo import PdoLayout, layout_for
from orccadd.drivers.ethercat.settings import TARGET_OF_MODE, EthercatSettings
from orccadd.errors import ResourceError

log = logging.getLogger("orccadd.ethercat")

AL_NAMES = {1: "INIT", 2: "PRE-OP", 3: "BOOT", 4: "SAFE-OP", 8: "OP"}
AL_ERROR = 0x10
AL_NO_SYNC = 0x002D  # SYNC0 not seen yet: OP asked too early, asked again
SIOCGIFFLAGS = 0x8913
SCAN_RETRIES = 3
IFF_UP, IFF_RUNNING = 0x1, 0x40


def al_state_name(state: int) -> str:
    name = AL_NAMES.get(state & 0x0F, f"state 0x{state & 0x0F:X}")
    return name + (" + ERROR" if state & AL_ERROR else "")


def check_interface(name: str) -> None:
    """ResourceError unless `name` is a network interface of this network namespace that is up
    and has its link (asked of the kernel: /sys/class/net shows the namespace sysfs was mounted in)."""
    names = sorted(n for _, n in socket.if_nameindex())
    if name not in names:
        raise ResourceError(
            f"network interface {name!r} does not exist (interfaces here: {', '.join(names)})"
        )
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        ifreq = fcntl.ioctl(s, SIOCGIFFLAGS, struct.pack("16sH14x", name.encode()[:15], 0))
    (flags,) = struct.unpack_from("H", ifreq, 16)
    if not flags & IFF_UP:
        raise ResourceError(f"network interface {name!r} is down: ip link set {name} up")
    if not flags & IFF_RUNNING:
        raise ResourceError(f"network interface {name!r} has no link: its cable, the line's power")


def _socket_fds() -> set[int]:
    """This process's open sockets (their descriptors)."""
    out = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{name}").startswith("socket:"):
                out.add(int(name))
        except OSError:
            continue  # closed meanwhile
    return out


def _never_block(fd: int) -> None:
    """SOEM's raw socket made non-blocking. SOEM reads it with a receive timeout of 1 µs, which
    the kernel rounds up to a scheduler tick (4 ms at HZ=250): every read that finds no frame
    then blocked that long, and a tick whose frame was lost took 8 ms instead of the receive
    timeout. Non-blocking, such a read returns at once and SOEM's own timer bounds the wait."""
    try:
        probe = socket.socket(fileno=os.dup(fd))
    except OSError:
        return
    try:
        if probe.family == socket.AF_PACKET:
            probe.setblocking(False)  # the flag is the open file's: SOEM's descriptor shares it
    finally:
        probe.close()


@dataclass
class DriveLink:
    """What the master knows of one drive (updated by `receive`)."""

    position: int  # on the line, 1-based
    name: str  # its joint
    counts_per_rad: float
    nm_per_mille: float
    layout: PdoLayout
    rx: struct.Struct = field(init=False)
    tx: struct.Struct = field(init=False)
    statusword: int = 0
    state: cia402.State = cia402.State.NOT_READY_TO_SWITCH_ON
    controlword: int = 0
    mode: int = cia402.MODE_CSP
    mode_shown: int = 0
    position_counts: int = 0
    velocity_counts: int = 0
    torque_per_mille: int = 0
    error_code: int = 0
    fresh: int = 0  # inputs decoded since startup
    emergency: str = ""  # the last CoE emergency read from its mailbox, in words ("" once reset)
    identity: str = ""  # as the scan found it

    def __post_init__(self) -> None:
        self.rx = struct.Struct(self.layout.rx_format)
        self.tx = struct.Struct(self.layout.tx_format)

    @property
    def where(self) -> str:
        return f"slave {self.position} ({self.name})"


class EcatMaster:
    def __init__(
        self,
        settings: EthercatSettings,
        joint_names: list[str],
        period_s: float,
        stop_deceleration_rad_s2: float,
    ) -> None:
        self.s = settings
        self.stop_deceleration_rad_s2 = stop_deceleration_rad_s2
        self.names = joint_names
        self.period_s = period_s
        self.period_ns = int(round(period_s * 1e9))
        self.m: Any = None  # pysoem.Master once open
        self.drives: list[DriveLink] = []
        self.expected_wkc = 0
        self.sent = False  # a frame is out, its answer not taken yet
        self.frames = 0
        self.frames_lost = 0  # no answer within the receive timeout
        self.wkc_errors = 0  # an answer with a working counter short of the expected one
        self.bad_in_row = 0
        self.last_wkc = 0
        self.dc_time_ns = 0
        self.al_lost = ""  # a slave found out of OP while the line should be in OP (words), else ""
        self.al_lost_joint = ""
        self.in_op = False  # every slave reached OP: from then on, one that leaves it is a fault
        self._al_suspect: tuple[int, int] | None = None  # (slave, state) read once out of OP
        self.sent_at_ns = 0  # CLOCK_MONOTONIC when the last frame left
        self.dc_offset_ns: int | None = None  # the reference clock's system time minus ours
        self._timeout_us = settings.receive_timeout_us or max(100, int(period_s * 1e6 / 3))
        for i, (sl, eds) in enumerate(zip(settings.slaves, settings.eds_paths, strict=True)):
            counts_per_rad = sl.counts_per_rev * sl.gear_ratio / (2 * np.pi)
            layout = layout_for(object_dictionary(eds, 1))
            self.drives.append(
                DriveLink(
                    i + 1, joint_names[i], counts_per_rad, sl.gear_ratio * sl.rated_torque_nm / 1000, layout
                )
            )
        self._mode = MODE_CODES[settings.mode]

    # ---- startup -----------------------------------------------------------------------------
    def start(self) -> list[str]:
        """Open the line and take every slave to SAFE-OP (see the module's doc)."""
        s = self.s
        check_interface(s.interface)
        m = pysoem.Master()
        m.always_release_gil = True
        m.manual_state_change = 1  # every state change is ours
        m.sdo_read_timeout = m.sdo_write_timeout = int(s.sdo_timeout_s * 1e6)
        before = _socket_fds()
        try:
            m.open(s.interface)
        except (ConnectionError, OSError) as e:
            who = "root" if os.geteuid() == 0 else f"uid {os.geteuid()}"
            raise ResourceError(
                f"cannot open {s.interface} for EtherCAT ({e}; as {who}): a raw socket needs root or "
                "CAP_NET_RAW (docs/install.md)"
            ) from None
        self.m = m
        for fd in _socket_fds() - before:
            _never_block(fd)
        found = m.config_init()
        for _ in range(SCAN_RETRIES):  # the scan waits 20 ms for its broadcast: a line may be slower
            if found > 0:
                break
            time.sleep(0.1)
            found = m.config_init()
        if found <= 0:
            raise ResourceError(f"no EtherCAT slave answers on {s.interface}: the line's cable and power")
        if found != len(self.drives):
            raise ResourceError(
                f"{found} EtherCAT slaves on {s.interface}, the config has {len(self.drives)} "
                f"({', '.join(self.names)})"
            )
        self._check_identities()
        for d, slave in zip(self.drives, m.slaves, strict=True):
            ident = f"vendor 0x{slave.man:08X}, product 0x{slave.id:08X}, revision 0x{slave.rev:08X}"
            d.identity = f"{slave.name}: {ident}"
            slave.add_emergency_callback(lambda e, d=d: self._emergency(d, e))
        self._walk_al(pysoem.PREOP_STATE)
        for d in self.drives:
            self._configure_drive(d)
        warnings: list[str] = []
        if s.distributed_clocks:
            if not m.config_dc():
                raise ResourceError(
                    f"no slave on {s.interface} has distributed clocks (distributed_clocks = false)"
                )
            shift_ns = s.sync0_shift_us * 1000 or self.period_ns * 3 // 4
            for slave in m.slaves:
                slave.dc_sync(True, self.period_ns, shift_ns)
        size = m.config_map()
        want = sum(d.layout.rx_bytes + d.layout.tx_bytes for d in self.drives)
        if size != want:
            raise ResourceError(
                f"the process data image on {s.interface} is {size} bytes, the mapping {want}"
            )
        self.expected_wkc = int(m.expected_wkc)
        self._walk_al(pysoem.SAFEOP_STATE)
        return warnings

    def _check_identities(self) -> None:
        for d, sl, slave in zip(self.drives, self.s.slaves, self.m.slaves, strict=True):
            got = (slave.man, slave.id, slave.rev)
            want = (sl.vendor_id, sl.product_code, sl.revision or slave.rev)
            if got != want:
                raise ResourceError(
                    f"{d.where} on {self.s.interface} is {slave.name!r}: vendor 0x{got[0]:08X}, product "
                    f"0x{got[1]:08X}, revision 0x{got[2]:08X}; the config expects vendor 0x{want[0]:08X}, "
                    f"product 0x{want[1]:08X}" + (f", revision 0x{sl.revision:08X}" if sl.revision else "")
                )

    def _sdo_write(self, d: DriveLink, index: int, sub: int, data: bytes) -> None:
        try:
            self.m.slaves[d.position - 1].sdo_write(index, sub, data)
        except pysoem.SdoError as e:
            raise ResourceError(
                f"{d.where}: SDO write 0x{index:04X}:{sub:02X} aborted 0x{e.abort_code:08X} ({e.desc})"
            ) from None
        except (pysoem.WkcError, pysoem.MailboxError, pysoem.PacketError) as e:
            raise ResourceError(f"{d.where}: SDO write 0x{index:04X}:{sub:02X} failed ({e!r})") from None

    def _configure_drive(self, d: DriveLink) -> None:
        """The PDO mapping and assignment (ETG.1000.6 order: count 0, entries, count), the mode,
        the interpolation period, the following error window, the synchronisation."""
        sl = self.s.slaves[d.position - 1]
        od = object_dictionary(self.s.eds_paths[d.position - 1], 1)
        u8, u16, u32 = (struct.Struct(f) for f in ("<B", "<H", "<I"))
        for assign, pdo, transmit in ((0x1C12, sl.rx_pdo, False), (0x1C13, sl.tx_pdo, True)):
            entries = d.layout.entries(transmit)
            self._sdo_write(d, assign, 0, u8.pack(0))
            self._sdo_write(d, pdo, 0, u8.pack(0))
            for k, entry in enumerate(entries, 1):
                self._sdo_write(d, pdo, k, u32.pack(entry))
            self._sdo_write(d, pdo, 0, u8.pack(len(entries)))
            self._sdo_write(d, assign, 1, u16.pack(pdo))
            self._sdo_write(d, assign, 0, u8.pack(1))
        d.mode = self._mode
        self._sdo_write(d, 0x6060, 0, struct.pack("<b", self._mode))
        if 0x60C2 in od:  # the drive interpolates (its CSP velocity feed-forward) over the period
            value, exponent = interpolation_time_period(self.period_s)
            self._sdo_write(d, 0x60C2, 1, u8.pack(value))
            self._sdo_write(d, 0x60C2, 2, struct.pack("<b", exponent))
        if 0x6085 in od:  # quick stop: the config's safe stop deceleration
            decel = round(self.stop_deceleration_rad_s2 * d.counts_per_rad)
            self._sdo_write(d, 0x6085, 0, u32.pack(min(decel, 0xFFFFFFFF)))
        if 0x6065 in od:
            window = round(self.s.following_error_rad * d.counts_per_rad)
            self._sdo_write(d, 0x6065, 0, u32.pack(min(window, 0xFFFFFFFE)))
        if 0x6066 in od:
            self._sdo_write(d, 0x6066, 0, u16.pack(self.s.following_error_timeout_ms))
        sync = 2 if self.s.distributed_clocks else 1
        for index in (0x1C32, 0x1C33):
            if index in od:
                self._sdo_write(d, index, 1, u16.pack(sync))
                self._sdo_write(d, index, 2, u32.pack(self.period_ns))

    def watch_states(self) -> None:
        """Whether every slave is still in OP (AL status frames beside the cyclic exchange: a
        lifecycle thread, only while the line answers). A slave that left OP (its SM watchdog, a
        cable pulled and put back, its own error) keeps its place in the working counter in
        SAFE-OP, but no longer takes its outputs: `receive` reports it as a lost slave. Only a
        state that is one (1, 2, 3, 4 or 8, with or without the error bit) read twice in a row
        with the line answering counts: a frame answered very late can be taken by SOEM as the
        answer to a later request (0x0F, every state's bit, was read once after a 1.4 s stall)."""
        if not self.in_op or self.bad_in_row or self.m is None or self.al_lost:
            return
        states = self.states()
        if self.bad_in_row:
            return
        out = [
            (d, state, code)
            for d, (state, code) in zip(self.drives, states, strict=True)
            if state != pysoem.OP_STATE
        ]
        if not out or any(state & 0x0F not in AL_NAMES for _, state, _ in out):
            self._al_suspect = None
            return
        d, state, code = out[0]
        if self._al_suspect != (d.position, state):
            self._al_suspect = (d.position, state)  # seen once: confirmed by the next read
            return
        why = f", AL status code 0x{code:04X} ({pysoem.al_status_code_to_string(code)})" if code else ""
        self.al_lost_joint = d.name
        self.al_lost = f"EtherCAT: {d.where} left OP, now {al_state_name(state)}{why}"

    # ---- CoE emergencies --------------------------------------------------------------------------
    def _emergency(self, d: DriveLink, e: Any) -> None:
        text = cia402.error_code_text(e.error_code)
        d.emergency = (
            f"EMCY 0x{e.error_code:04X}"
            + (f" {text}" if text else "")
            + f", error register 0x{e.error_reg:02X}"
        )

    def read_emergencies(self) -> None:
        """Read the mailbox of every drive in FAULT whose emergency is not known yet (mailbox
        frames beside the cyclic exchange: lifecycle threads only, and only while the line
        answers)."""
        if self.bad_in_row or self.m is None:
            return
        for d, slave in zip(self.drives, self.m.slaves, strict=True):
            if d.state is cia402.State.FAULT and not d.emergency:
                try:
                    slave.mbx_receive()  # an emergency there reaches `_emergency`
                except (pysoem.MailboxError, pysoem.PacketError, pysoem.WkcError, pysoem.SdoError) as e:
                    log.debug("%s: mailbox: %s", d.where, e)

    def forget_emergencies(self) -> None:
        for d in self.drives:
            d.emergency = ""

    # ---- the application layer's states --------------------------------------------------------
    def _walk_al(self, target: int) -> None:
        """Every slave to `target`, within `state_timeout_s`; ResourceError naming who did not."""
        m = self.m
        m.state = target
        m.write_state()
        deadline = time.monotonic() + self.s.state_timeout_s
        while True:
            if m.state_check(target, 2000) == target:
                return
            if time.monotonic() > deadline:
                raise ResourceError(self.state_refusal(target))
            time.sleep(0.005)

    def states(self) -> list[tuple[int, int]]:
        """(AL state, AL status code) of every slave, read now (frames: lifecycle only)."""
        self.m.read_state()
        return [(int(slave.state), int(slave.al_status)) for slave in self.m.slaves]

    def state_refusal(self, target: int) -> str:
        """Which slaves are not in `target`, and why, in words."""
        parts = []
        for d, (state, code) in zip(self.drives, self.states(), strict=True):
            if state != target:
                why = (
                    f", AL status code 0x{code:04X} ({pysoem.al_status_code_to_string(code)})" if code else ""
                )
                parts.append(f"{d.where} in {al_state_name(state)}{why}")
        limit = self.s.state_timeout_s
        return f"{al_state_name(target)} not reached within {limit:g} s (state_timeout_s): " + "; ".join(
            parts
        )

    def step_operational(self) -> bool:
        """One try towards OP on every slave (the cyclic exchange running meanwhile): an error
        acknowledged, OP asked; True once every slave is in OP."""
        states = self.states()
        if all(state == pysoem.OP_STATE for state, _ in states):
            self.in_op = True
            self.al_lost = self.al_lost_joint = ""
            self._al_suspect = None
            return True
        for slave, (state, _code) in zip(self.m.slaves, states, strict=True):
            if state & AL_ERROR or state != pysoem.OP_STATE:
                slave.state = pysoem.OP_STATE | (pysoem.STATE_ACK if state & AL_ERROR else 0)
                slave.write_state()
        return False

    # ---- the cyclic exchange ------------------------------------------------------------------------
    def receive(self) -> CycleReport:
        """The answer to the last frame: the working counter checked, each drive's inputs."""
        rep = CycleReport()
        if not self.sent:
            return rep
        self.sent = False
        wkc = int(self.m.receive_processdata(self._timeout_us))
        self.last_wkc = wkc
        if wkc == self.expected_wkc:
            self.bad_in_row = 0
            self.dc_time_ns = int(self.m.dc_time)
            if self.dc_time_ns and self.sent_at_ns:  # the frame passed the reference clock just after it left
                measured = self.dc_time_ns - self.sent_at_ns
                offset = self.dc_offset_ns
                self.dc_offset_ns = measured if offset is None else offset + (measured - offset) // 16
            for d, slave in zip(self.drives, self.m.slaves, strict=True):
                self._decode(d, slave.input)
        else:
            self.bad_in_row += 1
            if wkc <= 0:
                self.frames_lost += 1
            else:
                self.wkc_errors += 1
            if self.bad_in_row >= self.s.lost_frames:
                rep.comm_lost, rep.comm_lost_joint = self._lost_words(wkc)
        if self.al_lost and not rep.comm_lost:
            rep.comm_lost, rep.comm_lost_joint = self.al_lost, self.al_lost_joint
        for d in self.drives:
            if d.state in (cia402.State.FAULT, cia402.State.FAULT_REACTION_ACTIVE) and not rep.fault:
                text = cia402.error_code_text(d.error_code)
                rep.fault = f"{d.where}: drive fault" + (
                    f", error code 0x{d.error_code:04X}" + (f" {text}" if text else "")
                    if d.error_code
                    else ""
                )
                if d.emergency:
                    rep.fault += f" ({d.emergency})"
                rep.fault_code, rep.fault_joint = d.error_code, d.name
        return rep

    def _decode(self, d: DriveLink, data: bytes) -> None:
        values = dict(zip(d.layout.tx, d.tx.unpack_from(data), strict=True))
        d.statusword = values[0x6041]
        d.state = cia402.decode_state(d.statusword)
        d.position_counts = values[0x6064]
        d.velocity_counts = values.get(0x606C, 0)
        d.torque_per_mille = values.get(0x6077, 0)
        d.mode_shown = values.get(0x6061, d.mode)
        d.error_code = values.get(0x603F, 0)
        d.fresh += 1

    def _lost_words(self, wkc: int) -> tuple[str, str]:
        iface, n = self.s.interface, self.s.lost_frames  # fixed words: a fault is recorded once
        if wkc <= 0:
            first = self.drives[0]
            return (
                f"EtherCAT line on {iface}: {n} frames in a row did not come back (from {first.where} on)",
                first.name,
            )
        per_slave = self.expected_wkc // max(1, len(self.drives))
        answering = wkc // per_slave if per_slave else 0
        if 0 <= answering < len(self.drives):
            d = self.drives[answering]
            return (
                f"EtherCAT line on {iface}: working counter {wkc} of {self.expected_wkc} for {n} frames in a "
                f"row: {d.where} and after it are not on the line",
                d.name,
            )
        return (
            f"EtherCAT line on {iface}: working counter {wkc} of {self.expected_wkc} for {n} frames in a row",
            "",
        )

    def transmit(self, pos_rad: np.ndarray, vel_rad_s: np.ndarray, tau_nm: np.ndarray) -> None:
        """Each drive's outputs (controlword, targets, mode), then the frame."""
        for j, (d, slave) in enumerate(zip(self.drives, self.m.slaves, strict=True)):
            values = []
            for index in d.layout.rx:
                if index == 0x6040:
                    values.append(d.controlword)
                elif index == 0x607A:
                    values.append(round(pos_rad[j] * d.counts_per_rad))
                elif index == 0x60FF:
                    values.append(round(vel_rad_s[j] * d.counts_per_rad))
                elif index == 0x6071:
                    values.append(max(-32768, min(32767, round(tau_nm[j] / d.nm_per_mille))))
                else:  # 0x6060
                    values.append(d.mode)
            slave.output = d.rx.pack(*values)
        self.sent_at_ns = time.monotonic_ns()
        self.m.send_processdata()
        self.sent = True
        self.frames += 1

    def next_cycle_ns(self, now_ns: int) -> int:
        """When the next cycle starts on our clock: the next multiple of the period on the
        reference clock's time (SYNC0 comes `sync0_shift` after it), before the first frame with
        the reference time back, a period from now."""
        offset = self.dc_offset_ns
        if offset is None:
            return now_ns + self.period_ns
        return ((now_ns + offset) // self.period_ns + 1) * self.period_ns - offset

    # ---- CiA 402 --------------------------------------------------------------------------------
    def set_controlword(self, cw: int) -> None:
        for d in self.drives:
            d.controlword = cw

    def set_mode(self, code: int) -> None:
        """The mode of operation the next frame carries (0x6060 is in the RxPDO)."""
        for d in self.drives:
            d.mode = code

    def modes(self) -> frozenset[int]:
        """The modes every drive's RxPDO carries a target for."""
        out = set()
        for code_name, index in TARGET_OF_MODE.items():
            if all(index in d.layout.rx for d in self.drives):
                out.add(MODE_CODES[code_name])
        return frozenset(out)

    # ---- shutdown ----------------------------------------------------------------------------------
    def close(self) -> None:
        """Power stages off (disable voltage) in one last frame, the slaves to INIT, the socket closed."""
        m = self.m
        if m is None:
            return
        try:
            if self.expected_wkc:  # the process image is mapped: one last frame, power stages off
                if self.sent:
                    self.receive()
                self.set_controlword(cia402.CW_DISABLE_VOLTAGE)
                zeros = np.zeros(len(self.drives))
                self.transmit(zeros, zeros, zeros)
                self.receive()
            m.state = pysoem.INIT_STATE
            m.write_state()
        except Exception as e:  # closing whatever state the line is in
            log.warning("EtherCAT on %s: closing: %s", self.s.interface, e)
        finally:
            m.close()
            self.m = None
