"""The master's PDO mapping and COB-IDs by CiA 301's steps: planned (pure), run against the strict
simulated drive, and recorded on the bus as the master configures six of them."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.drivers.canopen.capabilities import object_dictionary
from orccadd.drivers.canopen.pdo_mapping import (
    PdoPlan,
    SdoStep,
    check_described,
    cob_id_steps,
    disable_steps,
    mapping_steps,
    run_steps,
)
from orccadd.errors import ResourceError
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from tests.canopen_rig import BusRecorder, canopen_rig, consuming_elmo, edit_dcf, sdo_downloads
from tests.conftest import eds
from tests.drivesim.test_slave import NODE, Harness

INVALID = 1 << 31
RTR_NOT_ALLOWED = 1 << 30
RPDO1 = PdoPlan("RPDO1", 0x1400, 0x1600, 0x205, ((0x6040, 0, 16), (0x607A, 0, 32)))


def steps_of(steps: list[SdoStep]) -> list[tuple[int, int, int]]:
    return [(s.index, s.sub, s.value) for s in steps]


# ---- the plan --------------------------------------------------------------------------------------
def test_a_valid_pdo_is_remapped_in_the_five_steps() -> None:
    assert steps_of(mapping_steps(RPDO1, 0x220)) == [
        (0x1400, 1, 0x220 | INVALID),  # a: not valid, the identifier as it is
        (0x1400, 1, 0x205 | INVALID),  # a: the new identifier, still not valid
        (0x1400, 2, 1),  # a: transmission type while not valid
        (0x1600, 0, 0),  # b
        (0x1600, 1, 0x60400010),  # c
        (0x1600, 2, 0x607A0020),
        (0x1600, 0, 2),  # d
        (0x1400, 1, 0x205),  # e
    ]


def test_a_pdo_not_valid_with_its_identifier_needs_no_cob_id_step_before_the_mapping() -> None:
    steps = steps_of(mapping_steps(RPDO1, 0x205 | INVALID))
    assert steps[0] == (0x1400, 2, 1) and steps[-1] == (0x1400, 1, 0x205)
    assert [s for s in steps if s[:2] == (0x1400, 1)] == [(0x1400, 1, 0x205)]


def test_the_rtr_bit_is_kept_as_the_drive_has_it() -> None:
    tpdo = PdoPlan("TPDO1", 0x1800, 0x1A00, 0x185, ((0x6041, 0, 16),), trans_type=None)
    steps = steps_of(mapping_steps(tpdo, RTR_NOT_ALLOWED | 0x1A0))
    assert steps[0] == (0x1800, 1, INVALID | RTR_NOT_ALLOWED | 0x1A0)
    assert steps[-1] == (0x1800, 1, RTR_NOT_ALLOWED | 0x185)
    assert (0x1800, 2, 1) not in steps  # trans_type None: left as it is


def test_every_step_names_its_letter_and_object() -> None:
    whats = [s.what for s in mapping_steps(RPDO1, 0x220)]
    assert [w.split(", ")[1][:6] for w in whats] == ["step a"] * 3 + ["step b"] + ["step c"] * 2 + [
        "step d",
        "step e",
    ]
    assert whats[3] == "RPDO1 mapping, step b: mapping count to 0"
    assert whats[4] == "RPDO1 mapping, step c: entry 1, 0x6040:00 (16 bits)"


def test_unused_pdos_and_cob_ids() -> None:
    assert steps_of(disable_steps("RPDO2", 0x1401, 0x305)) == [(0x1401, 1, 0x305 | INVALID)]
    assert disable_steps("RPDO2", 0x1401, 0x305 | INVALID) == []
    assert cob_id_steps("EMCY", 0x1014, 0, 0x85, 0x85) == []
    assert steps_of(cob_id_steps("EMCY", 0x1014, 0, 0x85 | INVALID, 0x85)) == [(0x1014, 0, 0x85)]


def test_a_fixed_mapping_in_the_description_is_refused_before_anything_is_sent(tmp_path: Path) -> None:
    dcf = edit_dcf(eds("ros_canopen/Elmo.dcf"), tmp_path / "fixed.dcf", {"1600sub0": {"AccessType": "ro"}})
    with pytest.raises(ResourceError) as e:
        check_described(object_dictionary(dcf, 1), "node 1 (j1)", str(dcf), mapping_steps(RPDO1, 0x201))
    assert str(e.value) == (
        f"node 1 (j1): RPDO1 mapping, step b: mapping count to 0: 0x1600:00 is ro in {dcf} (a fixed "
        "mapping or parameter): the drive cannot take this config"
    )


# ---- against the strict simulated drive --------------------------------------------------------------
@pytest.fixture
def h() -> Iterator[Harness]:
    harness = Harness(str(eds("ros_canopen/Elmo.dcf")))
    try:
        yield harness
    finally:
        harness.close()


def test_the_steps_are_taken_by_a_strict_drive(h: Harness) -> None:
    plan = PdoPlan("RPDO1", 0x1400, 0x1600, 0x200 + NODE, RPDO1.entries)
    run_steps(h.master, f"node {NODE}", mapping_steps(plan, int(h.master.sdo[0x1400][1].raw)))
    rpdo = h.node.rpdos[0x1400]
    assert rpdo.valid and rpdo.cob_id == 0x200 + NODE and rpdo.trans_type == 1
    assert rpdo.entries == [(0x6040, 0, 16), (0x607A, 0, 32)]


def test_a_refused_step_is_an_error_naming_it_the_object_and_the_abort_code(h: Harness) -> None:
    """The mapping written while the PDO is still valid (step a left out): the strict drive
    refuses it, and the error says which step, where, and why."""
    assert h.node.rpdos[0x1400].valid
    out_of_order = [s for s in mapping_steps(RPDO1, 0x205 | INVALID) if s.index == 0x1600]
    with pytest.raises(ResourceError) as e:
        run_steps(h.master, "node 5 (j1)", out_of_order)
    assert str(e.value) == (
        "node 5 (j1): RPDO1 mapping, step b: mapping count to 0: 0x1600:00 = 0x0 refused, "
        "SDO abort 0x06010000 (Unsupported access to an object)"
    )


def test_a_silent_drive_is_an_error_naming_the_step(h: Harness) -> None:
    h.node.silent = True
    h.master.sdo.RESPONSE_TIMEOUT = 0.2
    with pytest.raises(
        ResourceError, match=r"^node 5: RPDO1 mapping, step a: the PDO not valid .*0x1400:01 = "
    ):
        run_steps(h.master, "node 5", mapping_steps(RPDO1, 0x205))


# ---- the master configuring six strict drives, on the bus -------------------------------------------
def test_the_master_maps_every_drive_in_cia_301_order(tmp_path: Path) -> None:
    """Every PDO mapping write on the bus checked against CiA 301's rules from the description's
    values on (no mapping written while its PDO is valid, no entry while its count is not 0, no
    identifier changed while valid), and node 1's writes in the exact order of the five steps."""
    with canopen_rig(tmp_path) as rig, BusRecorder(rig) as bus:
        arm = create_resource(load_robot_config(rig.config))
        assert isinstance(arm, Canopen402Arm)
        try:
            arm.configure()  # strict drives: a write out of order would be aborted
        finally:
            arm.shutdown()
    od = {node: object_dictionary(consuming_elmo(tmp_path), node) for node in range(1, 7)}
    state: dict[tuple[int, int, int], int] = {}

    def value(node: int, index: int, sub: int) -> int:
        if (node, index, sub) not in state:
            var = od[node][index][sub]
            state[(node, index, sub)] = int(var.value if var.value is not None else var.default)
        return state[(node, index, sub)]

    broken = []
    pdo_writes = [w for w in sdo_downloads(bus.frames) if 0x1400 <= w[1] < 0x1C00]
    for node, index, sub, new in pdo_writes:
        if index & 0x200:  # a mapping: 0x1600-0x17FF, 0x1A00-0x1BFF
            valid = not value(node, index - 0x200, 1) & INVALID
            if valid or (sub > 0 and value(node, index, 0) != 0):
                broken.append((node, hex(index), sub, hex(new)))
        elif sub == 1:
            now = value(node, index, 1)
            if not now & INVALID and (now ^ new) & 0x3FFFFFFF:
                broken.append((node, hex(index), sub, hex(new)))
        state[(node, index, sub)] = new
    assert not broken, f"written out of CiA 301's order: {broken}"
    assert [w[1:] for w in pdo_writes if w[0] == 1] == [
        (0x1400, 1, INVALID | 0x201),
        (0x1400, 2, 1),
        (0x1600, 0, 0),
        (0x1600, 1, 0x60400010),
        (0x1600, 2, 0x607A0020),
        (0x1600, 3, 0x60710010),
        (0x1600, 0, 3),
        (0x1400, 1, 0x201),
        (0x1401, 1, INVALID | 0x301),
        (0x1402, 1, INVALID | 0x401),
        (0x1403, 1, INVALID | 0x501),
        (0x1800, 1, INVALID | 0x181),
        (0x1800, 2, 1),
        (0x1A00, 0, 0),
        (0x1A00, 1, 0x60410010),
        (0x1A00, 2, 0x60640020),
        (0x1A00, 3, 0x60770010),
        (0x1A00, 0, 3),
        (0x1800, 1, 0x181),
        (0x1801, 1, INVALID | 0x281),
        (0x1802, 1, INVALID | 0x381),
        (0x1803, 1, INVALID | 0x481),
    ]
