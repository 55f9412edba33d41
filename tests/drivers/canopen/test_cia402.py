"""The CiA 402 state machine: every numbered transition, the statusword coding, the path to
OPERATION ENABLED from every state."""

from __future__ import annotations

import pytest

from orccadd.drivers.canopen.cia402 import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    CW_FAULT_RESET,
    CW_QUICK_STOP,
    CW_SHUTDOWN,
    CW_SWITCH_ON,
    SW_REMOTE,
    SW_VOLTAGE_ENABLED,
    DriveStateMachine,
    State,
    command_towards,
    decode_state,
)

S = State


def drive_in(state: State, quick_stop_option: int = 2) -> DriveStateMachine:
    """A drive brought to `state` through the standard's transitions."""
    d = DriveStateMachine(quick_stop_option)
    if state is S.NOT_READY_TO_SWITCH_ON:
        return d
    d.boot()
    path = {
        S.SWITCH_ON_DISABLED: [],
        S.READY_TO_SWITCH_ON: [CW_SHUTDOWN],
        S.SWITCHED_ON: [CW_SHUTDOWN, CW_SWITCH_ON],
        S.OPERATION_ENABLED: [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION],
        S.QUICK_STOP_ACTIVE: [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION, CW_QUICK_STOP],
        S.FAULT_REACTION_ACTIVE: [],
        S.FAULT: [],
    }[state]
    for cw in path:
        d.controlword(cw)
    if state in (S.FAULT_REACTION_ACTIVE, S.FAULT):
        d.fault()
    if state is S.FAULT:
        d.fault_reaction_done()
    assert d.state is state
    return d


@pytest.mark.parametrize(
    ("start", "cw", "end", "number"),
    [
        (S.SWITCH_ON_DISABLED, CW_SHUTDOWN, S.READY_TO_SWITCH_ON, 2),
        (S.READY_TO_SWITCH_ON, CW_SWITCH_ON, S.SWITCHED_ON, 3),
        (S.SWITCHED_ON, CW_ENABLE_OPERATION, S.OPERATION_ENABLED, 4),
        (S.OPERATION_ENABLED, CW_SWITCH_ON, S.SWITCHED_ON, 5),
        (S.SWITCHED_ON, CW_SHUTDOWN, S.READY_TO_SWITCH_ON, 6),
        (S.READY_TO_SWITCH_ON, CW_DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 7),
        (S.READY_TO_SWITCH_ON, CW_QUICK_STOP, S.SWITCH_ON_DISABLED, 7),
        (S.OPERATION_ENABLED, CW_SHUTDOWN, S.READY_TO_SWITCH_ON, 8),
        (S.OPERATION_ENABLED, CW_DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 9),
        (S.SWITCHED_ON, CW_DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 10),
        (S.SWITCHED_ON, CW_QUICK_STOP, S.SWITCH_ON_DISABLED, 10),
        (S.OPERATION_ENABLED, CW_QUICK_STOP, S.QUICK_STOP_ACTIVE, 11),
        (S.QUICK_STOP_ACTIVE, CW_DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 12),
    ],
)
def test_controlword_transitions(start: State, cw: int, end: State, number: int) -> None:
    d = drive_in(start)
    assert d.controlword(cw) == number
    assert d.state is end and d.last_transition == number
    assert decode_state(d.statusword) is end


def test_automatic_and_fault_transitions() -> None:
    d = DriveStateMachine()
    assert d.state is S.NOT_READY_TO_SWITCH_ON and d.last_transition == 0
    d.boot()
    assert (d.state, d.last_transition) == (S.SWITCH_ON_DISABLED, 1)
    for state in S:
        if state in (S.FAULT_REACTION_ACTIVE, S.FAULT):
            continue
        d = drive_in(state)
        assert d.fault() == 13 and d.state is S.FAULT_REACTION_ACTIVE
        assert d.fault() is None  # a second fault during the reaction changes nothing
        assert d.fault_reaction_done() == 14 and d.state is S.FAULT


