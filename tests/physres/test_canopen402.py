"""The canopen402 resource against simulated CiA 402 drives in another process, over a bus in a
third (the userspace hub here; vcan0 where the kernel has it)."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import can
import canopen
import numpy as np
import pytest

from orccadd.drivers.canopen.cia402 import MODE_CST, State
from orccadd.errors import ResourceError
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from orccadd.types import CommandMode, Status
from tests.canopen_rig import (
    COB_HEARTBEAT_OURS,
    CONSUMING_ELMO,
    BusRecorder,
    Rig,
    canopen_rig,
    consuming_elmo,
    edit_dcf,
    emcy_errors,
    enable_to_sync_gaps_s,
    sdo_downloads,
    until,
)
from tests.conftest import eds


@pytest.fixture(params=[CONSUMING_ELMO, "canopen/e35.eds"], ids=["elmo", "e35"])
def rig(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Rig]:
    with canopen_rig(tmp_path, request.param) as r:
        yield r


def new_arm(rig: Rig) -> Canopen402Arm:
    res = create_resource(load_robot_config(rig.config))
    assert isinstance(res, Canopen402Arm)
    return res


@contextmanager
def active_arm(rig: Rig) -> Iterator[Canopen402Arm]:
    """The rig's arm configured and active in position mode; shut down at the end."""
    res = new_arm(rig)
    try:
        res.configure()
        res.activate(CommandMode.POSITION)
        yield res
    finally:
        if res.lifecycle.name != "FINALIZED":
            res.shutdown()


@pytest.fixture
def arm(rig: Rig) -> Iterator[Canopen402Arm]:
    with active_arm(rig) as res:
        yield res


def run(arm: Canopen402Arm, seconds: float, command: Callable[[float], np.ndarray] | None = None) -> int:
    """Tick the resource `seconds / period` times on the wall clock (missed periods skipped, like
    the executor): read, then the command or `keep_alive`; the OR of the status flags seen. The
    command is given the tick's time as a trajectory generator sees it, one period per tick: after
    a stall of the test's thread it goes on from where it was instead of jumping (which the
    resource rightly clamps as faster than max_velocity). A stall makes the run longer, not shorter."""
    period = arm.config.control_period_s
    nxt = time.monotonic()
    seen = 0
    for k in range(round(seconds / period)):
        st = arm.read(nxt)
        seen |= st.status
        if command is not None:
            seen |= arm.write(nxt, command(k * period))
        else:
            arm.keep_alive(nxt)
        nxt += period
        while nxt < time.monotonic():
            nxt += period
        time.sleep(max(0.0, nxt - time.monotonic()))
    return seen


def wait_for(arm: Canopen402Arm, flag: int, timeout_s: float) -> float:
    """Seconds until a read shows `flag` (AssertionError after `timeout_s`). Ticks on a schedule
    that catches up after a stall (a tick's work plus a whole period made 5 ms ticks on this
    loaded 2-core VM: 150 SYNCs then outlasted 3 heartbeat periods)."""
    t0 = nxt = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        now = time.monotonic()
        status = arm.read(now).status
        arm.keep_alive(now)  # one tick: read, then a command or this
        if status & flag:
            return time.monotonic() - t0
        nxt += arm.config.control_period_s
        time.sleep(max(0.0, nxt - time.monotonic()))
    raise AssertionError(f"no {Status(flag)!r} within {timeout_s} s: {arm.fault_message}")


def test_startup_enables_every_axis_and_csp_moves_the_arm(rig: Rig, arm: Canopen402Arm) -> None:
    # activated, the drives wait in SWITCHED ON: the loop's first ticks enable them
    assert all(a.state is State.SWITCHED_ON for a in arm.master.axes)
    assert arm.read(time.monotonic()).status & Status.TORQUE_OFF
    run(arm, 0.1)
    assert all(a.state is State.OPERATION_ENABLED for a in arm.master.axes)
    assert not arm.state.status & Status.TORQUE_OFF
    assert CommandMode.POSITION in arm.supported_modes
    q0 = arm.state.q_rad.copy()
    goal = q0 + np.array([0.3, -0.2, 0.2, 0.0, 0.1, -0.1])

    def ramp(t: float) -> np.ndarray:
        return q0 + (goal - q0) * min(1.0, t / 1.5)

    flags = run(arm, 2.5, ramp)
    assert not flags & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION), arm.fault_message
    np.testing.assert_allclose(arm.state.q_rad, goal, atol=0.01)
    np.testing.assert_allclose(rig.drives.status()["q_rad"], goal, atol=0.01)  # the drives agree
    arm.safe_stop()
    wait_for(arm, Status.STOPPED, 5.0)
    assert all(a.state is State.SWITCH_ON_DISABLED for a in arm.master.axes)


