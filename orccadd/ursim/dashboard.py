"""The dashboard server on port 29999: one command a line, one answer a line.

On connection it greets with "Connected: Universal Robots Dashboard Server". Commands and their
answers are UR's (Dashboard Server e-Series / CB-Series guides; the expected answers in UR's
client library, `dashboard_client_implementation_g5.cpp`, and ur_rtde's `dashboard_client.cpp`).
The table below is the one declaration of each command: its words, its argument, its answer.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable
from dataclasses import dataclass

from orccadd.ursim.controller import UrController
from orccadd.ursim.states import PowerEvent, RuntimeState

log = logging.getLogger("orccadd.ursim")

GREETING = "Connected: Universal Robots Dashboard Server"
SERIAL_NUMBER = "20215300001"
ROBOT_MODEL = "UR5"


@dataclass
class Session:
    """One dashboard client: what it set for itself."""

    user_role: str = "NONE"
    operational_mode: str = "NONE"
    quit: bool = False


Handler = Callable[[UrController, Session, str], str]


def _program_state(ctl: UrController) -> str:
    state = (
        ctl.runtime_state.name
        if ctl.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSED)
        else "STOPPED"
    )
    return f"{state} {ctl.program_name or '<unnamed>'}"


def _power_on(ctl: UrController, s: Session, arg: str) -> str:
    ctl.power_event(PowerEvent.POWER_ON)
    return "Powering on"


def _brake_release(ctl: UrController, s: Session, arg: str) -> str:
    ctl.power_event(PowerEvent.BRAKE_RELEASE)
    return "Brake releasing"


def _power_off(ctl: UrController, s: Session, arg: str) -> str:
    ctl.power_event(PowerEvent.POWER_OFF)
    return "Powering off"


def _unlock(ctl: UrController, s: Session, arg: str) -> str:
    return ctl.unlock_protective_stop() or "Protective stop releasing"


def _play(ctl: UrController, s: Session, arg: str) -> str:
    return "Starting program" if ctl.resume_program() else "Failed to execute: play"


def _stop(ctl: UrController, s: Session, arg: str) -> str:
    ctl.stop_program("dashboard stop")
    return "Stopped"


def _pause(ctl: UrController, s: Session, arg: str) -> str:
    if ctl.runtime_state is not RuntimeState.PLAYING:
        return "Failed to execute: pause"
    ctl.pause_program("dashboard pause")
    return "Pausing program"


def _running(ctl: UrController, s: Session, arg: str) -> str:
    return f"Program running: {str(ctl.runtime_state is RuntimeState.PLAYING).lower()}"


def _loaded(ctl: UrController, s: Session, arg: str) -> str:
    return f"Loaded program: {ctl.program_name}" if ctl.program_name else "No program loaded"


def _restart_safety(ctl: UrController, s: Session, arg: str) -> str:
    ctl.restart_safety()
    return "Restarting safety"


def _set_role(ctl: UrController, s: Session, arg: str) -> str:
    role = arg.strip().upper()
    if role not in ("PROGRAMMER", "OPERATOR", "NONE", "LOCKED", "RESTRICTED"):
        return f"Failed setting user role: {arg}"
    s.user_role = role
    return f"Setting user role: {arg.strip()}"


def _set_operational_mode(ctl: UrController, s: Session, arg: str) -> str:
    mode = arg.strip().upper()
    if mode not in ("MANUAL", "AUTOMATIC"):
        return f"Failed to execute: set operational mode {arg}"
    s.operational_mode = mode
    return f"Operational mode '{mode.lower()}' is set"


def _clear_operational_mode(ctl: UrController, s: Session, arg: str) -> str:
    s.operational_mode = "NONE"
    return "No longer controlling the operational mode. Current operational mode: 'NONE'."


def _quit(ctl: UrController, s: Session, arg: str) -> str:
    s.quit = True
    return "Disconnected"


def _const(text: str) -> Handler:
    return lambda ctl, s, arg: text


# (command words, takes an argument, handler); matched case-insensitively, longest first
COMMANDS: list[tuple[str, bool, Handler]] = [
    ("power on", False, _power_on),
    ("power off", False, _power_off),
    ("brake release", False, _brake_release),
    ("unlock protective stop", False, _unlock),
    ("close safety popup", False, _const("closing safety popup")),
    ("close popup", False, _const("closing popup")),
    ("popup", True, _const("showing popup")),
    ("robotmode", False, lambda ctl, s, a: f"Robotmode: {ctl.robot_mode.name}"),
    ("safetymode", False, lambda ctl, s, a: f"Safetymode: {ctl.safety_mode.name}"),
    ("safetystatus", False, lambda ctl, s, a: f"Safetystatus: {ctl.safety_mode.name}"),
    ("programstate", False, lambda ctl, s, a: _program_state(ctl)),
    ("running", False, _running),
    ("play", False, _play),
    ("stop", False, _stop),
    ("pause", False, _pause),
    ("load installation", True, lambda ctl, s, a: f"Failed to load installation: {a}"),
    ("load", True, lambda ctl, s, a: f"File not found: {a}"),
    ("get loaded program", False, _loaded),
    ("isprogramsaved", False, lambda ctl, s, a: f"true {ctl.program_name or '<unnamed>'}"),
    ("polyscopeversion", False, lambda ctl, s, a: ctl.series.polyscope),
    ("version", False, lambda ctl, s, a: ctl.series.version_text),
    ("get serial number", False, _const(SERIAL_NUMBER)),
    ("get robot model", False, _const(ROBOT_MODEL)),
    ("is in remote control", False, _const("true")),
    ("addtolog", True, _const("Added log message")),
    ("setuserrole", True, _set_role),
    ("getuserrole", False, lambda ctl, s, a: s.user_role),
    ("get operational mode", False, lambda ctl, s, a: s.operational_mode),
    ("set operational mode", True, _set_operational_mode),
    ("clear operational mode", False, _clear_operational_mode),
    ("restart safety", False, _restart_safety),
    ("savelog", False, _const("Log saved to disk")),
    ("quit", False, _quit),
    ("shutdown", False, _const("Shutting down")),
]
COMMANDS.sort(key=lambda c: -len(c[0]))


def answer(ctl: UrController, session: Session, line: str) -> str:
    """The answer to one command line (under the controller's lock)."""
    text = " ".join(line.split())
    low = text.lower()
    for words, takes_arg, handler in COMMANDS:
        if low == words or (takes_arg and low.startswith(words + " ")):
            with ctl.lock:
                return handler(ctl, session, text[len(words) :].strip())
    return f"could not understand: '{text}'"


def dashboard_handler(ctl: UrController, on_shutdown: Callable[[], None]) -> Callable[[socket.socket], None]:
    """The `net.Server` handler serving one dashboard connection."""

    def handle(conn: socket.socket) -> None:
        session = Session()
        conn.sendall((GREETING + "\n").encode())
        with conn.makefile("rb") as f:
            for raw in f:
                line = raw.decode(errors="replace").strip()
                if not line:
                    continue
                reply = answer(ctl, session, line)
                log.debug("dashboard: %r -> %r", line, reply)
                conn.sendall((reply + "\n").encode())
                if session.quit:
                    return
                if line.lower() == "shutdown":
                    on_shutdown()
                    return

    return handle
