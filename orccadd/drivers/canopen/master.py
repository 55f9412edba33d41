"""The controller's side of a CANopen CiA 402 bus: startup over SDO, then the cyclic exchange.

Startup (`CanopenMaster.start`, before the control loop runs; blocking SDO through the
`canopen` library): our heartbeat starts at once, from a startup producer (python-can's periodic
send), so drives that watch it never starve while the startup and then the daemon's own setup
keep the loop from running; NMT reset, wait for every boot-up, configure each drive
(`startup.configure_drive`: modes, PDO mapping, heartbeats, COB-IDs, mode of operation shown);
NMT start; SYNC production through python-can's periodic send on SocketCAN (the kernel's
broadcast manager), else by the control loop itself once per tick, right after the RPDOs
(python-can would use a thread in the real-time process). Each bus (`port.BusPort`; one or
more, `settings.buses`) has its own drives, SYNC and heartbeat; the axes stay in joint order.
The resource then walks the drives to SWITCHED ON (the power stage still off) and leaves Enable
Operation to the loop's first ticks, once SYNC runs; the first tick of the loop takes the
heartbeat over (`loop_started`), so a stalled loop is one the drives notice.

    RPDO (0x200 + id):  controlword 0x6040 | target of the mode (0x607A or 0x60FF, 4 bytes)
                        | target torque 0x6071 (2 bytes) when the drive has CST, so the tasks
                        can switch between the mode and torque without remapping
    TPDO (0x180 + id):  statusword 0x6041 | position actual 0x6064 | torque actual 0x6077

Velocity is not mapped (it would not fit the 8 bytes): it is estimated from successive
positions. Cyclic part (`receive` at the start of a tick, `transmit` at its end; no thread, no
blocking call): frames already on every bus are drained and decoded (TPDOs, EMCY, heartbeats,
boot-ups, answers to our non-blocking SDO requests), watchdogs are checked (a TPDO missing for
`missed_tpdo_periods`, a heartbeat silent for 3 × `heartbeat_ms`, a drive that rebooted, a bus
error; with `tpdo_wait_us`, a tick first waits that long at most from its release for the TPDOs
answering each bus's last SYNC), and each axis's RPDO goes out with the controlword that the
resource's state asks for, then each bus's SYNC (the drives apply the RPDOs at once and sample
for the next tick's read), a tick's frames in one write per bus where the bus allows it (`port`).
"""

from __future__ import annotations

import logging
import select
import struct
import time
from dataclasses import dataclass

import can
import canopen
import numpy as np

from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.capabilities import MODE_CODES, object_dictionary
from orccadd.drivers.canopen.cia402 import CycleReport
from orccadd.drivers.canopen.pdo_mapping import abort_text
from orccadd.drivers.canopen.port import BusPort
from orccadd.drivers.canopen.settings import CanopenSettings
from orccadd.drivers.canopen.startup import CONTROLLER_NODE_ID, configure_drive
from orccadd.errors import ResourceError

POWERED = cia402.POWERED
_TARGET_OF = {cia402.MODE_CSP: 0x607A, cia402.MODE_CSV: 0x60FF, cia402.MODE_CST: 0x6071}
_TARGET_FMT = {0x607A: "i", 0x60FF: "i", 0x6071: "h"}

# python-can's socketcand client warns on every TCP read that ends mid-message
logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)


@dataclass
class AxisLink:
    """What the master knows of one drive (updated by `receive`)."""

    node_id: int
    name: str
    port: int  # index of its bus in `CanopenMaster.ports`
    counts_per_rad: float
    nm_per_mille: float
    has_torque_actual: bool
    statusword: int = 0
    position_counts: int = 0
    position_time_s: float = 0.0  # the frame's timestamp (kernel or hub receive time)
    prev_position_counts: int = 0
    prev_position_time_s: float = 0.0
    fresh: bool = False  # a TPDO arrived since the resource last looked
    tpdo_count: int = 0
    torque_per_mille: int = 0
    tpdo_seen_s: float = 0.0  # when the last TPDO was drained (0: none yet)
    tpdo_seen_sync: int = 0  # how many SYNCs we had sent then (loop-produced SYNC)
    heartbeat_s: float = 0.0
    emcy_code: int = 0
    emcy_text: str = ""
    rebooted: bool = False
    mode_code: int = 0
    mode_shown: int | None = None  # modes of operation display (0x6061) as last read
    sdo_pending: tuple[int, int, float] | None = None  # (index, sub, deadline_s) of a request
    sdo_error: str = ""
    controlword: int = 0
    consumer_ok: bool = False  # the drive watches our heartbeat
    rx_objects: tuple[int, ...] = ()  # the RPDO's targets after the controlword
    rx_format: str = "<H"

    @property
    def modes(self) -> frozenset[int]:
        """Modes this axis can be switched to at run time (its RPDO carries their targets)."""
        return frozenset(code for code, target in _TARGET_OF.items() if target in self.rx_objects)

    state: cia402.State = cia402.State.NOT_READY_TO_SWITCH_ON  # decoded from each statusword

    @property
    def where(self) -> str:
        return f"node {self.node_id} ({self.name})"


