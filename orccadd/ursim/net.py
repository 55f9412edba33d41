"""TCP servers on 127.0.0.1 with their connections tracked, so faults can drop them all and a
controller restart can close the ports and open them again.

Binding refuses a port another program listens on (SO_REUSEADDR only lets a port in TIME_WAIT
be reused), with a message naming the port and what usually holds it.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import socket
import threading
from collections.abc import Callable

from orccadd.errors import OrccaddError
from orccadd.runtime.threads import ThreadGroup

log = logging.getLogger("orccadd.ursim")

HOSTS = ("127.0.0.1", "localhost")
JOIN_S = 5.0  # how long `close` waits for the accept and connection threads


class PortTakenError(OrccaddError):
    """A port the simulator needs is in use."""


def listen(host: str, port: int) -> socket.socket:
    """A listening socket, or `PortTakenError`/`OrccaddError` saying why not."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        srv.bind((host, port))
    except OSError as e:
        srv.close()
        if e.errno == errno.EADDRINUSE:
            raise PortTakenError(
                f"{host}:{port} is already in use (another UR simulator, URSim or robot software?): "
                "stop it, or give this simulator other ports"
            ) from None
        raise OrccaddError(f"cannot listen on {host}:{port}: {e.strerror}") from None
    srv.listen(16)
    return srv


class Server:
    """Accepts connections on one port and runs `handler(conn)` in a thread per connection."""

    def __init__(self, name: str, host: str, port: int, handler: Callable[[socket.socket], None]) -> None:
        self.name = name
        self.host = host
        self.port = port
        self.handler = handler
        self._srv: socket.socket | None = None
        self._conns: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._threads = ThreadGroup(name)
        self.accepted = 0

    def open(self) -> None:
        """Listen (`PortTakenError` if the port is in use) and accept in a background thread."""
        self._srv = listen(self.host, self.port)
        if self.port == 0:
            self.port = self._srv.getsockname()[1]
        self._threads = ThreadGroup(self.name)  # a new group for each opening (a restart reopens)
        self._threads.start(self._accept, self._srv, name="accept")

    def _accept(self, srv: socket.socket) -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return  # closed
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._conns.add(conn)
                self.accepted += 1
            self._threads.start(self._serve, conn, name="connection")

    def _serve(self, conn: socket.socket) -> None:
        try:
            self.handler(conn)
        except OSError:
            pass
        except Exception:
            log.exception("%s: connection handler failed", self.name)
        finally:
            with self._lock:
                self._conns.discard(conn)
            with contextlib.suppress(OSError):
                conn.close()

    @property
    def connections(self) -> int:
        with self._lock:
            return len(self._conns)

    def drop_connections(self) -> int:
        """Close every open connection (the port stays open); how many there were."""
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
        return len(conns)

    def close(self) -> None:
        """Stop listening, drop every connection, and wait for their threads to end."""
        if self._srv is not None:
            with contextlib.suppress(OSError):
                self._srv.shutdown(socket.SHUT_RDWR)
            self._srv.close()
            self._srv = None
        self.drop_connections()
        self._threads.join(JOIN_S)
