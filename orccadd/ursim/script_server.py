"""The script ports (30001 primary, 30002 secondary, 30003 real-time): URScript in, programs
started.

A `def name():` ... `end` program replaces the running program (a `sec` program runs beside
it); a single line is a program of its own. The only program this simulator executes is
ur_rtde's control script, recognised by its "RTDE Control Script" message and run by
`control_script.ControlScript` (with the register offset ur_rtde injected). `protective_stop()`
sent alone triggers a protective stop. Any other program is logged, replaces the running one
as it would on a controller, and ends at once. These ports do not stream the robot state
packages a real controller sends on them.
"""

from __future__ import annotations

import logging
import re
import socket
from collections.abc import Callable

from orccadd.ursim.control_script import ControlScript, is_control_script, register_offsets
from orccadd.ursim.controller import UrController

log = logging.getLogger("orccadd.ursim")

PROGRAM_START = re.compile(r"^(def|sec)\s+(\w+)\s*\(", re.MULTILINE)
PROGRAM_END = re.compile(r"^end[ \t]*\r?$", re.MULTILINE)
MAX_SCRIPT_BYTES = 4 << 20


class EmptyProgram:
    """A program the simulator does not execute: it ends in its first cycle."""

    def __init__(self, name: str) -> None:
        self.name = name

    def step(self) -> bool:
        return False


def split_programs(buffer: str) -> tuple[list[str], str]:
    """Complete programs and single lines at the start of `buffer`, and what remains."""
    found: list[str] = []
    while True:
        buffer = buffer.lstrip("\r\n")
        if not buffer:
            return found, ""
        start = PROGRAM_START.match(buffer)
        if start is not None:
            end = PROGRAM_END.search(buffer, start.end())
            if end is None:
                return found, buffer
            found.append(buffer[: end.end()])
            buffer = buffer[end.end() :]
            continue
        nl = buffer.find("\n")
        if nl < 0:
            return found, buffer
        found.append(buffer[:nl].strip())
        buffer = buffer[nl + 1 :]


def run_script(ctl: UrController, text: str, port: int) -> None:
    """Start what one program or line asks (under the controller's lock)."""
    m = PROGRAM_START.match(text)
    with ctl.lock:
        if m is None:
            if text.replace(" ", "") == "protective_stop()":
                ctl.protective_stop(f"protective_stop() sent to port {port}")
                return
            log.warning("port %d: script line not simulated, run as an empty program: %.80s", port, text)
            ctl.start_program(EmptyProgram("<line>"), "<line>")
            return
        kind, name = m[1], m[2]
        if kind == "def" and is_control_script(text):
            offset_int, offset_float = register_offsets(text)
            ctl.start_program(ControlScript(ctl, offset_int, offset_float), name)
        elif kind == "sec":
            log.warning("port %d: secondary program %s not simulated (ignored)", port, name)
        else:
            log.warning("port %d: program %s not simulated: it ends at once", port, name)
            ctl.start_program(EmptyProgram(name), name)


def script_handler(ctl: UrController, port: int) -> Callable[[socket.socket], None]:
    """The `net.Server` handler reading scripts from one connection."""

    def handle(conn: socket.socket) -> None:
        pending = ""
        while True:
            data = conn.recv(65536)
            if not data:
                return
            pending += data.decode(errors="replace")
            if len(pending) > MAX_SCRIPT_BYTES:
                log.warning(
                    "port %d: more than %d bytes without a complete program: closing", port, MAX_SCRIPT_BYTES
                )
                return
            programs, pending = split_programs(pending)
            for text in programs:
                run_script(ctl, text, port)

    return handle
