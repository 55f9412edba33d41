"""The console's side of a cell: which daemons are there, their status, a command to one of them,
their events merged. `orccadctl cell …` and `orccadctl --robot NAME …` use it.

A console is a Zenoh peer with its own certificate (its `[cell]` table, in a file of its own or
in a robot config); what it may do on each daemon is that daemon's say (its access control).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import queue
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from orccadd.cellnet import keys
from orccadd.cellnet.zconfig import to_json5, zenoh_config
from orccadd.config.cellnet import CellNetConfig, load_cellnet
from orccadd.config.robot import read_toml
from orccadd.errors import ConfigError
from orccadd.wire.commands import COMMANDS, Role, client_wait_s
from orccadd.wire.schema import PROTOCOL_VERSION

if TYPE_CHECKING:
    import zenoh

DISCOVER_S = 3.0  # a console's first look at the cell: at most this long for its peers
SETTLE_S = 0.5  # ... and done once no new peer came for this long (gossip under load is slow)


class CellError(Exception):
    """The cell cannot be reached or a daemon does not answer: the words say which and why."""


def read_console_config(path: str) -> CellNetConfig:
    """The `[cell]` table of `path` (a console's file, or a robot config with one). With TLS, a
    console names the daemons it takes answers from (`daemons`): without them it could not tell
    a daemon's reply from another certificate's."""
    raw = read_toml(Path(path))
    if "cell" not in raw:
        raise ConfigError(
            path, "cell", "is missing: a console needs a [cell] table (name, connect, TLS files)"
        )
    net = load_cellnet(raw["cell"], path, "console")
    if net.secured and not net.daemons:
        raise ConfigError(
            path,
            "cell.daemons",
            "is missing: a console takes answers only from the daemons it names, each by its "
            'certificate\'s common name (e.g. daemons = ["arm-a", "arm-b"])',
        )
    return net


class CellConsole:
    def __init__(self, net: CellNetConfig) -> None:
        try:
            import zenoh
        except ImportError:
            raise CellError("the cell needs Zenoh: pip install 'orccadd[cell]'") from None
        self.net = net
        self._zenoh = zenoh
        conf = zenoh.Config.from_json5(to_json5(zenoh_config(net, daemon=False)))
        try:
            self.session: zenoh.Session = zenoh.open(conf)
        except zenoh.ZError as e:
            raise CellError(f"cell {net.name}: cannot open a Zenoh session: {e}") from None
        self.next_id = 0
        self._ids = itertools.count(1)  # one per request, from any thread (`status_all`'s)
        self._settle()

    def _settle(self) -> None:
        """Wait until the peers this console reaches stop growing (the ones it connects to,
        then those they tell it of), for `SETTLE_S` without a new one, at most `DISCOVER_S`."""
        t_end = time.monotonic() + DISCOVER_S
        seen, since = -1, time.monotonic()
        while time.monotonic() < t_end:
            n = len(list(self.session.info.peers_zid()))
            if n != seen:
                seen, since = n, time.monotonic()
            elif n and time.monotonic() - since >= SETTLE_S:
                return
            time.sleep(0.02)

    def __enter__(self) -> CellConsole:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.session.close()  # type: ignore[no-untyped-call]

    def robots(self, wait_s: float = 1.0) -> list[str]:
        """The daemons whose liveliness token is there, sorted (each peer answers at once;
        `wait_s` bounds the wait for one that does not). With TLS, only this console's
        `daemons`, each token from its own certificate (the access control)."""
        found: set[str] = set()
        for r in self.session.liveliness().get(keys.every_robot(self.net.name, keys.ALIVE), timeout=wait_s):
            if r.ok is not None:
                with contextlib.suppress(ValueError):
                    found.add(keys.robot_of(self.net.name, str(r.ok.key_expr)))
        return sorted(found)

    def request(self, robot: str, cmd: str, timeout_s: float | None = None, **args: Any) -> dict[str, Any]:
        """One request to `robot`, on its `control` key if the command needs that role, else on
        its `read` key: its reply as the socket gives it, or an error reply saying why none came.

        Only `robot`'s own certificate can answer (the console's access control drops any other
        peer's reply); a reply to another request, or under another key, is not taken either. A
        command that changes what the robot does and gets no such reply is not confirmed: the
        error says so, and the robot must be taken as still doing what it did."""
        if robot not in self.net.daemons and self.net.secured:
            raise CellError(
                f"{robot!r} is not one of this console's daemons ({', '.join(self.net.daemons)}): "
                f"add it to [cell] daemons in {self.net.source} to take its answers"
            )
        spec = COMMANDS.get(cmd)
        chunk = keys.CONTROL if spec is not None and spec.role is Role.CONTROL else keys.READ
        if chunk == keys.CONTROL and not self.net.secured:
            raise CellError(
                f"{cmd!r} to {robot}: this console has no TLS (ca, certificate, private_key in "
                f"{self.net.source}), so no reply could be told from another peer's and no daemon "
                "takes a command from it; `make setup` makes the shipped cell's certificates"
            )
        rid = self.next_id = next(self._ids)
        line = json.dumps({"id": rid, "cmd": cmd, "args": args, "protocol": PROTOCOL_VERSION})
        key = keys.robot_key(self.net.name, robot, chunk)
        wait = timeout_s if timeout_s is not None else client_wait_s(cmd)
        for r in self.session.get(key, payload=line, timeout=wait):
            if r.ok is None or str(r.ok.key_expr) != key:
                continue
            try:
                reply = json.loads(r.ok.payload.to_bytes())
            except ValueError:
                return {"id": rid, "ok": False, "error": f"{robot}: an unreadable reply"}
            if isinstance(reply, dict) and reply.get("id") == rid:
                return reply
        why = self._why_silent(robot, cmd, chunk)
        if chunk == keys.CONTROL:
            why = f"{cmd} NOT confirmed by {robot}: {why}"
        return {"id": rid, "ok": False, "error": why}

    def _why_silent(self, robot: str, cmd: str, chunk: str) -> str:
        if not self.reaches_anyone():
            return self.why_alone()
        online = self.robots(wait_s=0.3)
        if robot not in online:
            there = ", ".join(online) or "none"
            return f"{robot!r} is not in cell {self.net.name!r} (online: {there})"
        if chunk == keys.CONTROL:
            return (
                f"not authorised: {robot} did not take {cmd!r} from this console "
                f"({self.net.robot!r}): its certificate holds no control role there, or the cell is read-only"
            )
        return f"{robot} did not answer {cmd!r}: not authorised (its certificate holds no role there) or busy"

    def reaches_anyone(self) -> bool:
        return bool(list(self.session.info.peers_zid()))

    def why_alone(self) -> str:
        """Why this console reaches no peer at all: the words a newcomer needs."""
        where = ", ".join(self.net.connect) or "none (connect = [])"
        tls = (
            "with TLS (its certificate from the cell's authority)"
            if self.net.secured
            else "without TLS: a daemon with TLS takes no plain tcp/ peer"
        )
        return (
            f"this console reaches no peer of cell {self.net.name!r} at {where}, {tls}: is a daemon "
            "running there, with the same protocol (tls/ or tcp/) and authority? (`make setup` makes "
            "the shipped cell's certificates)"
        )

    def status_all(self) -> dict[str, dict[str, Any]]:
        """Every daemon's `status` reply, by name, asked all at once."""
        out: dict[str, dict[str, Any]] = {}
        robots = self.robots()
        threads = [
            threading.Thread(target=lambda r=r: out.__setitem__(r, self.request(r, "status"))) for r in robots
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        return {r: out[r] for r in robots}

    def follow(self, chunk: str = keys.EVENTS) -> Iterator[tuple[str, Any]]:
        """(robot, message) for each sample every daemon publishes under `chunk`, and
        (robot, {"cell": "joined" | "lost"}) as their liveliness tokens come and go; an unreadable
        sample is skipped. Ends when the caller stops iterating."""
        q: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=10_000)
        name = self.net.name
        zenoh = self._zenoh

        def on_sample(s: Any) -> None:  # a zenoh.Sample, on Zenoh's thread
            try:
                robot = keys.robot_of(name, str(s.key_expr))
                if s.kind == zenoh.SampleKind.DELETE:
                    msg: Any = {"cell": "lost"}
                elif chunk == keys.ALIVE:
                    msg = {"cell": "joined"}
                else:
                    msg = json.loads(s.payload.to_bytes())
            except ValueError:
                return
            with contextlib.suppress(queue.Full):
                q.put_nowait((robot, msg))

        subs = [self.session.liveliness().declare_subscriber(keys.every_robot(name, keys.ALIVE), on_sample)]
        if chunk != keys.ALIVE:
            subs.append(self.session.declare_subscriber(keys.every_robot(name, chunk), on_sample))
        try:
            while True:
                try:
                    yield q.get(timeout=0.1)
                except queue.Empty:
                    yield "", None
        finally:
            for sub in subs:
                with contextlib.suppress(Exception):
                    sub.undeclare()  # type: ignore[no-untyped-call]
