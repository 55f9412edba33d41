"""Everything the controller exports over RTDE and everything a client may write, by field name.

`RobotState` holds the values (preallocated arrays the controller's cycle updates in place);
`output_field(name)` and `input_field(name)` give a field's RTDE type and its getter or setter,
or None for a name the controller does not have (answered NOT_FOUND). Names and types are the
RTDE guide's ("Field names and associated types", PolyScope 5.11 / 3.15); fields of devices the
simulator does not model (tool analog I/O, Euromap, analog inputs, energy) read as constants.
Digital outputs (standard 0-7, configurable 8-15, tool 16-17 of `actual_digital_output_bits`)
are written by RTDE clients through the masked inputs; digital inputs (the same layout in
`actual_digital_input_bits`) by the control channel.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import numpy as np

from orccadd.state import FloatArray
from orccadd.ursim.fields import Getter, RtdeType, Setter

N_REGISTERS = 48  # int and double registers 0-47 (24-47: the upper range of 3.9+/5.3+)
BIT_REGISTERS = 128  # bit registers 0-127 (64-127 addressable one by one)

D, V3, V6 = RtdeType.DOUBLE, RtdeType.VECTOR3D, RtdeType.VECTOR6D


class RobotState:
    """The exported state; vectors are numpy arrays updated in place by the controller."""

    def __init__(self) -> None:
        self.timestamp_s = 0.0
        self.target_q, self.target_qd, self.target_qdd = _z6(), _z6(), _z6()
        self.target_current, self.target_moment = _z6(), _z6()
        self.actual_q, self.actual_qd, self.actual_current = _z6(), _z6(), _z6()
        self.actual_current_as_torque = _z6()
        self.actual_tcp_pose, self.actual_tcp_speed, self.actual_tcp_force = _z6(), _z6(), _z6()
        self.target_tcp_pose, self.target_tcp_speed = _z6(), _z6()
        self.tcp_offset = _z6()
        self.elbow_position, self.elbow_velocity = np.zeros(3), np.zeros(3)
        self.joint_temperatures_c = np.full(6, 35.0)
        self.actual_joint_voltage = _z6()
        self.actual_tool_accelerometer = np.array([0.0, 0.0, 9.82])
        self.payload_kg = 0.0
        self.payload_cog, self.payload_inertia = np.zeros(3), _z6()
        self.robot_mode = 0
        self.safety_mode = 0
        self.runtime_state = 0
        self.joint_mode = [0] * 6
        self.robot_status_bits = 0
        self.safety_status_bits = 0
        self.speed_scaling = 1.0
        self.target_speed_fraction = 1.0
        self.actual_execution_time_ms = 0.0
        self.actual_momentum = 0.0
        self.main_voltage_v = 0.0
        self.robot_voltage_v = 0.0
        self.robot_current_a = 0.0
        self.digital_output_bits = 0  # standard 0-7, configurable 8-15, tool 16-17
        self.digital_input_bits = 0  # the same layout (set through the control channel)
        self.ft_raw_wrench = _z6()
        self.analog_output = [0.0, 0.0]
        self.analog_output_types = 0
        self.speed_slider_mask = 0
        self.speed_slider_fraction = 1.0
        self.external_force_torque = _z6()
        self.in_int = [0] * N_REGISTERS
        self.in_double = [0.0] * N_REGISTERS
        self.out_int = [0] * N_REGISTERS
        self.out_double = [0.0] * N_REGISTERS
        self.in_bits = 0  # bit registers 0-127 as one integer
        self.out_bits = 0


def _z6() -> FloatArray:
    return np.zeros(6)


def _const(value: Any) -> Getter:
    return lambda: value


def _vec(a: FloatArray) -> Getter:
    return a.tolist


def _outputs(s: RobotState) -> dict[str, tuple[RtdeType, Getter]]:
    T = RtdeType
    return {
        "timestamp": (D, lambda: s.timestamp_s),
        "target_q": (V6, _vec(s.target_q)),
        "target_qd": (V6, _vec(s.target_qd)),
        "target_qdd": (V6, _vec(s.target_qdd)),
        "target_current": (V6, _vec(s.target_current)),
        "target_moment": (V6, _vec(s.target_moment)),
        "actual_q": (V6, _vec(s.actual_q)),
        "actual_qd": (V6, _vec(s.actual_qd)),
        "actual_current": (V6, _vec(s.actual_current)),
        "actual_current_window": (V6, _const([0.0] * 6)),
        "actual_current_as_torque": (V6, _vec(s.actual_current_as_torque)),
        "joint_control_output": (V6, _vec(s.actual_current)),
        "actual_TCP_pose": (V6, _vec(s.actual_tcp_pose)),
        "actual_TCP_speed": (V6, _vec(s.actual_tcp_speed)),
        "actual_TCP_force": (V6, _vec(s.actual_tcp_force)),
        "target_TCP_pose": (V6, _vec(s.target_tcp_pose)),
        "target_TCP_speed": (V6, _vec(s.target_tcp_speed)),
        "tcp_offset": (V6, _vec(s.tcp_offset)),
        "actual_digital_input_bits": (T.UINT64, lambda: s.digital_input_bits),
        "actual_configurable_digital_input_bits": (T.UINT64, lambda: (s.digital_input_bits >> 8) & 0xFF),
        "joint_temperatures": (V6, _vec(s.joint_temperatures_c)),
        "actual_execution_time": (D, lambda: s.actual_execution_time_ms),
        "robot_mode": (T.INT32, lambda: s.robot_mode),
        "joint_mode": (T.VECTOR6INT32, lambda: s.joint_mode),
        "safety_mode": (T.INT32, lambda: s.safety_mode),
        "safety_status": (T.INT32, lambda: s.safety_mode),
        "actual_tool_accelerometer": (V3, _vec(s.actual_tool_accelerometer)),
        "speed_scaling": (D, lambda: s.speed_scaling),
        "target_speed_fraction": (D, lambda: s.target_speed_fraction),
        "actual_momentum": (D, lambda: s.actual_momentum),
        "actual_main_voltage": (D, lambda: s.main_voltage_v),
        "actual_robot_voltage": (D, lambda: s.robot_voltage_v),
        "actual_robot_current": (D, lambda: s.robot_current_a),
        "actual_joint_voltage": (V6, _vec(s.actual_joint_voltage)),
        "actual_digital_output_bits": (T.UINT64, lambda: s.digital_output_bits),
        "actual_configurable_digital_output_bits": (T.UINT64, lambda: (s.digital_output_bits >> 8) & 0xFF),
        "runtime_state": (T.UINT32, lambda: s.runtime_state),
        "elbow_position": (V3, _vec(s.elbow_position)),
        "elbow_velocity": (V3, _vec(s.elbow_velocity)),
        "robot_status_bits": (T.UINT32, lambda: s.robot_status_bits),
        "safety_status_bits": (T.UINT32, lambda: s.safety_status_bits),
        "analog_io_types": (T.UINT32, lambda: s.analog_output_types << 2),
        "standard_analog_input0": (D, _const(0.0)),
        "standard_analog_input1": (D, _const(0.0)),
        "standard_analog_output0": (D, lambda: s.analog_output[0]),
        "standard_analog_output1": (D, lambda: s.analog_output[1]),
        "io_current": (D, _const(0.0)),
        "actual_robot_energy_consumed": (D, _const(0.0)),
        "actual_robot_braking_energy_dissipated": (D, _const(0.0)),
        "tool_mode": (T.UINT32, _const(0)),
        "tool_analog_input_types": (T.UINT32, _const(0)),
        "tool_analog_input0": (D, _const(0.0)),
        "tool_analog_input1": (D, _const(0.0)),
        "tool_output_voltage": (T.INT32, _const(0)),
        "tool_output_current": (D, _const(0.0)),
        "tool_temperature": (D, _const(30.0)),
        "tcp_force_scalar": (D, _const(0.0)),
        "joint_position_deviation_ratio": (D, _const(0.0)),
        "collision_detection_ratio": (D, _const(0.0)),
        "ft_raw_wrench": (V6, _vec(s.ft_raw_wrench)),
        "payload": (D, lambda: s.payload_kg),
        "payload_cog": (V3, _vec(s.payload_cog)),
        "payload_inertia": (V6, _vec(s.payload_inertia)),
        "script_control_line": (T.UINT32, _const(0)),
        "output_bit_registers0_to_31": (T.UINT32, lambda: s.out_bits & 0xFFFFFFFF),
        "output_bit_registers32_to_63": (T.UINT32, lambda: (s.out_bits >> 32) & 0xFFFFFFFF),
        "input_bit_registers0_to_31": (T.UINT32, lambda: s.in_bits & 0xFFFFFFFF),
        "input_bit_registers32_to_63": (T.UINT32, lambda: (s.in_bits >> 32) & 0xFFFFFFFF),
    }


def _set_vec(a: FloatArray) -> Setter:
    def set_value(v: Any) -> None:
        a[:] = v

    return set_value


def _set_masked(s: RobotState, shift: int, mask_holder: list[int]) -> tuple[Setter, Setter]:
    """Setters for a (mask, value) byte pair of digital outputs: bits `shift`..`shift+7`."""

    def set_mask(v: Any) -> None:
        mask_holder[0] = int(v)

    def set_value(v: Any) -> None:
        m = mask_holder[0] << shift
        s.digital_output_bits = (s.digital_output_bits & ~m) | ((int(v) << shift) & m)

    return set_mask, set_value


def _inputs(s: RobotState) -> dict[str, tuple[RtdeType, Setter]]:
    T = RtdeType
    std, conf, tool, analog = [0], [0], [0], [0]
    std_mask, std_value = _set_masked(s, 0, std)
    conf_mask, conf_value = _set_masked(s, 8, conf)
    tool_mask, tool_value = _set_masked(s, 16, tool)

    def setattr_(name: str) -> Setter:
        return lambda v: setattr(s, name, v)

    def analog_out(i: int) -> Setter:
        def set_value(v: Any) -> None:
            if analog[0] & (1 << i):
                s.analog_output[i] = float(v)

        return set_value

    def set_bits(shift: int) -> Setter:
        def set_value(v: Any) -> None:
            m = 0xFFFFFFFF << shift
            s.in_bits = (s.in_bits & ~m) | ((int(v) << shift) & m)

        return set_value

    return {
        "speed_slider_mask": (T.UINT32, setattr_("speed_slider_mask")),
        "speed_slider_fraction": (D, setattr_("speed_slider_fraction")),
        "standard_digital_output_mask": (T.UINT8, std_mask),
        "standard_digital_output": (T.UINT8, std_value),
        "configurable_digital_output_mask": (T.UINT8, conf_mask),
        "configurable_digital_output": (T.UINT8, conf_value),
        "tool_digital_output_mask": (T.UINT8, tool_mask),
        "tool_digital_output": (T.UINT8, tool_value),
        "standard_analog_output_mask": (T.UINT8, lambda v: analog.__setitem__(0, int(v))),
        "standard_analog_output_type": (T.UINT8, setattr_("analog_output_types")),
        "standard_analog_output_0": (D, analog_out(0)),
        "standard_analog_output_1": (D, analog_out(1)),
        "external_force_torque": (V6, _set_vec(s.external_force_torque)),
        "input_bit_registers0_to_31": (T.UINT32, set_bits(0)),
        "input_bit_registers32_to_63": (T.UINT32, set_bits(32)),
    }


_REGISTER = re.compile(r"(input|output)_(int|double|bit)_register_(\d+)")


def _register(s: RobotState, name: str) -> tuple[str, RtdeType, Getter, Setter] | None:
    """A numbered register: (input/output, type, getter, setter), or None."""
    m = _REGISTER.fullmatch(name)
    if m is None or (len(m[3]) > 1 and m[3].startswith("0")):
        return None
    side, kind, i = m[1], m[2], int(m[3])
    if kind == "bit":
        if not 64 <= i < BIT_REGISTERS:
            return None
        attr = "in_bits" if side == "input" else "out_bits"

        def get_bit() -> bool:
            return bool(getattr(s, attr) >> i & 1)

        def set_bit(v: Any) -> None:
            setattr(s, attr, getattr(s, attr) & ~(1 << i) | (int(bool(v)) << i))

        return side, RtdeType.BOOL, get_bit, set_bit
    if i >= N_REGISTERS:
        return None
    banks: dict[tuple[str, str], list[Any]] = {
        ("input", "int"): s.in_int,
        ("input", "double"): s.in_double,
        ("output", "int"): s.out_int,
        ("output", "double"): s.out_double,
    }
    bank = banks[side, kind]
    conv: Callable[[Any], Any] = int if kind == "int" else float

    def set_reg(v: Any) -> None:
        bank[i] = conv(v)

    return side, RtdeType.INT32 if kind == "int" else D, lambda: bank[i], set_reg


class FieldTable:
    """Field lookup over one `RobotState` (built once, at start)."""

    def __init__(self, state: RobotState) -> None:
        self.state = state
        self._outputs = _outputs(state)
        self._inputs = _inputs(state)

    def output_field(self, name: str) -> tuple[RtdeType, Getter] | None:
        """A field a client may read: outputs, and every register (inputs read back too)."""
        if name in self._outputs:
            return self._outputs[name]
        reg = _register(self.state, name)
        return None if reg is None else (reg[1], reg[2])

    def input_field(self, name: str) -> tuple[RtdeType, Setter] | None:
        """A field a client may write: the controller's inputs and the input registers."""
        if name in self._inputs:
            return self._inputs[name]
        reg = _register(self.state, name)
        if reg is None or reg[0] != "input":
            return None
        return reg[1], reg[3]