def test_the_shipped_description_starts_watches_our_heartbeat_and_moves(tmp_path: Path) -> None:
    """configs/eds/orccadd-cia402.eds, the description the shipped CANopen configs name (a user's
    drives come with their vendor's): the drives start on it, watch our heartbeat, and move in
    CSP; position and torque modes are available (one RPDO per axis carries the controlword and
    the targets of CSP and CST)."""
    shipped = Path(__file__).resolve().parents[2] / "configs/eds/orccadd-cia402.eds"
    with canopen_rig(tmp_path, shipped) as rig, active_arm(rig) as arm:
        assert all(a.consumer_ok for a in arm.master.axes)
        assert {CommandMode.POSITION, CommandMode.TORQUE} <= arm.supported_modes  # CSP and CST
        run(arm, 0.1)
        q0 = arm.state.q_rad.copy()
        goal = q0 + np.array([0.2, -0.1, 0.1, 0.0, 0.1, -0.1])
        flags = run(arm, 1.5, lambda t: q0 + (goal - q0) * min(1.0, t / 1.0))
        assert not flags & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION), arm.fault_message
        np.testing.assert_allclose(arm.state.q_rad, goal, atol=0.01)


@pytest.mark.parametrize("rig", [CONSUMING_ELMO], indirect=True)
def test_drive_fault_emcy_then_fault_reset_and_a_new_motion(rig: Rig, arm: Canopen402Arm) -> None:
    run(arm, 0.2, lambda t: arm.state.q_rad.copy())
    rig.drives.inject("overcurrent", device=3)
    wait_for(arm, Status.FAULT, 2.0)
    assert arm.state.fault_code == 0x2310 and "node 3 (elbow_joint)" in arm.fault_message
    assert "over-current" in arm.fault_message
    arm.safe_stop()  # what the task does on a type 3: quick stop on every axis
    wait_for(arm, Status.STOPPED, 5.0)
    assert rig.drives.status()["states"][2] == "FAULT"
    arm.reset_fault()
    run(arm, 0.3)
    assert not arm.read(time.monotonic()).status & Status.FAULT
    arm.clear_stop()
    assert all(a.state is State.OPERATION_ENABLED for a in arm.master.axes)
    q0 = arm.state.q_rad.copy()
    flags = run(arm, 1.0, lambda t: q0 + np.array([0, 0, 0.1 * min(1.0, t / 0.5), 0, 0, 0]))
    assert not flags & (Status.FAULT | Status.COMM_LOST), arm.fault_message
    assert arm.state.q_rad[2] == pytest.approx(q0[2] + 0.1, abs=0.01)


@pytest.mark.parametrize("rig", [CONSUMING_ELMO], indirect=True)
def test_a_silent_heartbeat_is_comm_lost_within_three_periods(rig: Rig, arm: Canopen402Arm) -> None:
    heartbeat_ms = arm.settings.heartbeat_ms  # the rig's 250 ms, not the file's 100 ms
    timeout_s = 3 * heartbeat_ms / 1000  # the master's consumer timeout: 3 silent heartbeat periods
    assert not run(arm, 0.3) & Status.COMM_LOST, arm.fault_message  # every drive's heartbeat arrives
    rig.drives.inject("heartbeat_silence", device=4)
    wait_for(arm, Status.COMM_LOST, 10 * timeout_s)  # reported within an order of magnitude of it
    now = time.monotonic()
    assert "node 4 (wrist_1_joint): heartbeat lost (" in arm.fault_message
    assert f"ms > 3 × {heartbeat_ms} ms)" in arm.fault_message
    silent_s = {a.node_id: now - a.heartbeat_s for a in arm.master.axes}
    assert silent_s[4] > timeout_s, silent_s  # not before the timeout
    # only node 4 went silent: the other drives' heartbeats were still arriving
    assert all(s < timeout_s for n, s in silent_s.items() if n != 4), silent_s


@pytest.mark.parametrize("rig", [CONSUMING_ELMO], indirect=True)
def test_a_node_silent_on_pdos_is_comm_lost(rig: Rig, arm: Canopen402Arm) -> None:
    run(arm, 0.3)
    rig.drives.inject("node_silence", device=6)
    wait_for(arm, Status.COMM_LOST, 3.0)
    assert "node 6 (wrist_3_joint) silent: no TPDO" in arm.fault_message


