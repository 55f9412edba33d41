"""The `ethercat402` backend's startup refusals, each naming what is wrong: an interface that does
not exist or is down, a line whose slaves are not the config's (their count, an identity), and
what a started line reports (each slave's identity, a drive's emergency from its mailbox)."""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.ecatsim.process import EcatSimProcess
from orccadd.errors import ResourceError
from orccadd.robot import create_resource, load_robot_config
from orccadd.types import CommandMode, Status
from tests.conftest import ROOT
from tests.drivers.ethercat.test_settings import variant

pytest.importorskip("pysoem")
pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="raw sockets and the simulator's link need root")

SIM = ROOT / "configs/robots/ethercat-6axis-sim.toml"


@pytest.fixture
def sim() -> Iterator[EcatSimProcess]:
    with EcatSimProcess(SIM, "--priority", "70") as process:
        yield process


def test_an_interface_that_does_not_exist_is_refused_naming_it(tmp_path: Path) -> None:
    res = create_resource(
        load_robot_config(variant(tmp_path, ('interface = "ecm0"', 'interface = "ecnone9"')))
    )
    with pytest.raises(
        ResourceError, match=r"network interface 'ecnone9' does not exist \(interfaces here: .*lo"
    ):
        res.configure()


def test_an_interface_that_is_down_is_refused_naming_it(tmp_path: Path) -> None:
    subprocess.run(["ip", "link", "add", "ecdown0", "type", "veth", "peer", "name", "ecdown1"], check=True)
    try:
        res = create_resource(
            load_robot_config(variant(tmp_path, ('interface = "ecm0"', 'interface = "ecdown0"')))
        )
        with pytest.raises(
            ResourceError, match=r"network interface 'ecdown0' is down: ip link set ecdown0 up"
        ):
            res.configure()
    finally:
        subprocess.run(["ip", "link", "del", "ecdown0"], check=False)


def test_a_slave_that_is_not_the_configs_is_refused_naming_both_identities(
    tmp_path: Path, sim: EcatSimProcess
) -> None:
    text = SIM.read_text()
    third = text.index("[[resource.settings.slaves]]", text.index("[[resource.settings.slaves]]") + 1)
    third = text.index("[[resource.settings.slaves]]", third + 1)
    at = text.index("product_code = 0x00000402", third)
    path = tmp_path / "other.toml"
    path.write_text(
        (text[:at] + "product_code = 0x00000999" + text[at + 25 :]).replace('"../', f'"{ROOT / "configs"}/')
    )
    res = create_resource(load_robot_config(path))
    with pytest.raises(
        ResourceError,
        match=r"slave 3 \(elbow_joint\) on ecm0 is .*product 0x00000402.*expects .*product 0x00000999",
    ):
        res.configure()
    res.shutdown()


def test_a_line_shorter_than_the_config_is_refused(sim: EcatSimProcess) -> None:
    sim.inject("unplug", device=5)
    res = create_resource(load_robot_config(SIM))
    with pytest.raises(ResourceError, match=r"4 EtherCAT slaves on ecm0, the config has 6"):
        res.configure()
    res.shutdown()


def test_a_started_line_names_its_slaves_and_a_drives_emergency(sim: EcatSimProcess) -> None:
    res = create_resource(load_robot_config(SIM))
    res.configure()
    try:
        res.activate(CommandMode.POSITION)
        end = time.monotonic() + 5.0
        while res.read(time.monotonic()).status & Status.TORQUE_OFF and time.monotonic() < end:
            res.keep_alive(time.monotonic())  # enabled by these ticks
            time.sleep(0.001)
        details = res.diagnostics().details
        assert details["slave_1"] == (
            "orccadd CiA 402 drive (simulated): vendor 0x00000000, product 0x00000402, revision 0x00000001"
        )
        sim.inject("overcurrent", device=2)
        end = time.monotonic() + 5.0
        while "EMCY" not in res.fault_message and time.monotonic() < end:
            st = res.read(time.monotonic())
            res.keep_alive(time.monotonic())
            time.sleep(0.001)
        assert st.status & Status.FAULT
        assert res.fault_message.endswith(
            "slave 2 (shoulder_lift_joint): drive fault, error code 0x2310 over-current "
            "(EMCY 0x2310 over-current, error register 0x03)"
        ), res.fault_message
    finally:
        res.shutdown()


def test_a_slave_that_leaves_op_is_comm_lost_naming_it_and_reset_brings_it_back(sim: EcatSimProcess) -> None:
    res = create_resource(load_robot_config(SIM))
    res.configure()
    try:
        res.activate(CommandMode.POSITION)
        end = time.monotonic() + 5.0
        while res.read(time.monotonic()).status & Status.TORQUE_OFF and time.monotonic() < end:
            res.keep_alive(time.monotonic())
            time.sleep(0.001)
        sim.inject("al_error", device=3)  # its working counter stays: only its AL state tells
        end = time.monotonic() + 5.0
        while not res.state.status & Status.COMM_LOST and time.monotonic() < end:
            res.read(time.monotonic())
            res.keep_alive(time.monotonic())
            time.sleep(0.001)
        assert res.state.status & Status.COMM_LOST
        assert res.fault is not None and res.fault.joint == "elbow_joint"
        assert (
            "slave 3 (elbow_joint) left OP, now SAFE-OP + ERROR, AL status code 0x001A" in res.fault_message
        )
        res.safe_stop()
        end = time.monotonic() + 5.0
        while not res.state.status & Status.STOPPED and time.monotonic() < end:
            res.read(time.monotonic())
            res.keep_alive(time.monotonic())
            time.sleep(0.001)
        assert res.state.status & Status.STOPPED
        res.reset_fault()  # the slave back to OP, its drive's fault reset
        assert sim.status()["al_states"] == ["OP"] * 6
        for _ in range(50):
            assert not res.read(time.monotonic()).status & Status.COMM_LOST
            res.keep_alive(time.monotonic())
            time.sleep(0.001)
    finally:
        res.shutdown()
