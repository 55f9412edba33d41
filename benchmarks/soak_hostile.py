"""The soak's hostile clients (issue 34): what an attacker with a local account and a careless
operator do to the daemon, while the operator's missions run.

- `SlotHolders`: every place of the urgent socket held by peers that trickle a byte now and then
  (and reconnect when closed), every free control place of the main socket held by idle
  connections; meanwhile `orccadctl abort` (a process of its own, as an operator types it) must
  be applied, exit 0, and the run end `aborted`.
- `HostileLogs`: a log asked for 12,000 × `q` and the rest (a signal named twice is logged once),
  `status` timed on a fresh connection all through; the daemon's log directory a small tmpfs
  (root: `--small-log-dir-kb`) that the log fills: the log must end saying so, every file left
  readable (CSV rows whole, MCAP read to the end by mcap's own reader), nothing left beside them;
  the files are then removed for the next one.

Losses counted (the soak fails on any): an abort not applied or not reported, `status` slower
than `STATUS_LIMIT_S` or unanswered, a log that did not end, a file left unreadable.
"""

from __future__ import annotations

import contextlib
import csv
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from orccadd.ctl.client import Client, ClientError
from orccadd.wire.socketdir import urgent_socket_path

URGENT_PLACES = 8  # orccadd.daemon.urgent.CLIENTS_MAX
TRICKLE_S = 0.3
STATUS_LIMIT_S = 2.0
HUGE_LOG = ["q"] * 12_000 + ["dq", "tau", "cmd", "wake_us", "compute_us"]
LOG_HOLD_S = 10.0


class SlotHolders:
    """Peers holding every place they can (a context manager); see the module."""

    def __init__(self, sock: str, free_control_places: int, opened: Callable[[int], None]) -> None:
        self.sock = sock
        self.opened = opened  # told of each main-socket connection held (+1) and let go (-1)
        self.stop = threading.Event()
        self.urgent: list[socket.socket] = []
        self.main: list[socket.socket] = []
        self.lock = threading.Lock()
        for _ in range(URGENT_PLACES):
            self._hold_urgent()
        for _ in range(max(0, free_control_places)):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(sock)
            self.main.append(s)
            opened(1)
        self.thread = threading.Thread(target=self._trickle, daemon=True)
        self.thread.start()

    def _hold_urgent(self) -> None:
        with contextlib.suppress(OSError):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(urgent_socket_path(self.sock))
            with self.lock:
                self.urgent.append(s)

    def _trickle(self) -> None:
        while not self.stop.wait(TRICKLE_S):
            with self.lock:
                held = list(self.urgent)
            for s in held:
                try:
                    s.sendall(b" ")
                except OSError:  # closed to make way, or for a line too slow: hold again
                    with self.lock:
                        self.urgent.remove(s)
                    s.close()
                    self._hold_urgent()

    def __enter__(self) -> SlotHolders:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        for s in [*self.urgent, *self.main]:
            s.close()
        self.opened(-len(self.main))


def abort_through_holders(
    sock: str, free_control_places: int, opened: Callable[[int], None]
) -> tuple[int, str, float]:
    """`orccadctl abort` while every place is held: (exit code, stderr, seconds it took).
    `opened` is told of the connections held (the soak counts its own clients)."""
    with SlotHolders(sock, free_control_places, opened):
        time.sleep(0.5)  # the command daemon has taken the idle connections in
        env = {**os.environ, "ORCCADD_SOCKET": sock}
        t0 = time.monotonic()
        p = subprocess.run(
            [sys.executable, "-m", "orccadd.cli", "abort"],
            capture_output=True,
            text=True,
            env=env,
            timeout=30,
        )
        return p.returncode, p.stderr.strip(), time.monotonic() - t0


def timed_status(sock: str, opened: Callable[[int], None]) -> float:
    """Seconds for a `status` on a new connection (inf: no answer within 10 s)."""
    t0 = time.monotonic()
    opened(1)
    try:
        with Client(sock, timeout_s=10.0) as c:
            c.call("status")
    except (ClientError, OSError):
        return float("inf")
    finally:
        opened(-1)
    return time.monotonic() - t0