@pytest.mark.parametrize("rig", [CONSUMING_ELMO], indirect=True)
def test_the_bus_dying_is_comm_lost_with_a_clear_message(rig: Rig, arm: Canopen402Arm) -> None:
    if rig.hub is None:
        pytest.skip("the kernel's vcan0 cannot be killed from a test")
    run(arm, 0.3)
    rig.hub.kill()
    wait_for(arm, Status.COMM_LOST, 3.0)
    assert "CAN bus can0 (socketcand 127.0.0.1:" in arm.fault_message
    arm.safe_stop()
    wait_for(arm, Status.STOPPED, 10.0)  # unreachable drives: presumed stopped by their watchdogs


# ---- issue 15: startup against strict drives ------------------------------------------------------
LOOP_START_S = 1.0  # the daemon's setup between activate and its loop's first tick (0.15-0.22 s
# measured), here longer than the drives' heartbeat timeout (3 × 200 ms on this rig)


def when_watched(frames: list[can.Message]) -> list[float]:
    """When each drive was told to watch our heartbeat (its SDO write of 0x1016)."""
    return [m.timestamp for m in frames if 0x601 <= m.arbitration_id <= 0x67F and m.data[1:3] == b"\x16\x10"]


def test_drives_watching_our_heartbeat_are_enabled_once_sync_runs(tmp_path: Path) -> None:
    """The drives wait in SWITCHED ON through the time the loop does not run, our heartbeat goes
    on, and Enable Operation comes from the loop's ticks, each followed by the next tick's SYNC:
    no drive misses our heartbeat (EMCY 0x8130). (Gaps from the hub's own time stamps, bounded by
    the heartbeat period and the drives' timeout: 50 and 150 ticks, not a tick's time.)"""
    with canopen_rig(tmp_path) as rig, BusRecorder(rig) as bus:
        arm = new_arm(rig)
        try:
            arm.configure()
            arm.activate(CommandMode.POSITION)
            time.sleep(LOOP_START_S)
            flags = run(arm, 0.5)
            end_s = time.time()
            states = [a.state for a in arm.master.axes]
            watching = [a.consumer_ok for a in arm.master.axes]
        finally:
            arm.shutdown()
    period_s = arm.settings.controller_heartbeat_ms / 1000
    frames = until(bus.frames, end_s)
    assert all(watching)  # every drive watches our heartbeat: the test means something
    assert not flags & Status.FAULT, arm.fault_message  # (COMM_LOST: a starved drive simulator)
    assert states == [State.OPERATION_ENABLED] * 6
    assert not emcy_errors(frames)
    gaps_s = enable_to_sync_gaps_s(frames)
    assert gaps_s and max(gaps_s) < period_s, max(gaps_s)
    ours = [m.timestamp for m in frames if m.arbitration_id == COB_HEARTBEAT_OURS]
    reset = next(m.timestamp for m in frames if m.arbitration_id == 0 and m.data[0] == 0x81)
    assert ours[0] < reset  # from before the drives boot, through the whole startup
    watched_s = next(t for t in ours if t > min(when_watched(frames)))  # armed by this one
    assert max(np.diff([t for t in ours if t >= watched_s])) < 3 * period_s  # the drives' timeout


def test_a_drive_that_never_enables_is_a_fault_naming_it_and_its_statusword(tmp_path: Path) -> None:
    """A drive whose Safe Torque Off is active stays SWITCHED ON whatever the controlword says:
    within `startup_timeout_s` of the walk the resource reports a fault naming the node, its
    statusword and what was awaited (before: it waited in SWITCHED ON for ever, without a word);
    once STO is released, `reset` enables every drive."""
    with canopen_rig(tmp_path, settings_extra="startup_timeout_s = 1.5") as rig:
        rig.drives.inject("sto", device=2)
        res = new_arm(rig)
        try:
            res.configure()
            res.activate(CommandMode.POSITION)
            waited = wait_for(res, Status.FAULT, 10.0)
            assert 1.0 < waited < 5.0, waited
            msg = res.fault_message
            assert "node 2 (shoulder_lift_joint) did not reach OPERATION_ENABLED within 1.5 s" in msg, msg
            assert "statusword 0x" in msg and "SWITCHED_ON" in msg, msg
            rig.drives.inject("clear", device=2)
            res.safe_stop()
            wait_for(res, Status.STOPPED, 5.0)
            res.reset_fault()
            run(res, 0.3)
            res.clear_stop()
            assert all(a.state is State.OPERATION_ENABLED for a in res.master.axes)
        finally:
            res.shutdown()


