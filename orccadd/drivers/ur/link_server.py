"""`python -m orccadd.drivers.ur.link_server --fd N`: one UR controller's links (`UrLink`: the
dashboard, the RTDE stream and the control script, through ur_rtde) in a process of their own,
serving the `ur_rtde` resource (`remote_link.RemoteLink`) over the SOCK_SEQPACKET socket N.

Why a process: when a controller drops the connection, ur_rtde 1.6's control interface reconnects
from its receive thread and then runs two receive threads on one connection; in the daemon that
was a segmentation fault within a second (issue 31). Here it ends this process only: the daemon
sees the link gone (CommLost), and `reset` starts a new one.

Messages are pickled tuples (`remote_link` has the protocol). The settings come first, from the
parent; this process answers `("ready", version, model)` or `("failed", words)`, then:

- a stream thread reads the controller's RTDE output stream itself, by a blocking read on its
  socket (`rtde_stream.RtdeStream`: ur_rtde's receive interface has no wait, only getters its
  own thread refreshes every 100 µs), and sends `("state", StreamState)` for every package the
  moment the read returns (the parent's tick is released by its arrival); when the stream breaks
  it sends one that says so, and stops;
- the main thread executes requests in order: `("send", method, args)` (a stream command:
  servoJ, speedJ, directTorque, kickWatchdog; nothing comes back unless the controller refuses it
  or ur_rtde raises: `("refused", method, words)`), `("call", seq, target, method, args)` (a call
  on `link` or `control`, answered `("reply", seq, ok, value or words)`), `("quit",)`.

It ends when the parent closes the socket (the parent's death included).
"""

from __future__ import annotations

import argparse
import os
import pickle
import socket
import sys
import threading
import time
from dataclasses import replace
from typing import Any

from orccadd.drivers.ur.link import UrLink
from orccadd.drivers.ur.remote_link import MAX_MESSAGE
from orccadd.drivers.ur.rtde_stream import RtdeError, RtdeStream, StreamState
from orccadd.errors import OrccaddError
from orccadd.runtime.rt import realtime_device_process

STREAM_METHODS = frozenset({"servoJ", "speedJ", "directTorque", "kickWatchdog", "forceMode"})
CALL_TARGETS = frozenset({"link", "control", "io"})


class LinkServer:
    def __init__(self, sock: socket.socket, link: UrLink) -> None:
        self.sock = sock
        self.link = link
        self.stopping = False

    def send(self, *message: Any) -> None:
        try:
            self.sock.send(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError:  # the parent is gone: the main thread sees it too and ends
            self.stopping = True

    # ---- the stream ------------------------------------------------------------------------
    def stream(self, rtde: RtdeStream) -> None:
        while not self.stopping:
            try:
                state = rtde.read()
            except RtdeError:
                self.send("state", StreamState.lost(time.monotonic_ns()))
                return  # ur_rtde would reconnect by itself: the parent ends this process first
            if not self._connected():
                state = replace(state, connected=False)
            self.send("state", state)
            if not state.connected:
                return

    def _connected(self) -> bool:
        c = self.link.control
        try:
            return bool(c is not None and c.isConnected())
        except RuntimeError:
            return False

    # ---- requests --------------------------------------------------------------------------
    def serve(self) -> None:
        while not self.stopping:
            try:
                data = self.sock.recv(MAX_MESSAGE)
            except OSError:
                return
            if not data:
                return
            request = pickle.loads(data)
            if request[0] == "quit":
                return
            if request[0] == "send":
                self._stream_command(request[1], request[2])
            elif request[0] == "call":
                self._call(*request[1:])

    def _stream_command(self, method: str, args: tuple[Any, ...]) -> None:
        if method not in STREAM_METHODS or self.link.control is None:
            self.send("refused", method, "no control link")
            return
        try:
            ok = getattr(self.link.control, method)(*args)
        except RuntimeError as e:
            self.send("refused", method, str(e) or "ur_rtde raised")
            return
        if ok is False:
            self.send("refused", method, "")

    def _call(self, seq: int, target: str, method: str, args: tuple[Any, ...]) -> None:
        if target not in CALL_TARGETS or method.startswith("_"):
            self.send("reply", seq, False, f"no such call: {target}.{method}")
            return
        try:
            obj = {"link": self.link, "control": self.link.control, "io": self.link.io}[target]
            if obj is None:
                raise AttributeError(f"no {target} interface")
            value = getattr(obj, method)(*args)
        except (OrccaddError, RuntimeError, AttributeError) as e:
            self.send("reply", seq, False, f"{type(e).__name__}: {e}")
            return
        self.send("reply", seq, True, value)


def main() -> int:
    ap = argparse.ArgumentParser(prog="orccadd.drivers.ur.link_server")
    ap.add_argument("--fd", type=int, required=True)
    args = ap.parse_args()
    sock = socket.socket(fileno=args.fd)
    settings, period_s, name = pickle.loads(sock.recv(MAX_MESSAGE))
    # ur_rtde's threads, started from here on, inherit it: the stream is the control loop's clock
    warnings = realtime_device_process(settings.rtde_priority)
    link = UrLink(settings, period_s, name)
    server = LinkServer(sock, link)
    try:
        link.connect()
        rtde = RtdeStream(settings.host, 1.0 / period_s, timeout_s=settings.connect_timeout_s)
    except RtdeError as e:
        server.send("failed", f"{name}: cannot read the RTDE stream: {e}")
        return 1
    except (OrccaddError, RuntimeError) as e:
        server.send("failed", str(e))
        return 1
    server.send("ready", link.version, link.robot_model, warnings)
    threading.Thread(target=server.stream, args=(rtde,), name="ur-stream", daemon=True).start()
    server.serve()
    server.stopping = True
    time.sleep(0.06)  # the stream thread's last wait
    sys.stdout.flush()
    os._exit(0)  # ur_rtde's destructors would join their threads for 0.5 s each: nothing to keep


if __name__ == "__main__":
    raise SystemExit(main())
