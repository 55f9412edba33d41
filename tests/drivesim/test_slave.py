"""The simulated CANopen slave against canopen's own master, on python-can's in-process bus."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import can
import canopen
import pytest

from orccadd.drivers.canopen.startup import write_cob_id
from orccadd.drivesim.slave import Nmt, SlaveNode
from tests.canopen_rig import sdo_downloads
from tests.conftest import eds

NODE = 5


class Harness:
    """A slave node served by a thread on one end of a virtual bus, canopen's master on the other."""

    def __init__(self, eds_file: str, strict_cob_ids: bool = True) -> None:
        channel = self.channel = f"slave-test-{id(self)}"
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.lock = threading.Lock()
        self.node = SlaveNode(NODE, eds_file, self.bus.send, strict_cob_ids)
        self.network = canopen.Network()
        self.network.connect(interface="virtual", channel=channel, receive_own_messages=False)
        self.master = canopen.RemoteNode(NODE, eds_file)
        self.network.add_node(self.master)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()
        with self.lock:
            self.node.boot(time.monotonic())

    def _serve(self) -> None:
        while not self.stop.is_set():
            msg = self.bus.recv(0.005)
            with self.lock:
                now = time.monotonic()
                if msg is not None:
                    self.node.on_frame(msg, now)
                    if msg.arbitration_id == 0x80:
                        self.node.on_sync(now)
                        self.node.transmit_sync_pdos()
                self.node.poll(now)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.network.disconnect()
        self.bus.shutdown()


@pytest.fixture
def h() -> Iterator[Harness]:
    harness = Harness(str(eds("ros_canopen/Elmo.dcf")))
    try:
        yield harness
    finally:
        harness.close()


@pytest.fixture
def e35() -> Iterator[Harness]:
    """e35's description: a writable EMCY COB-ID, 0xA0 for every node, RPDO1 on 0x220."""
    harness = Harness(str(eds("canopen/e35.eds")))
    try:
        yield harness
    finally:
        harness.close()


def test_sdo_expedited_and_segmented(h: Harness) -> None:
    assert h.master.sdo[0x1000].raw == h.node.get(0x1000)
    name = h.master.sdo[0x1008].raw  # a string longer than 4 bytes: segmented upload
    assert isinstance(name, str) and name == h.node.get(0x1008)
    h.master.sdo[0x1017].raw = 50
    assert h.node.get(0x1017) == 50 and h.master.sdo[0x1017].raw == 50


@pytest.mark.parametrize(
    ("index", "sub", "value", "code"),
    [
        (0x5555, 0, 1, 0x06020000),  # no such object
        (0x1018, 9, 1, 0x06090011),  # no such sub-index
        (0x1000, 0, 1, 0x06010002),  # read-only
    ],
)
def test_sdo_aborts(h: Harness, index: int, sub: int, value: int, code: int) -> None:
    with pytest.raises(canopen.SdoAbortedError) as e:
        h.master.sdo.download(index, sub, value.to_bytes(4, "little"))
    assert e.value.code == code


def test_nmt_and_heartbeat(h: Harness) -> None:
    h.master.sdo[0x1017].raw = 20
    h.master.nmt.wait_for_heartbeat(2.0)
    assert h.master.nmt.state == "PRE-OPERATIONAL"
    h.master.nmt.state = "OPERATIONAL"
    h.master.nmt.wait_for_heartbeat(2.0)
    assert h.master.nmt.state == "OPERATIONAL" and h.node.nmt is Nmt.OPERATIONAL
    h.master.nmt.state = "STOPPED"
    time.sleep(0.1)
    assert h.node.nmt is Nmt.STOPPED
    with pytest.raises(canopen.SdoCommunicationError):  # no SDO in STOPPED
        h.master.sdo[0x1000].raw  # noqa: B018
    h.master.nmt.state = "RESET"
    h.master.nmt.wait_for_bootup(2.0)
    var = h.node.vars[(0x1017, 0)]
    assert h.node.get(0x1017) == (var.value if var.value is not None else var.default) != 20


def test_pdo_remap_over_sdo_and_tpdo_on_sync(h: Harness) -> None:
    h.master.tpdo.read()
    t = h.master.tpdo[1]
    t.clear()
    t.add_variable(0x6041)
    t.add_variable(0x6064)
    t.trans_type = 1
    t.enabled = True
    t.save()
    assert [(i, s) for i, s, _ in h.node.tpdos[0x1800].entries] == [(0x6041, 0), (0x6064, 0)]
    with h.lock:
        h.node.set(0x6064, 0, -123456)
        h.node.set(0x6041, 0, 0x0237)
    h.master.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    h.network.sync.transmit()
    assert t.wait_for_reception(2.0)
    assert t[0x6041].raw == 0x0237 and t[0x6064].raw == -123456


