"""Simulated arm: Pinocchio forward dynamics (ABA) integrated in fixed sub-steps.

The co-simulation target of seed 001: the same Robot-Tasks run on it and on hardware. It
models what the controller would meet on a real arm:

- rigid-body dynamics from the URDF's inertial parameters, semi-implicit Euler at `substep_s`;
- viscous and Coulomb friction (Coulomb as a velocity-level projection, so joints really
  stick), holding brakes as extra Coulomb torque while engaged;
- torque saturation at max_torque_nm; in position and velocity modes, a joint servo (PD with
  gravity feed-forward, per-axis gains from the reflected inertia) like a drive's inner loop;
- measurement noise and latency (whole periods), deterministic for a given seed;
- a contact world (planes, holes: `contact`) acting on the tool point through its Jacobian, and
  the tool's force/torque sensor (the `wrench` signal, not delayed): `sim_contact`; a camera on
  the tool seeing a target (`features`, `target_visible`): `sim_camera`;
- safe stop by IEC 60204-1 category (0, 1, 2), and `inject_fault()` for fault tests.

Time is the caller's: `read(t_s)` integrates the dynamics up to `t_s` with the last command
held (zero-order hold), so the simulation follows a wall clock or a simulated clock alike.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar, TypeVar

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field, load_dataclass
from orccadd.errors import ConfigError
from orccadd.fault import Fault, FaultKind
from orccadd.model import RobotModel
from orccadd.physres.arm_dynamics import ArmDynamics
from orccadd.physres.base import PhysicalResource
from orccadd.physres.contact import ContactWorld
from orccadd.physres.description import MEASURED, ResourceDescription
from orccadd.physres.sim_camera import CameraSettings, SimCamera, camera_signals, check_camera
from orccadd.physres.sim_contact import WRENCH, HoleSettings, PlaneSettings, ToolContact, shapes_from_settings
from orccadd.state import FloatArray, JointState
from orccadd.types import CommandMode, Status
from orccadd.vec import clamp, float_view

INF = math.inf
POSITION = CommandMode.POSITION  # as a module global: a tick compares with it (see physres.base)
REST_SPEED_RAD_S = 0.005
INJECTED_FAULT_CODE = 0x1000  # "generic error" in CiA 301's EMCY table


def simulated_description(backend: str, config: RobotConfig) -> ResourceDescription:
    """What the simulated arm can do: every mode, everything measured (simulated sensors, the
    tool's wrench too), brakes, every stop category; its plant computes inside or beside the
    control process."""
    return ResourceDescription(
        backend=backend,
        joints=config.joint_names,
        modes=frozenset(CommandMode),
        mode_switch_needs_disable=False,
        position=MEASURED,
        velocity=MEASURED,
        torque=MEASURED,
        brakes=True,
        stop_categories=frozenset({0, 1, 2}),
        read_time_s=0.0,
        write_time_s=0.0,
        fault_reset=True,
        fault_injection=("device",),
        signals=(WRENCH, *camera_signals(config)),
    )


@dataclass(frozen=True)
class SimSettings:
    """`[resource.settings]` of the `sim` backend. Per-joint tuples may be empty (zeros)."""

    substep_s: float = field(default=0.0002, bounds=(1e-6, 0.01))
    viscous_friction_nm_s_rad: tuple[float, ...] = field(default=(), bounds=(0.0, INF))
    coulomb_friction_nm: tuple[float, ...] = field(default=(), bounds=(0.0, INF))
    brake_torque_nm: tuple[float, ...] = field(default=(), bounds=(0.0, INF))
    noise_q_rad: float = field(default=0.0, bounds=(0.0, 1.0))
    noise_dq_rad_s: float = field(default=0.0, bounds=(0.0, 10.0))
    noise_tau_nm: float = field(default=0.0, bounds=(0.0, 100.0))
    latency_periods: int = field(default=0, bounds=(0, 100))
    seed: int = field(default=0, bounds=(0, 2**63 - 1))
    initial_q_rad: tuple[float, ...] = field(default=())
    servo_bandwidth_hz: float = field(default=20.0, bounds=(0.1, 500.0))
    # the contact world (`contact`, `sim_contact`): the tool a sphere of this radius about its point
    tool_radius_m: float = field(default=0.0, bounds=(0.0, 1.0))
    world_planes: tuple[PlaneSettings, ...] = field(default=())
    world_holes: tuple[HoleSettings, ...] = field(default=())
    ft_noise_force_n: float = field(default=0.0, bounds=(0.0, 100.0))  # the sensor's noise (std)
    ft_noise_torque_nm: float = field(default=0.0, bounds=(0.0, 10.0))
    camera: CameraSettings | None = field(default=None)  # `[resource.settings.camera]`: sim_camera


S = TypeVar("S", bound=SimSettings)


def load_sim_settings(settings_cls: type[S], raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> S:
    """Check `[resource.settings]` of a simulated-arm backend (`sim`, `sim_process`)."""
    s = load_dataclass(settings_cls, raw, file, "resource.settings")
    n = cfg.dof
    for name in (
        "viscous_friction_nm_s_rad",
        "coulomb_friction_nm",
        "brake_torque_nm",
        "initial_q_rad",
    ):
        v = getattr(s, name)
        if len(v) not in (0, n):
            raise ConfigError(
                file,
                f"resource.settings.{name}",
                f"has {len(v)} entries, must have one per joint ({n}) or none",
            )
    if s.substep_s > cfg.control_period_s:
        raise ConfigError(
            file,
            "resource.settings.substep_s",
            f"(={s.substep_s!r}) must be at most control_period_s (={cfg.control_period_s!r})",
        )
    for i, q in enumerate(s.initial_q_rad):
        j = cfg.joints[i]
        if not j.position_min_rad <= q <= j.position_max_rad:
            raise ConfigError(
                file,
                f"resource.settings.initial_q_rad[{i}]",
                f"(={q!r}) must be in [{j.position_min_rad:g}, {j.position_max_rad:g}] ({j.name})",
            )
    shapes_from_settings(s.world_planes, s.world_holes, file)  # ConfigError if a shape is wrong
    check_camera(s.camera, file)
    if not s.brake_torque_nm:
        s = replace(s, brake_torque_nm=tuple(2.0 * j.max_torque_nm for j in cfg.joints))
    return s


class SimulatedArm(PhysicalResource):
    """A Physical Resource whose joints move by the robot's rigid-body dynamics."""

    Settings: ClassVar[type[Any]] = SimSettings

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        return simulated_description("sim", config)

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> SimSettings:
        return load_sim_settings(SimSettings, raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        s: SimSettings = config.backend_settings
        if s is None:
            s = SimulatedArm.load_settings({}, config, config.source)
        self.settings = s
        n = self.dof

        def vec(v: tuple[float, ...]) -> FloatArray:
            return np.array(v, dtype=np.float64) if v else np.zeros(n)

        self._pin = model.model
        self._data = model.new_data()
        self._brake = vec(s.brake_torque_nm)
        self._rng = np.random.default_rng(s.seed)
        self.arm = ArmDynamics(
            model,
            vec(s.initial_q_rad) if s.initial_q_rad else model.home_rad,
            viscous_nm_s_rad=vec(s.viscous_friction_nm_s_rad),
            coulomb_nm=vec(s.coulomb_friction_nm),
        )
        world = ContactWorld(
            shapes_from_settings(s.world_planes, s.world_holes, config.source), s.tool_radius_m
        )
        self.contact = ToolContact(model, world, s.ft_noise_force_n, s.ft_noise_torque_nm, s.seed)
        self.arm.external = self.contact.torque
        self._wrench = self.signals[WRENCH.name]
        self.camera = SimCamera.of(model, s, s.seed, self.signals)  # None: no camera
        self.q: FloatArray = self.arm.q  # the same arrays, moved in place by the core
        self.dq: FloatArray = self.arm.dq
        self.tau_applied: FloatArray = np.zeros(n)
        self.t_sim_s: float | None = None
        self.brakes_engaged = True
        self.torque_on = False
        self._held_cmd: FloatArray = np.zeros(n)
        self._prev_pos_cmd: FloatArray = np.zeros(n)
        self._vel_ff: FloatArray = np.zeros(n)
        self._fault = 0
        self._stopping = False
        self._stop_t0_s = 0.0
        self._stop_v0: FloatArray = np.zeros(n)
        self._hold_q: FloatArray = np.zeros(n)
        self._holding = False
        # Servo gains from the reflected inertia at home (diagonal of M).
        m_diag = np.diag(pin.crba(self._pin, self._data, model.home_rad)).copy()
        w = 2 * math.pi * s.servo_bandwidth_hz
        self._kp = m_diag * w * w
        self._kd = m_diag * 2.0 * 0.9 * w
        self._kd_velocity = 4.0 * self._kd
        self._servo_tmp = np.zeros(n)
        self._zero = np.zeros(n)
        # Measurement delay line (latency in periods) and noise buffers.
        depth = s.latency_periods + 1
        self._ring = np.zeros((depth, 3 * n))
        # per slot: views on its q, dq and tau, and on the whole (`JointState.vector`'s order)
        self._slots = tuple((r[:n], r[n : 2 * n], r[2 * n :], r) for r in self._ring)
        # without latency, `read` copies the plant's q, dq and torques into the measured state
        # directly, through memoryviews (a copy between two costs a third of numpy's)
        st = self.state
        pairs = ((st.q_rad, self.q), (st.dq_rad_s, self.dq), (st.tau_nm, self.tau_applied))
        self._now = tuple((float_view(measured), float_view(now)) for measured, now in pairs)
        self._ring_i = 0
        self._ring_filled = False
        self._noise = np.zeros(n)
        self._neg_tau_max = -model.tau_max_nm

    # ---- lifecycle hooks ------------------------------------------------------------------
    def _on_configure(self) -> None:
        self.brakes_engaged = True
        self.torque_on = False

    def _on_activate(self, mode: CommandMode) -> None:
        self.state.q_rad[:] = self.q
        self._fault = 0
        self._stopping = False
        self._holding = False
        self._set_hold_command(mode)
        self.brakes_engaged = False
        self.torque_on = True

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self._set_hold_command(mode)

    def _set_hold_command(self, mode: CommandMode) -> None:
        if mode is CommandMode.TORQUE:
            self._held_cmd[:] = pin.computeGeneralizedGravity(self._pin, self._data, self.q)
        elif mode is CommandMode.POSITION:
            self._held_cmd[:] = self.q
        else:
            self._held_cmd[:] = 0.0
        self._prev_pos_cmd[:] = self.q
        self._vel_ff[:] = 0.0
        self.mode = mode

    def _on_deactivate(self) -> None:
        self.brakes_engaged = True
        self.torque_on = False

    def _on_shutdown(self) -> None:
        self.brakes_engaged = True
        self.torque_on = False

    def _on_clear_stop(self) -> None:
        self._stopping = False
        self._holding = False
        self._set_hold_command(self.mode)
        self.brakes_engaged = False
        self.torque_on = True

    @property
    def world(self) -> ContactWorld:
        """What the tool touches (`contact.ContactWorld`; `sim_contact.change_world` changes it)."""
        return self.contact.world

    # ---- fault injection (tests, demos) ---------------------------------------------------
    def _on_inject_fault(self, kind: str, message: str) -> None:
        """Make the next read report a device fault (like a drive's EMCY)."""
        self._fault = int(Status.FAULT)
        self.fault = Fault(FaultKind.DEVICE, self.name, message, code=INJECTED_FAULT_CODE)
        self.state.fault_code = INJECTED_FAULT_CODE

    def _on_reset_fault(self) -> None:
        """Acknowledge a device fault (like CiA 402 fault reset). Not for a tick."""
        self._fault = 0
        self.fault = None
        self.state.fault_code = 0

    # ---- tick hooks -----------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        if self.t_sim_s is None:
            self.t_sim_s = t_s
        self._advance_to(t_s)
        slots = self._slots
        if len(slots) == 1 and state is self.state:  # no latency: what the plant is now
            for measured, now in self._now:
                measured[:] = now
        else:  # what it was `latency_periods` reads ago (the first one, until then)
            q, dq, tau, _ = slots[self._ring_i]
            q[:] = self.q
            dq[:] = self.dq
            tau[:] = self.tau_applied
            i = self._ring_i = (self._ring_i + 1) % len(slots)
            if i == 0:
                self._ring_filled = True
            state.vector[:] = slots[i if self._ring_filled else 0][3]
        s = self.settings
        if s.noise_q_rad:
            self._rng.standard_normal(out=self._noise)
            state.q_rad += s.noise_q_rad * self._noise
        if s.noise_dq_rad_s:
            self._rng.standard_normal(out=self._noise)
            state.dq_rad_s += s.noise_dq_rad_s * self._noise
        if s.noise_tau_nm:
            self._rng.standard_normal(out=self._noise)
            state.tau_nm += s.noise_tau_nm * self._noise
        self.contact.measure(self.q, self.dq, self._wrench)
        if self.camera is not None:
            self.camera.measure(self.q)
        flags = self._fault
        if not self.torque_on:
            flags |= Status.TORQUE_OFF
        return flags

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        if mode is POSITION:
            period = self.config.control_period_s
            np.subtract(command, self._prev_pos_cmd, out=self._vel_ff)
            self._vel_ff /= period
            self._prev_pos_cmd[:] = command
        self._held_cmd[:] = command
        return self._fault

    def _begin_safe_stop(self) -> None:
        cat = self.config.safe_stop.category
        self._stopping = True
        self._stop_t0_s = self.t_sim_s or 0.0
        self._stop_v0[:] = self.dq
        if cat == 0:
            self._engage_brakes()

    def _engage_brakes(self) -> None:
        self.brakes_engaged = True
        self.torque_on = False
        self._stopping = False
        self._mark_stopped(torque_off=True)

    # ---- dynamics -------------------------------------------------------------------------
    def _advance_to(self, t_s: float) -> None:
        assert self.t_sim_s is not None
        h = self.settings.substep_s
        steps = int((t_s - self.t_sim_s) / h + 1e-9)
        if steps <= 0:
            return
        arm = self.arm
        arm.refresh_inertia()
        for _ in range(steps):
            self._holding_torque(arm.holding_nm)
            self._motor_torque(self.tau_applied)
            arm.step(self.tau_applied, h)
        self.t_sim_s += steps * h

    def _motor_torque(self, out: FloatArray) -> None:
        """Torque the motors apply this sub-step (saturated), by mode and stop state."""
        m = self.model
        if not self.torque_on:
            out[:] = 0.0
            return
        if self._stopping or self._holding:
            self._stop_torque(out)
        elif self.mode is CommandMode.TORQUE:
            out[:] = self._held_cmd
        elif self.mode is CommandMode.POSITION:
            self._servo(self._held_cmd, self._vel_ff, out)
        else:
            self._servo(None, self._held_cmd, out)
        clamp(out, self._neg_tau_max, m.tau_max_nm, out)

    def _servo(self, q_ref: FloatArray | None, v_ref: FloatArray, out: FloatArray) -> None:
        """The drive's joint servo, in place: g(q) + kp·(q_ref − q) + kd'·(v_ref − dq), where
        kd' = kd with a position reference and 4·kd for velocity alone (q_ref None)."""
        tmp = self._servo_tmp
        out[:] = pin.computeGeneralizedGravity(self._pin, self._data, self.q)
        np.subtract(v_ref, self.dq, out=tmp)
        tmp *= self._kd if q_ref is not None else self._kd_velocity
        out += tmp
        if q_ref is not None:
            np.subtract(q_ref, self.q, out=tmp)
            tmp *= self._kp
            out += tmp

    def _stop_torque(self, out: FloatArray) -> None:
        """Controlled stop: track a velocity ramp to zero, then hold or brake."""
        cfg = self.config.safe_stop
        if self._holding:
            self._servo(self._hold_q, self._zero, out)
            return
        assert self.t_sim_s is not None
        elapsed = self.t_sim_s - self._stop_t0_s
        dv = cfg.deceleration_rad_s2 * elapsed
        v_ref = np.sign(self._stop_v0) * np.maximum(np.abs(self._stop_v0) - dv, 0.0)
        self._servo(None, v_ref, out)
        at_rest = bool((np.abs(self.dq) < REST_SPEED_RAD_S).all()) and not v_ref.any()
        if at_rest or elapsed > cfg.timeout_s:
            if cfg.category == 2 and at_rest:
                self._holding = True
                self._stopping = False
                self._hold_q[:] = self.q
                self._mark_stopped(torque_off=False)
            else:
                self._engage_brakes()

    def _holding_torque(self, out: FloatArray) -> None:
        """The holding brakes' torque on each joint this sub-step (0 where released)."""
        if self.brakes_engaged:
            out[:] = self._brake
        else:
            out[:] = 0.0
