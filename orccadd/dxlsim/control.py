"""The simulator's control channel: a UNIX stream socket speaking the simulators' control protocol
(`orccadd.runtime.sim_control`), "device" being a servo's ID:

    {"inject": "overload", "device": 3}   Hardware Error Status bit 5: torque off, alert bit set
    {"inject": "overheating", "device": 3}
                                          temperature held above Temperature Limit(31): bit 2
    {"inject": "unplug", "device": 3}     no power, no answer (torque off, the arm joint is free)
    {"inject": "replug", "device": 3}     power back: the servo boots (RAM at power-on values)
    {"inject": "noise", "rate": 0.01}     each byte of every status packet gets one bit flipped
                                          at this probability (0: off)
    {"inject": "late", "ms": 6, "packets": 3}
                                          the next 3 status packets each come 6 ms later than
                                          their wire time (a busy host, a USB adapter's hiccup)
    {"inject": "object", "device": 6, "at_rad": 0.3, "stiffness_nm_rad": 20, "closing": 1}
                                          servo 6's joint meets an object at 0.3 rad moving in its
                                          closing sense (+1: growing angles), which pushes back
                                          like a spring (a part between a gripper's fingers)
    {"inject": "remove_object", "device": 6}
    {"inject": "clear"}                   ends noise, held temperatures, unplugs and objects; latched
                                          hardware errors stay until a reboot, as on a servo
    {"status": true}                      the arm and each servo (see `status`)

The socket is made with mode 0600 (only its owner may inject faults). Served from the simulator's loop: a
request is handled between two bus transactions, never during one.
"""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

from orccadd.dxlsim import table as T
from orccadd.dxlsim.chain import Chain
from orccadd.runtime import sim_control
from orccadd.wire.socketdir import bind_with_mode

MAX_LINE = 4096


PID = (T.POSITION_P_GAIN, T.POSITION_I_GAIN, T.POSITION_D_GAIN)


def status(chain: Chain) -> dict[str, Any]:
    servos, devices = [], []
    for s in chain.servos:
        s.loop.refresh(chain.t_s or 0.0)
        torque, error = s.table.get(T.TORQUE_ENABLE), s.table.get(T.HARDWARE_ERROR_STATUS)
        servos.append(
            {
                "id": s.dxl_id,
                "model": s.model.name,
                "plugged": s.plugged,
                "torque_enable": torque,
                "hardware_error_status": error,
                "operating_mode": s.table.get(T.OPERATING_MODE),
                "present_position": s.table.get(T.PRESENT_POSITION),
                "goal_position": s.table.get(T.GOAL_POSITION),
                "position_pid": [
                    s.table.get(g) for g in (T.POSITION_P_GAIN, T.POSITION_I_GAIN, T.POSITION_D_GAIN)
                ],
                "present_temperature": s.table.get(T.PRESENT_TEMPERATURE),
            }
        )
        state = "torque on" if torque else "torque off"
        fault = f"hardware error status 0x{error:02X}" if error else ""
        devices.append(sim_control.device(s.dxl_id, state if s.plugged else "unplugged", fault))
    return {
        "q_rad": [float(x) for x in chain.arm.q],
        "dq_rad_s": [float(x) for x in chain.arm.dq],
        "devices": devices,
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
        bind_with_mode(self.sock, self.path, 0o177)
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
        def inject(req: sim_control.Injection) -> None:
            p = req.params
            allowed = {
                "late": {"ms", "packets"},
                "noise": {"rate"},
                "object": {"at_rad", "stiffness_nm_rad", "closing"},
            }.get(req.fault, set())
            if set(p) - allowed:
                raise ValueError(f"{req.fault}: unknown parameter(s) {sorted(set(p) - allowed)}")
            if req.fault == "late":
                chain.make_late(float(p["ms"]) * 1e-3, int(p.get("packets", 1)))
            elif req.fault == "object":
                chain.advance_to(now_s)
                closing = int(p.get("closing", 1))
                chain.place_object(
                    req.device, float(p["at_rad"]), float(p.get("stiffness_nm_rad", 20.0)), closing
                )
            elif req.fault == "remove_object":
                chain.advance_to(now_s)
                chain.remove_object(req.device)
            else:
                chain.inject(req.fault, req.device, float(p.get("rate", 0.0)), now_s)

        def state() -> dict[str, Any]:
            chain.advance_to(now_s)
            return status(chain)

        return sim_control.answer(line, inject, state)

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
