"""The whole simulated controller: the controller's cycle, its servers and its faults.

`UrSimulator.open()` listens on every port (or raises `PortTakenError`), `run()` runs the controller
cycle on absolute deadlines until told to stop. Faults (`inject`) act as the real ones would:

- `protective_stop`, `emergency_stop` (then `emergency_stop_release`): the safety system;
- `stream_stall` (`duration_s`): no RTDE data package leaves for that long, then the stream
  resumes with the newest data (a stalled network or an overloaded controller);
- `drop_connection` (`ports`: rtde, dashboard, script or all): the open connections are cut,
  the ports stay open;
- `controller_restart` (`down_s`): every port closes, the controller reboots (power off,
  program and registers cleared), and the ports open again `down_s` later.

And the world and the I/O the test plays (not faults, the same channel):

- `wall` (`point_m`, `normal`, `stiffness_n_m`, optional `damping_n_s_m`), `wall_remove`;
- `push` (`force_n`, optional `torque_nm`, `duration_s`): a wrench on the TCP (base frame);
- `digital_input`, `configurable_digital_input`, `tool_digital_input` (`index`, `value`):
  inputs 0-7, 0-7 and 0-1 (bits 0-7, 8-15 and 16-17 of actual_digital_input_bits);
- `ft_noise` (`force_n`, `torque_nm`, `seed`): the force/torque sensor's noise.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.errors import OrccaddError
from orccadd.runtime import PeriodicExecutor, WallClock
from orccadd.runtime.sim_control import device
from orccadd.runtime.threads import ThreadGroup
from orccadd.ursim.arm import UrArm
from orccadd.ursim.controller import UrController
from orccadd.ursim.dashboard import dashboard_handler
from orccadd.ursim.net import Server
from orccadd.ursim.rtde_server import Stall, rtde_handler
from orccadd.ursim.script_server import script_handler
from orccadd.ursim.series import Series
from orccadd.ursim.world import push_from_params, wall_from_params

log = logging.getLogger("orccadd.ursim")

DEFAULT_PORTS = {"rtde": 30004, "dashboard": 29999, "primary": 30001, "secondary": 30002, "realtime": 30003}
FAULTS = (
    "protective_stop",
    "emergency_stop",
    "emergency_stop_release",
    "stream_stall",
    "drop_connection",
    "controller_restart",
)
WORLD = ("wall", "wall_remove", "push", "plane", "hole", "tool", "clear_world", "ft_noise", "speed_slider")
# input name -> (first bit of actual_digital_input_bits, count)
DIGITAL_INPUTS = {
    "digital_input": (0, 8),
    "configurable_digital_input": (8, 8),
    "tool_digital_input": (16, 2),
}


class UrSimulator:
    def __init__(
        self,
        cfg: RobotConfig,
        series: Series,
        *,
        host: str = "127.0.0.1",
        ports: dict[str, int] | None = None,
        sim_settings: dict[str, Any] | None = None,
        sim_settings_file: str = "",
        unlock_delay_s: float = 5.0,
        boot_running: bool = False,
    ) -> None:
        arm = UrArm(cfg, 1.0 / series.rate_hz, sim_settings or {}, sim_settings_file)
        self.ctl = UrController(arm, series, unlock_delay_s, boot_running)
        self.stall = Stall()
        self.stop_requested = threading.Event()
        p = {**DEFAULT_PORTS, **(ports or {})}
        self.servers: dict[str, Server] = {
            "rtde": Server("rtde", host, p["rtde"], rtde_handler(self.ctl, self.stall)),
            "dashboard": Server(
                "dashboard", host, p["dashboard"], dashboard_handler(self.ctl, self.stop_requested.set)
            ),
        }
        for name in ("primary", "secondary", "realtime"):
            self.servers[name] = Server(name, host, p[name], script_handler(self.ctl, p[name]))
        self.executor = PeriodicExecutor(WallClock(), self.ctl.period_s, self._step)
        self._down = False
        self.threads = ThreadGroup("ursim-faults")  # an injected restart's (joined at the exit)

    def open(self) -> None:
        """Listen on every port; on `PortTakenError` none stays open."""
        try:
            for srv in self.servers.values():
                srv.open()
        except Exception:
            self.close()
            raise

    def close(self) -> None:
        for srv in self.servers.values():
            srv.close()

    def run(self, stop: Callable[[], bool]) -> None:
        """The controller's cycle until `stop()` (checked after every cycle)."""
        self.executor.run(until=lambda: stop() or self.stop_requested.is_set())

    def _step(self, t_s: float) -> None:
        if not self._down:
            self.ctl.step(t_s)

    # ---- faults ---------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        """Inject one of `FAULTS` (`ValueError` for an unknown one or a bad parameter)."""
        ctl = self.ctl
        if fault == "protective_stop":
            with ctl.lock:
                ctl.protective_stop(str(params.get("reason", "injected protective stop")))
        elif fault == "emergency_stop":
            with ctl.lock:
                ctl.emergency_stop()
        elif fault == "emergency_stop_release":
            with ctl.lock:
                ctl.release_emergency_stop()
        elif fault == "stream_stall":
            duration = float(params.get("duration_s", 1.0))
            self.stall.hold(duration)
        elif fault == "drop_connection":
            which = str(params.get("ports", "rtde"))
            names = {
                "rtde": ["rtde"],
                "dashboard": ["dashboard"],
                "script": ["primary", "secondary", "realtime"],
            }
            if which != "all" and which not in names:
                raise ValueError(f"ports (={which!r}) must be rtde, dashboard, script or all")
            for name in names.get(which, list(self.servers)):
                self.servers[name].drop_connections()
        elif fault == "controller_restart":
            down = float(params.get("down_s", 1.0))
            self.threads.start(self._restart, down, name="restart")
        elif fault in WORLD or fault in DIGITAL_INPUTS:
            with ctl.lock:
                self._set_world(fault, params)
        else:
            known = ", ".join((*FAULTS, *WORLD, *DIGITAL_INPUTS))
            raise ValueError(f"unknown fault {fault!r} (faults: {known})")
        log.info("fault injected: %s %s", fault, params or "")

    def _set_world(self, what: str, params: dict[str, Any]) -> None:
        """One of `WORLD` or `DIGITAL_INPUTS` (under the controller's lock)."""
        ctl = self.ctl
        if what == "wall":
            ctl.world.wall = wall_from_params(params)
        elif what == "wall_remove":
            ctl.world.wall = None
        elif what == "push":
            ctl.world.push = push_from_params(params, ctl.now_s())
        elif what in ("plane", "hole", "tool", "clear_world"):
            ctl.world.change(what, params)
        elif what == "ft_noise":
            unknown = set(params) - {"force_n", "torque_nm", "seed"}
            if unknown:
                raise ValueError(f"ft_noise: unknown parameter(s) {', '.join(sorted(unknown))}")
            noise = (float(params.get("force_n", 0.0)), float(params.get("torque_nm", 0.0)))
            ctl.forces.sensor.set_noise(*noise, int(params.get("seed", 0)))
        elif what == "speed_slider":  # a person's hand on the teach pendant's slider
            value = params.get("fraction")
            if set(params) != {"fraction"} or isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f'speed_slider takes "fraction", a number in [0, 1] (got {params})')
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"speed_slider: fraction (={value!r}) must be in [0, 1]")
            ctl.speed.slider = float(value)
        else:
            first, count = DIGITAL_INPUTS[what]
            if set(params) != {"index", "value"}:
                raise ValueError(f'{what} takes "index" and "value" (got {sorted(params)})')
            index, value = params["index"], params["value"]
            if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < count:
                raise ValueError(f"{what}: index (={index!r}) must be an integer in [0, {count - 1}]")
            if not isinstance(value, bool):
                raise ValueError(f"{what}: value (={value!r}) must be true or false")
            bit = 1 << (first + index)
            s = ctl.state
            s.digital_input_bits = (s.digital_input_bits | bit) if value else (s.digital_input_bits & ~bit)

    def _restart(self, down_s: float) -> None:
        self._down = True
        self.close()
        with self.ctl.lock:
            self.ctl.reset()
        time.sleep(down_s)
        for srv in self.servers.values():
            for attempt in range(50):
                try:
                    srv.open()
                    break
                except OrccaddError as e:  # taken meanwhile: retry for 5 s, then say so
                    if attempt == 49:
                        log.error("after the restart: %s", e)
                    time.sleep(0.1)
        self._down = False
        log.info("controller restarted")

    def status(self) -> dict[str, Any]:
        ctl = self.ctl
        with ctl.lock:
            safety = ctl.safety_mode.name
            return {
                "q_rad": ctl.arm.q_rad.tolist(),
                "dq_rad_s": ctl.arm.dq_rad_s.tolist(),
                "devices": [device("controller", ctl.robot_mode.name, "" if safety == "NORMAL" else safety)],
                "robot_mode": ctl.robot_mode.name,
                "safety_mode": ctl.safety_mode.name,
                "runtime_state": ctl.runtime_state.name,
                "program": ctl.program_name if ctl.program is not None else "",
                "stop_reason": ctl.stop_reason,
                "protective_stops": ctl.protective_stops,
                "target_q_rad": ctl.target.q.tolist(),
                "cycles": ctl.cycles,
                "rate_hz": ctl.series.rate_hz,
                "overruns": self.executor.stats.overruns,
                "rtde_streams": len(ctl.subscribers),
                "connections": {name: srv.connections for name, srv in self.servers.items()},
                "ports": {name: srv.port for name, srv in self.servers.items()},
                "down": self._down,
                # for benchmarks (benchmarks/ur_rtde_cycle.py): the cycle's timing and servoJ updates
                "missed_periods": self.executor.stats.missed_ticks,
                "clock_origin_s": ctl.clock_origin_s(),
                "input_packages": ctl.input_packages,
                "servoj_cycles": ctl.servoj_cycles,
                "servoj_stale_cycles": ctl.servoj_stale_cycles,
                "servoj_overwritten": ctl.servoj_overwritten,
                "rtde_packages_skipped": ctl.rtde_packages_skipped,
                # the force side and the I/O
                **ctl.world.describe(),
                "tcp_force": ctl.state.actual_tcp_force.tolist(),
                "external_wrench": ctl.forces.external.tolist(),
                "motion": ctl.motion.name if not ctl.motion_done else "",
                "payload_kg": ctl.arm.payload_kg,
                "digital_input_bits": ctl.state.digital_input_bits,
                "digital_output_bits": ctl.state.digital_output_bits,
                "speed_scaling": ctl.speed.scaling,
            }
