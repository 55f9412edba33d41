"""The UR controller's links, owned together: the dashboard server (power, brakes, protective-stop
unlock, version and model), ur_rtde's RTDE receive interface (the slow reads: the condition at a
reset, the measured currents and TCP pose; the tick's stream is `rtde_stream`'s) and the control script
(`RTDEControlInterface`: servoJ, speedJ, servoStop, speedStop, the RTDE watchdog), all through the
`ur-rtde` package; ur_rtde's I/O threads at our real-time priority; and the lock a reset holds
while it replaces them.

The `ur_rtde` resource ticks over it; nothing here knows about tasks or limits.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from orccadd.drivers.ur.controller import (
    ROBOT_PROGRAM_RUNNING,
    Condition,
    RobotMode,
    Version,
    condition,
    parse_polyscope_version,
    robot_model_name,
)
from orccadd.drivers.ur.settings import UrRtdeSettings
from orccadd.errors import ResourceError
from orccadd.runtime.rt import ThreadsStartedHere

log = logging.getLogger("orccadd.ur")

SLOW_RECEIVE_HZ = 125.0  # ur_rtde's receive interface: the slow reads only (the stream is ours)


class UrLink:
    """Dashboard, RTDE stream and control script of one controller (`settings.host`)."""

    def __init__(self, settings: UrRtdeSettings, period_s: float, name: str) -> None:
        self.settings = settings
        self.period_s = period_s
        self.name = name  # the resource's, for the errors' words
        self.receive: Any = None
        self.control: Any = None
        self.dashboard: Any = None
        self.io: Any = None  # ur_rtde's RTDEIOInterface, where the config names outputs
        self.version: Version | None = None
        self.robot_model = ""
        # `reset` and `clear_stop` come from the daemon's command thread while the control thread
        # ticks: they hold this lock over their dashboard/script work and link replacement, and a
        # tick that finds it taken leaves the links alone (the arm is at rest: reset needs it)
        self.lock = threading.Lock()
        self.watchdog_armed = False

    # ---- opening and closing (not for a tick) ---------------------------------------------
    def connect(self) -> None:
        """The dashboard (controller, model, period; power when configured), then RTDE and the
        control script."""
        import dashboard_client

        s = self.settings
        self.dashboard = dashboard_client.DashboardClient(s.host)
        self._try(self.dashboard.connect, f"the dashboard server at {s.host}:29999")
        self.version = parse_polyscope_version(self.dashboard.polyscopeVersion())
        self.robot_model = robot_model_name(self.dashboard.getRobotModel(), self.version)
        self._check_controller(self.version, self.robot_model)
        if s.power_on:
            self.power_on()
        mode = self.dashboard_robot_mode()
        if mode is not RobotMode.RUNNING:
            raise ResourceError(
                f"{self.name}: the arm is {mode.name} (power it on and release the brakes at the pendant, "
                "or set power_on = true in [resource.settings])"
            )
        self._open_rtde()

    def _check_controller(self, version: Version, model: str) -> None:
        s = self.settings
        if model != s.model:
            raise ResourceError(
                f"{self.name}: the controller drives a {model}, the config describes a {s.model}"
            )
        least = parse_polyscope_version(s.min_version)
        if (version.major, version.minor) < (least.major, least.minor):
            raise ResourceError(
                f"{self.name}: controller software {version} is older than min_version {s.min_version}"
            )
        if abs(version.period_s - self.period_s) > 1e-9:
            raise ResourceError(
                f"{self.name}: control_period_s = {self.period_s:g} s, but the controller ({version}) "
                f"runs at {1 / version.period_s:g} Hz: set control_period_s = {version.period_s:g}"
            )

    def power_on(self) -> None:
        """Power on, then release the brakes, each confirmed by the controller's robot mode."""
        d = self.dashboard
        d.powerOn()
        self._wait_mode({RobotMode.IDLE, RobotMode.RUNNING}, "power on")
        d.brakeRelease()
        self._wait_mode({RobotMode.RUNNING}, "brake release")

    def power_off(self) -> None:
        self.dashboard.powerOff()

    def _wait_mode(self, modes: set[RobotMode], what: str) -> None:
        end = time.monotonic() + self.settings.connect_timeout_s
        while (mode := self.dashboard_robot_mode()) not in modes:
            if time.monotonic() > end:
                raise ResourceError(f"{self.name}: {what}: the arm stayed {mode.name}")
            time.sleep(0.1)

    def dashboard_robot_mode(self) -> RobotMode:
        reply = str(self.dashboard.robotmode())  # "Robotmode: RUNNING"
        name = reply.split(":")[-1].strip().upper()
        return RobotMode[name] if name in RobotMode.__members__ else RobotMode.DISCONNECTED

    def _open_rtde(self) -> None:
        import rtde_control
        import rtde_receive

        host, hz, prio = self.settings.host, 1.0 / self.period_s, self.settings.rtde_priority
        slow_hz = min(hz, SLOW_RECEIVE_HZ)
        # ur_rtde sets its threads' priority on a PREEMPT_RT kernel only: ours sets it on any
        with ThreadsStartedHere(prio) as started:
            self.receive = self._try(
                lambda: rtde_receive.RTDEReceiveInterface(host, slow_hz, [], False, False, prio),
                f"RTDE at {host}:30004",
            )
            flags = rtde_control.RTDEControlInterface.FLAG_UPLOAD_SCRIPT
            self.control = self._try(
                lambda: rtde_control.RTDEControlInterface(host, hz, flags, 50002, prio), "the control script"
            )
            if self.settings.digital_outputs:
                import rtde_io

                self.io = self._try(lambda: rtde_io.RTDEIOInterface(host), "RTDE's I/O inputs")
        for w in started.warnings:
            log.warning("%s: %s", self.name, w)
        self.watchdog_armed = False
        self._set_tool()

    def _set_tool(self) -> None:
        """The config's payload and TCP, on the controller (each time the script starts: they hold
        for the program that sets them); a refusal is an error naming the value."""
        s, c = self.settings, self.control
        if s.payload_kg is not None:
            cog = list(s.payload_cog_m) if s.payload_cog_m is not None else []
            if not c.setPayload(s.payload_kg, cog):
                raise ResourceError(
                    f"{self.name}: the controller refused payload_kg = {s.payload_kg:g} (centre of "
                    f"gravity {cog or 'its own estimate'}): check it against the arm's rating"
                )
        if s.tcp_m_rad is not None and not c.setTcp(list(s.tcp_m_rad)):
            raise ResourceError(f"{self.name}: the controller refused tcp_m_rad = {list(s.tcp_m_rad)}")

    def _try(self, fn: Any, what: str) -> Any:
        try:
            return fn()
        except RuntimeError as e:
            raise ResourceError(f"{self.name}: cannot reach {what}: {e}") from None

    def close(self) -> None:
        """Every link dropped, ur_rtde's control interface first (left connected to a dead
        controller, it reconnects by itself from its own thread). Dropping the last reference is
        the disconnect: ur_rtde's destructors disconnect (0.5 s each, joining their threads), so
        an explicit disconnect() before would cost it twice. Nothing else holds them:
        the stream is the link process's own (`rtde_stream`)."""
        self.io = None
        self.control = None
        self.receive = None
        self.dashboard = None

    def unlock_protective_stop(self) -> None:
        """The controller allows it 5 s after the stop began; the safety popup closed after."""
        try:
            self.dashboard.unlockProtectiveStop()
        except RuntimeError as e:
            raise ResourceError(f"{self.name}: protective stop: {e}: reset again then") from None
        self.dashboard.closeSafetyPopup()

    def restart_script(self) -> None:
        """The script stopped with the controller's stop: start it again, its watchdog too."""
        self.control.stopScript()  # ur_rtde clears the command registers (no stale servoJ target)
        self.control.reuploadScript()
        self.watchdog_armed = False
        deadline = time.monotonic() + self.settings.connect_timeout_s
        while not self.control.isProgramRunning():  # uploaded, started within a few cycles
            if time.monotonic() > deadline:
                raise ResourceError(f"{self.name}: the control script did not start again")
            time.sleep(self.period_s)
        self._set_tool()

    # ---- the stream (tick-safe) ------------------------------------------------------------
    def script_running(self) -> bool:
        return bool(int(self.receive.getRobotStatus()) & ROBOT_PROGRAM_RUNNING)

    def condition(self) -> Condition | None:
        """What stops the arm now, from the stream's words (None: it may move)."""
        r = self.receive
        return condition(
            int(r.getRobotMode()), int(r.getSafetyMode()), int(r.getRuntimeState()), self.script_running()
        )

    def arm_watchdog(self, watchdog_s: float) -> None:
        """The controller's RTDE watchdog, armed by the first command of a (re)started script, so
        that no startup gap between configure and the loop trips it. From then on the controller
        stops the script, and the arm, when our commands stop coming for `watchdog_s`: this
        process killed or stalled, the link cut (mid-speedJ above all)."""
        if not self.watchdog_armed:
            self.control.setWatchdog(1.0 / watchdog_s)  # one round trip to the script, once
            self.watchdog_armed = True

    def measured(self) -> dict[str, float | int | str]:
        """What the controller measures beyond the joint state (not for a tick): its time, the
        joints' actual currents and the TCP pose (base frame, axis-angle)."""
        r = self.receive
        if r is None:
            return {}
        try:
            return {
                "controller_time_s": float(r.getTimestamp()),
                "actual_current_a": " ".join(f"{i:.3f}" for i in r.getActualCurrent()),
                "tcp_pose_m_rad": " ".join(f"{x:.4f}" for x in r.getActualTCPPose()),
                "payload_kg": float(r.getPayload()),
                "speed_slider": round(float(r.getTargetSpeedFraction()), 3),  # the pendant's slider
            }
        except RuntimeError:
            return {}
