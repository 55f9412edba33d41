"""The typed fault: one value from the device to the operator, the same on the wire."""

from __future__ import annotations

import json

from orccadd.fault import Fault, FaultKind, StopCause, cause_words

EMCY = Fault(FaultKind.DEVICE, "arm", "node 3 (elbow_joint): drive fault, EMCY 0x2310", "elbow_joint", 0x2310)


def test_a_fault_and_its_cause_cross_the_wire_unchanged() -> None:
    cause = StopCause("Move.T3.ResourceFault", EMCY)
    wire = json.loads(json.dumps(cause.to_wire()))
    assert wire == {
        "event": "Move.T3.ResourceFault",
        "kind": "device",
        "resource": "arm",
        "joint": "elbow_joint",
        "code": 0x2310,
        "text": "node 3 (elbow_joint): drive fault, EMCY 0x2310",
    }
    assert StopCause.from_wire(wire) == cause
    assert Fault.from_wire(wire) == EMCY


def test_people_read_it_in_one_line_without_parsing() -> None:
    assert str(StopCause("Move.T3.ResourceFault", EMCY)) == (
        "Move.T3.ResourceFault (arm: node 3 (elbow_joint): drive fault, EMCY 0x2310)"
    )
    abort = StopCause("", Fault(FaultKind.ABORT, "arm", "aborted by the operator"))
    assert str(abort) == "arm: aborted by the operator"
    assert cause_words(abort.to_wire()) == str(abort)
    assert cause_words(None) == "?"
    assert cause_words({"n": 7}) == "safe stop #7 (cause no longer kept)"


def test_the_kinds_are_a_closed_set_of_words() -> None:
    assert [k.value for k in FaultKind] == [
        "device", "limit", "command", "comm_lost", "overrun", "timeout", "mission", "abort", "internal"
    ]  # fmt: skip
    assert FaultKind("comm_lost") is FaultKind.COMM_LOST