def test_mapping_rules_of_cia_301(h: Harness) -> None:
    # an enabled PDO's mapping cannot change (0x06010000, docs/simulators.md); entries need the
    # count at 0; unmappable refused (test_pdo_mapping.py has each rule)
    with pytest.raises(canopen.SdoAbortedError) as e:
        h.master.sdo[0x1A00][0].raw = 0
    assert e.value.code == 0x06010000
    h.master.sdo[0x1800][1].raw = h.node.tpdos[0x1800].cob_id | 1 << 31
    h.master.sdo[0x1A00][0].raw = 0
    with pytest.raises(canopen.SdoAbortedError) as e:
        h.master.sdo[0x1A00][1].raw = 0x10000020  # 0x1000 device type: not mappable
    assert e.value.code == 0x06040041


def test_rpdo_applied_and_hook_called(h: Harness) -> None:
    seen: list[int] = []
    h.node.on_write[(0x6040, 0)] = seen.append
    h.master.rpdo.read()
    r = h.master.rpdo[1]
    assert r.enabled and 0x6040 in [v.index for v in r.map]
    h.master.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    r[0x6040].raw = 0x0F
    r.transmit()
    time.sleep(0.05)
    if r.trans_type <= 240:  # synchronous: applied at the next SYNC
        assert seen == []
        h.network.sync.transmit()
        time.sleep(0.05)
    assert seen == [0x0F] and h.node.get(0x6040) == 0x0F


INVALID = 1 << 31


@pytest.mark.parametrize(("index", "sub"), [(0x1014, 0), (0x1400, 1), (0x1800, 1)])
def test_a_valid_cob_id_keeps_its_identifier(e35: Harness, index: int, sub: int) -> None:
    """CiA 301: a COB-ID's identifier changes only while bit 31 says "not valid"; strict drives
    abort with 0x06090030 otherwise, also when the same write sets bit 31 (what canopen's own
    `PdoMap.save` does)."""
    cob = e35.node.get(index, sub)
    assert not cob & INVALID
    other = (cob & ~0x7FF) | 0x185
    for value in (other, other | INVALID):
        with pytest.raises(canopen.SdoAbortedError) as e:
            e35.master.sdo.download(index, sub, value.to_bytes(4, "little"))
        assert e.value.code == 0x06090030
    assert e35.node.get(index, sub) == cob
    for value in (cob | INVALID, other | INVALID, other):  # the two steps (and the new one valid)
        e35.master.sdo.download(index, sub, value.to_bytes(4, "little"))
    assert e35.node.get(index, sub) == other


def test_a_lenient_drive_lets_a_valid_cob_id_change() -> None:
    h = Harness(str(eds("canopen/e35.eds")), strict_cob_ids=False)
    try:
        h.master.sdo[0x1014].raw = 0x85
        assert h.node.get(0x1014) == 0x85
    finally:
        h.close()


def test_write_cob_id_invalidates_changes_then_validates(e35: Harness) -> None:
    recorder = can.Bus(interface="virtual", channel=e35.channel, receive_own_messages=False)
    try:
        write_cob_id(e35.master, 0x1014, 0, 0x80 + NODE)
        write_cob_id(e35.master, 0x1400, 1, 0x200 + NODE)
        write_cob_id(e35.master, 0x1400, 1, 0x200 + NODE)  # as it is: nothing written
        frames = []
        while (msg := recorder.recv(0.05)) is not None:
            frames.append(msg)
    finally:
        recorder.shutdown()
    assert [write[1:] for write in sdo_downloads(frames) if write[0] == NODE] == [
        (0x1014, 0, 0xA0 | INVALID),
        (0x1014, 0, 0x85 | INVALID),
        (0x1014, 0, 0x85),
        (0x1400, 1, 0x220 | INVALID),
        (0x1400, 1, 0x205 | INVALID),
        (0x1400, 1, 0x205),
    ]
    assert e35.node.get(0x1014) == 0x85
    assert e35.node.rpdos[0x1400].cob_id == 0x205 and e35.node.rpdos[0x1400].valid


def test_a_late_heartbeat_is_not_followed_by_a_catch_up_one() -> None:
    """The producer never sends sooner than 0x1017 after its last heartbeat, however late the
    last one was (before: a late one was followed by another within the next poll)."""
    sent: list[tuple[float, int]] = []
    clock = [0.0]
    node = SlaveNode(
        NODE, str(eds("ros_canopen/Elmo.dcf")), lambda m: sent.append((clock[0], m.arbitration_id))
    )
    node.boot(0.0)
    node.set(0x1017, 0, 100)
    for t in [0.0, 0.01, 0.35, 0.36, 0.40, 0.44, 0.45, 0.46, 0.56]:  # 0.35: a stall of 250 ms
        clock[0] = t
        node.poll(t)
    beats = [t for t, cob in sent if cob == 0x700 + NODE and t > 0.0]
    assert beats == [0.35, 0.45, 0.56], beats
    assert min(b - a for a, b in itertools.pairwise(beats)) >= 0.1