def test_fault_reset_needs_a_rising_edge() -> None:
    d = drive_in(S.FAULT)
    d._cw = CW_FAULT_RESET  # bit 7 was already high: no edge
    assert d.controlword(CW_FAULT_RESET) is None and d.state is S.FAULT
    assert d.controlword(CW_DISABLE_VOLTAGE) is None
    assert d.controlword(CW_FAULT_RESET) == 15 and d.state is S.SWITCH_ON_DISABLED


def test_quick_stop_options() -> None:
    d = drive_in(S.QUICK_STOP_ACTIVE, quick_stop_option=2)
    assert d.controlword(CW_ENABLE_OPERATION) is None  # options 1-4: no way back
    assert d.quick_stop_done() == 12 and d.state is S.SWITCH_ON_DISABLED
    d = drive_in(S.QUICK_STOP_ACTIVE, quick_stop_option=6)
    assert d.quick_stop_done() is None and d.state is S.QUICK_STOP_ACTIVE  # options 5-8: stays
    assert d.controlword(CW_ENABLE_OPERATION) == 16 and d.state is S.OPERATION_ENABLED
    d = drive_in(S.OPERATION_ENABLED, quick_stop_option=0)
    d.controlword(CW_QUICK_STOP)
    assert d.state is S.SWITCH_ON_DISABLED  # option 0: coast, the drive function is off at once


def test_commands_that_do_not_apply_change_nothing() -> None:
    d = drive_in(S.SWITCH_ON_DISABLED)
    for cw in (CW_SWITCH_ON, CW_ENABLE_OPERATION, CW_QUICK_STOP):
        assert d.controlword(cw) is None and d.state is S.SWITCH_ON_DISABLED
    d = drive_in(S.NOT_READY_TO_SWITCH_ON)
    assert d.controlword(CW_SHUTDOWN) is None and d.state is S.NOT_READY_TO_SWITCH_ON


def test_statusword_coding() -> None:
    for state in S:
        d = drive_in(state)
        sw = d.statusword
        assert decode_state(sw) is state
        assert sw & SW_REMOTE
        powered = state not in (S.NOT_READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED, S.FAULT)
        assert bool(sw & SW_VOLTAGE_ENABLED) == powered
    # examples from drive manuals: 0x0250 switch on disabled, 0x0237 operation enabled, 0x0218 fault
    assert decode_state(0x0250) is S.SWITCH_ON_DISABLED
    assert decode_state(0x0237) is S.OPERATION_ENABLED
    assert decode_state(0x0218) is S.FAULT
    assert decode_state(0x0207) is S.QUICK_STOP_ACTIVE


@pytest.mark.parametrize("start", list(S))
def test_command_towards_reaches_operation_enabled_from_every_state(start: State) -> None:
    d = drive_in(start)
    for _ in range(10):
        if d.state is S.FAULT_REACTION_ACTIVE:
            d.fault_reaction_done()
        if d.state is S.NOT_READY_TO_SWITCH_ON:
            d.boot()
        cw = command_towards(decode_state(d.statusword))
        if cw == CW_FAULT_RESET and d._cw & 0x80:
            d.controlword(CW_DISABLE_VOLTAGE)
        if cw is not None:
            d.controlword(cw)
        if d.state is S.OPERATION_ENABLED:
            break
    assert d.state is S.OPERATION_ENABLED


@pytest.mark.parametrize("start", list(S))
def test_command_towards_switched_on_reaches_it_from_every_state_and_stays(start: State) -> None:
    """Where the startup parks the drives (powered, torque off) until SYNC runs."""
    d = drive_in(start)
    for _ in range(10):
        if d.state is S.FAULT_REACTION_ACTIVE:
            d.fault_reaction_done()
        if d.state is S.NOT_READY_TO_SWITCH_ON:
            d.boot()
        cw = command_towards(decode_state(d.statusword), S.SWITCHED_ON)
        if cw == CW_FAULT_RESET and d._cw & 0x80:
            d.controlword(CW_DISABLE_VOLTAGE)
        if cw is not None:
            d.controlword(cw)
    assert d.state is S.SWITCHED_ON
    assert not d.power_stage_on