def test_a_drive_slow_to_show_its_mode_is_waited_for(tmp_path: Path) -> None:
    """Drives show a new mode of operation (0x6061) some ms after 0x6060 is written: configure
    (csp) and activate in another mode (torque: cst) read 0x6061 until it shows the mode."""
    with canopen_rig(tmp_path, drivesim_args=("--mode-display-delay-ms", "30")) as rig:
        arm = new_arm(rig)
        try:
            arm.configure()
            arm.activate(CommandMode.TORQUE)
            assert [a.mode_shown for a in arm.master.axes] == [MODE_CST] * 6
            flags = run(arm, 0.2, lambda t: arm.state.tau_nm.copy())
            assert not flags & (Status.FAULT | Status.COMM_LOST), arm.fault_message
            assert rig.drives.status()["states"] == ["OPERATION_ENABLED"] * 6
        finally:
            arm.shutdown()


def test_a_drive_that_never_shows_the_mode_is_refused_within_the_timeout(tmp_path: Path) -> None:
    settings = "mode_display_timeout_s = 0.2"
    with canopen_rig(
        tmp_path, settings_extra=settings, drivesim_args=("--mode-display-delay-ms", "inf")
    ) as rig:
        arm = new_arm(rig)
        try:
            t0 = time.monotonic()
            with pytest.raises(ResourceError) as e:
                arm.configure()
            took_s = time.monotonic() - t0
        finally:
            arm.shutdown()
    assert took_s < 5.0  # the startup (about a second here), then the 0.2 s timeout: no hang
    assert str(e.value) == (
        "node 1 (shoulder_pan_joint): asked mode csp (0x6060 = 8), the drive still shows 0 (0x6061) "
        "after 0.2 s"
    )


@functools.cache
def _object_dictionary(path: Path, node: int) -> canopen.ObjectDictionary:
    """A description parsed for `node` (once: parsing an EDS takes ~0.15 s here)."""
    return canopen.import_od(str(path), node)


def described(path: Path, node: int, index: int, sub: int) -> int:
    """An object's value as a description sets it for `node` (a DCF's value, else the default)."""
    var = _object_dictionary(path, node).get_variable(index, sub)
    assert var is not None
    value = var.value if var.value is not None else var.default
    assert isinstance(value, int)
    return value


def test_cob_ids_change_only_while_not_valid(tmp_path: Path) -> None:
    """e35's description gives every node the same EMCY and RPDO1 COB-IDs: each is changed by
    the CiA 301 steps (bit 31 set, new identifier, valid), which strict drives accept."""
    e35 = eds("canopen/e35.eds")
    with canopen_rig(tmp_path, "canopen/e35.eds") as rig, BusRecorder(rig) as bus:
        arm = new_arm(rig)
        try:
            arm.configure()  # strict drives: a valid COB-ID changed at once would be aborted
        finally:
            arm.shutdown()
    cob_ids = {  # (node, index, sub) -> value, from the description: the drives were reset
        (node, index, sub): described(e35, node, index, sub)
        for node in range(1, 7)
        for index, sub in ((0x1014, 0), *((i, 1) for i in (*range(0x1400, 0x1404), *range(0x1800, 0x1804))))
    }
    changed_while_valid = []
    for node, index, sub, value in sdo_downloads(bus.frames):
        key = (node, index, sub)
        if key in cob_ids:
            now = cob_ids[key]
            if not now & 1 << 31 and (now ^ value) & 0x3FFFFFFF:
                changed_while_valid.append((node, hex(index), hex(now), hex(value)))
            cob_ids[key] = value
    assert not changed_while_valid
    for node in range(1, 7):
        assert cob_ids[(node, 0x1014, 0)] == 0x80 + node
        assert cob_ids[(node, 0x1400, 1)] & 0xBFFFFFFF == 0x200 + node
        assert cob_ids[(node, 0x1800, 1)] & 0xBFFFFFFF == 0x180 + node
        assert all(cob_ids[(node, index, 1)] & 1 << 31 for index in (0x1401, 0x1402, 0x1801, 0x1802))


def test_a_dcf_with_no_free_heartbeat_consumer_entry_is_refused(tmp_path: Path) -> None:
    """0x1016 with 0 entries: the drives would never watch the controller's heartbeat."""
    dcf = edit_dcf(
        consuming_elmo(tmp_path),
        tmp_path / "Elmo-no-consumer-entry.dcf",
        {"1016sub0": {"DefaultValue": "0", "LowLimit": "0"}},
    )
    with canopen_rig(tmp_path, dcf) as rig:
        arm = new_arm(rig)
        try:
            with pytest.raises(ResourceError) as e:
                arm.configure()
        finally:
            arm.shutdown()
    assert str(e.value) == (
        f"node 1 (shoulder_pan_joint): {dcf}: 0x1016 has 0 consumer heartbeat entries (number of "
        "entries, sub 0): the drive would never watch the controller's heartbeat (node 0x7F); "
        "refused. Add a free entry to 0x1016 (a sub-index set to 0, counted in sub 0)"
    )
