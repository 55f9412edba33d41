"""The simulator's control channel: a UNIX stream socket taking one JSON object per line.

    {"inject": "overload", "id": 3}       Hardware Error Status bit 5: torque off, alert bit set
    {"inject": "overheating", "id": 3}    temperature held above Temperature Limit(31): bit 2
    {"inject": "unplug", "id": 3}         no power, no answer (torque off, the arm joint is free)
    {"inject": "replug", "id": 3}         power back: the servo boots (RAM at power-on values)
    {"inject": "noise", "rate": 0.01}     each byte of every status packet gets one bit flipped
                                          at this probability (0: off)
    {"inject": "late", "ms": 6, "packets": 3}
                                          the next 3 status packets each come 6 ms later than
                                          their wire time (a busy host, a USB adapter's hiccup)
    {"inject": "clear"}                   ends noise, held temperatures and unplugs; latched
                                          hardware errors stay until a reboot, as on a servo
    {"status": true}                      the arm and each servo (see `status`)

Each line gets one line back: `{"ok": true, ...}` or `{"ok": false, "error": "..."}`. The socket
is made with mode 0600 (only its owner may inject faults). Served from the simulator's loop: a
request is handled between two bus transactions, never during one.
"""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path
from typing import Any

from orccadd.dxlsim import table as T
from orccadd.dxlsim.chain import Chain

MAX_LINE = 4096


PID = (T.POSITION_P_GAIN, T.POSITION_I_GAIN, T.POSITION_D_GAIN)


def status(chain: Chain) -> dict[str, Any]:
    servos = []
    for s in chain.servos:
        s.loop.refresh(chain.t_s or 0.0)
        servos.append(
            {
                "id": s.dxl_id,
                "model": s.model.name,
                "plugged": s.plugged,
                "torque_enable": s.table.get(T.TORQUE_ENABLE),
                "hardware_error_status": s.table.get(T.HARDWARE_ERROR_STATUS),
                "operating_mode": s.table.get(T.OPERATING_MODE),
                "present_position": s.table.get(T.PRESENT_POSITION),
                "goal_position": s.table.get(T.GOAL_POSITION),
                "position_pid": [
                    s.table.get(g) for g in (T.POSITION_P_GAIN, T.POSITION_I_GAIN, T.POSITION_D_GAIN)
                ],
                "present_temperature": s.table.get(T.PRESENT_TEMPERATURE),
            }
        )
    return {
        "ok": True,
        "q_rad": [float(x) for x in chain.arm.q],
        "dq_rad_s": [float(x) for x in chain.arm.dq],
        "servos": servos,
        "packets": chain.packets,
        "crc_errors": chain.crc_errors,
        "noise_rate": chain.noise_rate,
    }


class ControlServer:
    """Non-blocking: `fds()` to select on, `serve(readable, chain, now_s)` when some are ready."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_socket():
            raise FileExistsError(f"{self.path} exists and is not a socket: not replaced")
        self.path.unlink(missing_ok=True)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old = os.umask(0o177)
        try:
            self.sock.bind(str(self.path))
        finally:
            os.umask(old)
        self.sock.listen(8)
        self.sock.setblocking(False)
        self.clients: dict[int, tuple[socket.socket, bytearray]] = {}

    def fds(self) -> list[int]:
        return [self.sock.fileno(), *self.clients]

    def serve(self, readable: list[int], chain: Chain, now_s: float) -> None:
        if self.sock.fileno() in readable:
            try:
                conn, _ = self.sock.accept()
                conn.setblocking(False)
                self.clients[conn.fileno()] = (conn, bytearray())
            except BlockingIOError:
                pass
        for fd in [fd for fd in readable if fd in self.clients]:
            conn, buf = self.clients[fd]
            try:
                data = conn.recv(MAX_LINE)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data or len(buf) + len(data) > MAX_LINE:
                self._drop(fd)
                continue
            buf += data
            while b"\n" in buf:
                line, _, rest = bytes(buf).partition(b"\n")
                buf[:] = rest
                self._reply(conn, self._answer(line, chain, now_s))

    @staticmethod
    def _answer(line: bytes, chain: Chain, now_s: float) -> dict[str, Any]:
        try:
            req = json.loads(line)
            if not isinstance(req, dict):
                raise ValueError("a request is a JSON object")
            if req.get("inject") == "late":
                chain.make_late(float(req["ms"]) * 1e-3, int(req.get("packets", 1)))
                return {"ok": True}
            if "inject" in req:
                dxl_id = req.get("id")
                rate = float(req.get("rate", 0.0))
                chain.inject(str(req["inject"]), None if dxl_id is None else int(dxl_id), rate, now_s)
                return {"ok": True}
            if req.get("status"):
                chain.advance_to(now_s)
                return status(chain)
            raise ValueError('unknown request: {"inject": ...} or {"status": true}')
        except (ValueError, TypeError, KeyError) as e:
            return {"ok": False, "error": str(e)}

    @staticmethod
    def _reply(conn: socket.socket, reply: dict[str, Any]) -> None:
        conn.setblocking(True)
        conn.settimeout(1.0)
        try:
            conn.sendall(json.dumps(reply).encode() + b"\n")
        except OSError:
            pass
        finally:
            conn.setblocking(False)

    def _drop(self, fd: int) -> None:
        conn, _ = self.clients.pop(fd)
        conn.close()

    def close(self) -> None:
        for fd in list(self.clients):
            self._drop(fd)
        self.sock.close()
        self.path.unlink(missing_ok=True)