class CanopenMaster:
    def __init__(self, settings: CanopenSettings, joint_names: list[str], period_s: float) -> None:
        self.s = settings
        self.period_s = period_s
        self.names = joint_names
        self.ports = [BusPort(bus) for bus in settings.bus_list()]
        self.axes: list[AxisLink] = []
        self.tick = 0
        self._next_heartbeat_s = 0.0
        self._rx_tpdo: list[dict[int, AxisLink]] = [{} for _ in self.ports]  # per port: COB-ID -> axis
        self._by_id: list[dict[int, AxisLink]] = [{} for _ in self.ports]  # per port: node id -> axis
        self._sync_msg = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
        self._heartbeat_msg = can.Message(
            arbitration_id=0x700 + CONTROLLER_NODE_ID, data=b"\x05", is_extended_id=False
        )
        self._heartbeat_on_startup = False
        self._wait_s = settings.tpdo_wait_us * 1e-6

    @property
    def sync_by_kernel(self) -> bool:
        return all(p.sync_by_kernel for p in self.ports)

    @property
    def bus_error(self) -> str:
        return next((p.error for p in self.ports if p.error), "")

    @property
    def syncs_sent(self) -> int:
        """SYNCs the loop sent on the first bus (every bus gets one per tick)."""
        return self.ports[0].syncs_sent

    # ---- startup (blocking, before the loop) ------------------------------------------------
    def start(self) -> list[str]:
        """Open every bus and bring every drive to OPERATIONAL in its mode; warnings returned."""
        warnings: list[str] = []
        try:
            for port in self.ports:
                port.open()
                port.start_heartbeat(self._heartbeat_msg, self.s.controller_heartbeat_ms / 1000)
            self._heartbeat_on_startup = True
            self.axes = [None] * len(self.s.axes)  # type: ignore[list-item]  # filled per bus
            for port in self.ports:
                self._configure_drives(port, warnings)
        except (canopen.SdoAbortedError, canopen.SdoCommunicationError) as e:
            where = next((p.where for p in self.ports if p.nodes and p.network), self.ports[0].where)
            self.close()
            raise ResourceError(f"CAN bus {where}: SDO configuration failed: {e}") from None
        except ResourceError:
            self.close()
            raise
        now = time.monotonic()
        for k, port in enumerate(self.ports):
            self._by_id[k] = {self.axes[i].node_id: self.axes[i] for i in port.axes}
            self._rx_tpdo[k] = {0x180 + self.axes[i].node_id: self.axes[i] for i in port.axes}
            port.cyclic(self._sync_msg, self.period_s)
        for a in self.axes:
            a.heartbeat_s = now
        return warnings

    def loop_started(self) -> None:
        """The control loop ticks: from now on `transmit` produces our heartbeat, and the startup
        producers stop (a loop that stalls must go unheard by the drives). Tick-safe (stopping a
        task only raises its flag, or is one system call), idempotent."""
        if self._heartbeat_on_startup:
            self._heartbeat_on_startup = False
            self._next_heartbeat_s = 0.0  # the loop's first transmit sends one
            for port in self.ports:
                port.stop_heartbeat()

    @property
    def startup_heartbeat(self) -> bool:
        """Our heartbeat still comes from the startup producers (the loop has not ticked)."""
        return self._heartbeat_on_startup

    def _configure_drives(self, port: BusPort, warnings: list[str]) -> None:
        s, net = self.s, port.network
        assert net is not None
        for i in port.axes:
            node = canopen.RemoteNode(s.axes[i].node_id, object_dictionary(s.eds_paths[i], s.axes[i].node_id))
            node.sdo.RESPONSE_TIMEOUT = s.sdo_timeout_s
            net.add_node(node)
            port.nodes.append(node)
        self._reset_and_wait_for_bootups(port)
        k = self.ports.index(port)
        for i, node in zip(port.axes, port.nodes, strict=True):
            setup = configure_drive(node, s, i, self.names[i], self.period_s, warnings)
            self.axes[i] = self._link(i, k, setup.has_torque_actual, setup.consumer_ok, setup.rx_objects)
        for node in port.nodes:
            node.nmt.send_command(0x01)  # start: OPERATIONAL

    def _link(self, i: int, port: int, has_tq: bool, consumer_ok: bool, rx: tuple[int, ...]) -> AxisLink:
        ax, code = self.s.axes[i], MODE_CODES[self.s.mode]
        return AxisLink(
            node_id=ax.node_id,
            name=self.names[i],
            port=port,
            counts_per_rad=ax.counts_per_rev * ax.gear_ratio / (2 * np.pi),
            nm_per_mille=ax.gear_ratio * ax.rated_torque_nm / 1000.0,
            has_torque_actual=has_tq,
            mode_code=code,
            mode_shown=code,  # configure_drive saw it
            consumer_ok=consumer_ok,
            rx_objects=rx,
            rx_format="<H" + "".join(_TARGET_FMT[index] for index in rx),
        )

    def _reset_and_wait_for_bootups(self, port: BusPort) -> None:
        """NMT reset node on every drive of `port`; every boot-up message seen (in any order) or
        an error."""
        net = port.network
        assert net is not None
        booted: set[int] = set()

        def on_boot(can_id: int, data: bytearray, timestamp: float) -> None:
            if len(data) >= 1 and data[0] == 0:
                booted.add(can_id - 0x700)

        ids = [self.s.axes[i].node_id for i in port.axes]
        for i in ids:
            net.subscribe(0x700 + i, on_boot)
        try:
            for node in port.nodes:
                node.nmt.send_command(0x81)
            end = time.monotonic() + self.s.startup_timeout_s
            while not booted.issuperset(ids) and time.monotonic() < end:
                time.sleep(0.01)
        finally:
            for i in ids:
                net.unsubscribe(0x700 + i, on_boot)
        missing = [f"{n} ({self.names[i]})" for i, n in zip(port.axes, ids, strict=True) if n not in booted]
        if missing:
            raise ResourceError(
                f"CAN bus {port.where}: node {', '.join(missing)} did not boot within "
                f"{self.s.startup_timeout_s:g} s after NMT reset (wrong node id, bus, or power?)"
            )

    # ---- cyclic part (tick-safe: no blocking call, no allocation beyond frames) --------------
    def receive(self, now_s: float) -> CycleReport:
        """Drain every bus and check the watchdogs (start of a tick): the TPDOs the drives sent
        for the previous tick's SYNC, on every bus, are in before the tick computes."""
        self.tick += 1
        rep = CycleReport()
        for k, port in enumerate(self.ports):
            if port.bus is None:
                rep.comm_lost = rep.comm_lost or f"CAN bus {port.where}: closed"
                continue
            self._drain(k, now_s)
        if rep.comm_lost:
            return rep
        if self._wait_s:
            self._gather(now_s)
        bus_error = self.bus_error
        if bus_error:
            rep.comm_lost = bus_error
        hb_timeout = 3 * self.s.heartbeat_ms / 1000
        tpdo_timeout = self.s.missed_tpdo_periods * self.period_s
        for a in self.axes:
            lost = ""
            if a.rebooted:
                lost = f"node {a.node_id} ({a.name}) rebooted (boot-up message)"
            elif a.tpdo_seen_s and self._tpdo_missing(a, now_s, tpdo_timeout):
                lost = (
                    f"node {a.node_id} ({a.name}) silent: no TPDO for {(now_s - a.tpdo_seen_s) * 1e3:.0f} ms "
                    f"(> {self.s.missed_tpdo_periods} SYNC periods)"
                )
            elif now_s - a.heartbeat_s > hb_timeout:
                lost = (
                    f"node {a.node_id} ({a.name}): heartbeat lost ({(now_s - a.heartbeat_s) * 1e3:.0f} ms "
                    f"> 3 × {self.s.heartbeat_ms} ms)"
                )
            if lost and not rep.comm_lost:
                rep.comm_lost, rep.comm_lost_joint = lost, a.name
            if (
                a.state is cia402.State.FAULT or a.state is cia402.State.FAULT_REACTION_ACTIVE
            ) and not rep.fault:
                code = a.emcy_code
                rep.fault = f"node {a.node_id} ({a.name}): drive fault" + (
                    f", EMCY 0x{code:04X} {a.emcy_text}" if code else ""
                )
                rep.fault_code, rep.fault_joint = code, a.name
            if a.sdo_pending is not None and now_s > a.sdo_pending[2]:
                a.sdo_error = (
                    f"node {a.node_id} ({a.name}): no answer to SDO request 0x{a.sdo_pending[0]:04X}"
                )
                a.sdo_pending = None
            if a.sdo_error and not rep.comm_lost:
                rep.comm_lost, rep.comm_lost_joint = a.sdo_error, a.name
        return rep

    def _drain(self, k: int, now_s: float) -> None:
        """Every frame already received on bus `k`, decoded."""
        port = self.ports[k]
        bus, rx_tpdo, by_id = port.bus, self._rx_tpdo[k], self._by_id[k]
        assert bus is not None
        try:
            while True:
                msg = bus.recv(0.0)
                if msg is None:
                    break
                self._frame(msg, now_s, port, rx_tpdo, by_id)
        except (can.CanError, OSError) as e:
            port.error = port.error or f"CAN bus {port.where}: {e}"

    def _gather(self, now_s: float) -> None:
        """Wait, until `tpdo_wait_us` after the tick's release at most, for the TPDOs that answer
        the SYNC each bus got last (loop SYNC only; a bus that fails stops the wait): an axis is
        behind while its newest TPDO is time-stamped (by the kernel, or the socketcand server:
        this host's clock) before that SYNC left. A lost TPDO costs one tick its wait."""
        deadline_s = now_s + self._wait_s
        while True:
            waiting = [
                k
                for k, port in enumerate(self.ports)
                if port.cyclic_started
                and port.fileno >= 0
                and not port.sync_by_kernel
                and not port.error
                and any(self.axes[i].position_time_s < port.sync_wall_s for i in port.axes)
            ]
            timeout_s = deadline_s - time.monotonic()
            if not waiting or timeout_s <= 0:
                return
            try:
                ready, _, _ = select.select([self.ports[k].fileno for k in waiting], [], [], timeout_s)
            except (OSError, ValueError) as e:
                self.ports[waiting[0]].error = f"CAN bus {self.ports[waiting[0]].where}: {e}"
                return
            for k in waiting:
                if self.ports[k].fileno in ready:
                    self._drain(k, now_s)

    def _tpdo_missing(self, a: AxisLink, now_s: float, timeout_s: float) -> bool:
        """Kernel SYNC: by time. Loop SYNC: by SYNCs sent since (a stalled loop sent none, and
        its drives owe nothing)."""
        port = self.ports[a.port]
        if port.sync_by_kernel:
            return now_s - a.tpdo_seen_s > timeout_s
        return port.syncs_sent - a.tpdo_seen_sync > self.s.missed_tpdo_periods

    def _frame(
        self,
        msg: can.Message,
        now_s: float,
        port: BusPort,
        rx_tpdo: dict[int, AxisLink],
        by_id: dict[int, AxisLink],
    ) -> None:
        cob = msg.arbitration_id
        if msg.is_extended_id or msg.is_error_frame:
            return
        a = rx_tpdo.get(cob)
        data = msg.data
        if a is not None:
            if len(data) >= 6:
                a.prev_position_counts, a.prev_position_time_s = a.position_counts, a.position_time_s
                statusword, a.position_counts = struct.unpack_from("<Hi", data, 0)
                if statusword != a.statusword:
                    a.statusword = statusword
                    a.state = cia402.decode_state(statusword)
                a.position_time_s = msg.timestamp
                a.fresh = True
                a.tpdo_count += 1
                if a.has_torque_actual and len(data) >= 8:
                    a.torque_per_mille = struct.unpack_from("<h", data, 6)[0]
                a.tpdo_seen_s = now_s
                a.tpdo_seen_sync = port.syncs_sent
            return
        a = by_id.get(cob & 0x7F)
        if a is None:
            return
        kind = cob & 0x780
        if kind == 0x700:
            a.heartbeat_s = now_s
            if len(data) >= 1 and data[0] == 0:
                a.rebooted = True
        elif kind == 0x080 and len(data) >= 3:
            a.emcy_code = struct.unpack_from("<H", data, 0)[0]
            a.emcy_text = cia402.error_code_text(a.emcy_code)
        elif kind == 0x580 and a.sdo_pending is not None and len(data) >= 8:
            self._sdo_answer(a, bytes(data))

    def _sdo_answer(self, a: AxisLink, data: bytes) -> None:
        """The answer to our pending non-blocking SDO request: an abort is an error; an
        expedited upload of 0x6061 is the mode shown."""
        index, sub = struct.unpack_from("<HB", data, 1)
        if a.sdo_pending is None or (index, sub) != a.sdo_pending[:2]:
            return
        if data[0] == 0x80:
            code = struct.unpack_from("<I", data, 4)[0]
            where = f"0x{index:04X}:{sub:02X}"
            a.sdo_error = f"node {a.node_id} ({a.name}): SDO request {where} refused, {abort_text(code)}"
        elif index == 0x6061 and data[0] & 0xE2 == 0x42:  # expedited upload
            a.mode_shown = struct.unpack_from("<b", data, 4)[0]
        a.sdo_pending = None

    def transmit(
        self, now_s: float, position_rad: np.ndarray, velocity_rad_s: np.ndarray, torque_nm: np.ndarray
    ) -> None:
        """One RPDO per axis (end of a tick): its controlword and every target it carries, the
        active mode's from the command and the others holding (consistent while a mode switch
        is under way); then each bus's SYNC (when the loop produces it) and our heartbeat when
        due; a bus's frames in one write where it allows (`BusPort.flush`)."""
        ports = self.ports
        for j, a in enumerate(self.axes):
            values = []
            for index in a.rx_objects:
                if index == 0x607A:
                    values.append(round(float(position_rad[j]) * a.counts_per_rad))
                elif index == 0x60FF:
                    values.append(round(float(velocity_rad_s[j]) * a.counts_per_rad))
                else:
                    values.append(_per_mille(float(torque_nm[j]), a))
            body = struct.pack(a.rx_format, a.controlword, *values)
            ports[a.port].queue(
                can.Message(arbitration_id=0x200 + a.node_id, data=body, is_extended_id=False)
            )
        heartbeat = now_s >= self._next_heartbeat_s and not self._heartbeat_on_startup
        if heartbeat:
            self._next_heartbeat_s = now_s + self.s.controller_heartbeat_ms / 1000
        for port in ports:
            if not port.sync_by_kernel and port.cyclic_started:
                port.queue(self._sync_msg)
                port.syncs_sent += 1
                port.sync_wall_s = time.time()  # (before it leaves: its answers are stamped later)
            if heartbeat:
                port.queue(self._heartbeat_msg)
            port.flush()

    # ---- controlwords (the CiA 402 state machine, driven one step per cycle) ---------------------
    def set_controlword(self, cw: int) -> None:
        """The same controlword for every axis from the next RPDO on."""
        for a in self.axes:
            a.controlword = cw

    def clear_faults(self) -> None:
        """Forget the drives' last EMCY and SDO errors (before a fault reset)."""
        for a in self.axes:
            a.sdo_error = ""
            a.emcy_code = 0
            a.emcy_text = ""

    def write_mode(self, code: int) -> None:
        """Ask every drive for mode `code` (0x6060) by a non-blocking SDO write; answers are
        matched in `receive`, a refusal or silence becomes a communication fault."""
        deadline = time.monotonic() + self.s.sdo_timeout_s
        req = struct.pack("<BHBb3x", 0x2F, 0x6060, 0, code)
        for a in self.axes:
            a.sdo_pending = (0x6060, 0, deadline)
            a.mode_code = code
            self.ports[a.port].queue(
                can.Message(arbitration_id=0x600 + a.node_id, data=req, is_extended_id=False)
            )
        for port in self.ports:
            port.flush()

    def request_mode_display(self) -> None:
        """Ask every drive for its modes of operation display (0x6061) by a non-blocking SDO
        upload; `AxisLink.mode_shown` gets the answer in `receive` (None until then)."""
        deadline = time.monotonic() + self.s.sdo_timeout_s
        req = struct.pack("<BHB4x", 0x40, 0x6061, 0)
        for a in self.axes:
            a.sdo_pending = (0x6061, 0, deadline)
            a.mode_shown = None
            self.ports[a.port].queue(
                can.Message(arbitration_id=0x600 + a.node_id, data=req, is_extended_id=False)
            )
        for port in self.ports:
            port.flush()

    # ---- shutdown ------------------------------------------------------------------------------
    def close(self) -> None:
        """Disable voltage on every drive (power stage off, brakes on), then close every bus."""
        for k, port in enumerate(self.ports):
            last = [
                can.Message(
                    arbitration_id=0x200 + a.node_id,
                    data=struct.pack(a.rx_format, 0, *(0 for _ in a.rx_objects)),
                    is_extended_id=False,
                )
                for a in self.axes
                if a is not None and a.port == k
            ]
            port.close(last)
        self._heartbeat_on_startup = False


def _per_mille(tau_nm: float, a: AxisLink) -> int:
    return max(-32768, min(32767, round(tau_nm / a.nm_per_mille)))