def huge_log(sock: str, stop: threading.Event, opened: Callable[[int], None]) -> dict[str, Any]:
    """A log of `HUGE_LOG` for `LOG_HOLD_S` (or until it ends by itself: a full log directory),
    `status` timed all through. {"slowest_status_s", "ended", "error", "files"}."""
    opened(1)
    try:
        return _huge_log(sock, stop, opened)
    finally:
        opened(-1)


def _huge_log(sock: str, stop: threading.Event, opened: Callable[[int], None]) -> dict[str, Any]:
    slowest = 0.0
    with Client(sock, timeout_s=10.0) as c:
        r = c.reply("log", action="start", signals=HUGE_LOG)
        if not r.get("ok"):
            return {"slowest_status_s": 0.0, "ended": False, "error": f"log start refused: {r.get('error')}"}
        files = [r["result"]["file"], *r["result"].get("mcap", [])]
        end = time.monotonic() + LOG_HOLD_S
        ended_by_itself: dict[str, Any] | None = None
        while time.monotonic() < end and not stop.is_set():
            slowest = max(slowest, timed_status(sock, opened))
            s = c.call("status")
            if s.get("log") and "error" in s["log"]:
                ended_by_itself = s["log"]
                break
            time.sleep(0.5)
        if ended_by_itself is None:
            t0 = time.monotonic()
            r = c.reply("log", action="stop")
            slowest = max(slowest, time.monotonic() - t0)
            ok = bool(r.get("ok"))
            return {
                "slowest_status_s": slowest,
                "ended": ok,
                "error": "" if ok else str(r.get("error")),
                "files": files,
            }
        return {
            "slowest_status_s": slowest,
            "ended": True,
            "error": str(ended_by_itself["error"]),
            "files": files,
        }


def unreadable_log_files(log_dir: Path) -> list[str]:
    """What a reader cannot take in the log directory: a CSV row of the wrong width or a cut
    last line, an MCAP mcap's reader refuses, a state file's temporary left behind."""
    bad = []
    for p in sorted(log_dir.iterdir()):
        if p.name.startswith(".active-log.json."):
            bad.append(f"{p.name}: a state file's temporary left behind")
        elif p.suffix == ".csv":
            text = p.read_text()
            rows = [r for r in csv.reader(x for x in text.splitlines() if not x.startswith("#"))]
            if text and not text.endswith("\n"):
                bad.append(f"{p.name}: its last line is cut")
            elif rows and any(len(r) != len(rows[0]) for r in rows):
                bad.append(f"{p.name}: a row of another width than its header")
        elif p.suffix == ".mcap":
            try:
                with p.open("rb") as f:
                    for _ in make_reader(f).iter_messages():
                        pass
            except Exception as e:  # the reader's own exceptions say what is broken
                bad.append(f"{p.name}: {type(e).__name__}: {e}")
    return bad


def empty(log_dir: Path) -> None:
    """Room for the next log (root, the daemon's own directory)."""
    for p in log_dir.iterdir():
        if p.suffix in (".csv", ".mcap") or p.name.startswith(".active-log.json."):
            with contextlib.suppress(OSError):
                p.unlink()


class SmallLogDir:
    """A tmpfs of `kb` KiB for the daemon's logs (root; `path` None if it cannot be mounted)."""

    def __init__(self, kb: int) -> None:
        self.path: Path | None = None
        if kb <= 0 or os.geteuid() != 0:
            return
        mount = Path(os.path.realpath(os.environ.get("TMPDIR", "/tmp"))) / f"orccadd-soak-logs-{os.getpid()}"
        mount.mkdir(mode=0o750, exist_ok=True)
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={kb}k,mode=0750", "tmpfs", str(mount)], capture_output=True
        )
        if r.returncode == 0:
            self.path = mount
        else:
            mount.rmdir()

    def close(self) -> None:
        if self.path is not None:
            subprocess.run(["umount", "-l", str(self.path)], check=False)
            with contextlib.suppress(OSError):
                self.path.rmdir()
