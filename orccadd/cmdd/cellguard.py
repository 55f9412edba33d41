"""What the cell's peers may cost a daemon, and words about what was dropped (`cmdd.cellpeer`).

- `SignalIntake`: which of the peers' signals a daemon takes, with the ones below;
- `TokenBucket`: a peer's signals taken at `rate_hz` on average, `burst` at once;
- `InFlight`: requests on one queryable being served at once (beyond: a `busy` reply at once);
- `sequence`: a peer's sequence numbers: duplicate, gap, or the peer counting again;
- `Counts`: drops and deliveries, by peer and reason, for `status`'s `cell` section;
- `LogThrottle`: the first lines of a kind, then one summary per window (how many more);
- `OutputLedger`: the mission's outputs seen two ways (the real-time process's push and its
  trace), so that one emitted and never published is counted and said.

Times are arguments (`now_s`, monotonic seconds) or an injected clock: tests run them on
simulated time. All but the ledger may be called from Zenoh's threads and the event loop (a lock
each); none from a tick.
"""

from __future__ import annotations

import enum
import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from orccadd.config.cellnet import CellNetConfig

SEQ_MAX = (1 << 63) - 1  # a sequence number beyond this is malformed
SIGNAL_MAX = 4096  # bytes of a signal's payload (beyond: dropped before decoding)
UNLISTED = "(unlisted)"  # the counts of peers no role names (without TLS: every peer)


class Payload(Protocol):
    """A sample's payload (`zenoh.ZBytes`): its length known before it is copied."""

    def __len__(self) -> int: ...

    def to_bytes(self) -> bytes: ...


class SignalIntake:
    """Which of the peers' signals a daemon takes, the cheapest checks first and nothing stored
    for one dropped: from a peer with the control role (none without TLS); for an input the
    loaded mission declares from that peer (`mission_changed`); within the peer's
    `signal_rate_hz` and `signal_burst`; at most `SIGNAL_MAX` bytes of JSON `{"seq": N}`; in
    sequence (`sequence`). What is dropped is counted by peer and reason (`counts`) and said
    through `say`. `admit` from Zenoh's threads; the rest from the event loop."""

    def __init__(
        self, net: CellNetConfig, say: LogThrottle, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.net = net
        self.say = say
        self.clock = clock
        self.controllers = frozenset(net.control) if net.secured else frozenset()
        self.listed = self.controllers | frozenset(net.read)
        now = clock()
        self.buckets = {n: TokenBucket(net.signal_rate_hz, net.signal_burst, now) for n in self.controllers}
        self.takes: frozenset[tuple[str, str]] = frozenset()  # (peer, input) the mission declares
        self.last_seq: dict[tuple[str, str], int] = {}  # (peer, input) -> the last number taken
        self.skipped: set[tuple[str, str]] = set()  # dropped over the rate since the last taken
        self.counts = Counts()  # by peer: taken, and why dropped
        self._lock = threading.Lock()  # buckets, last_seq

    def who(self, peer: str) -> str:
        """The name counts are kept under: a listed peer's, else `UNLISTED` (a bounded set)."""
        return peer if peer in self.listed else UNLISTED

    def mission_changed(self, takes: frozenset[tuple[str, str]]) -> None:
        """The (peer, input) pairs the loaded mission declares (`input X from "peer"`)."""
        with self._lock:
            self.takes = takes
            self.last_seq = {k: v for k, v in self.last_seq.items() if k in takes}
            self.skipped &= takes

    def joined(self, peer: str) -> None:
        """A new run of `peer` (its liveliness token came): its numbering starts again."""
        with self._lock:
            self.last_seq = {k: v for k, v in self.last_seq.items() if k[0] != peer}

    def admit(self, peer: str, name: str, payload: Payload, key: str) -> bool:
        """True if the signal `name` from `peer` (on `key`) goes to the mission."""
        if peer not in self.controllers:
            self._drop(peer, "not_control", self._why_not_control(peer))
            return False
        if (peer, name) not in self.takes:
            self.counts.add(peer, "undeclared")  # another daemon's business: counted, not said
            return False
        with self._lock:
            within = self.buckets[peer].take(self.clock())
            if not within:
                self.skipped.add((peer, name))
        if not within:
            net = self.net
            why = (
                f"over its rate ({net.signal_rate_hz:g}/s, {net.signal_burst} at once: [cell] signal_rate_hz)"
            )
            self._drop(peer, "over_rate", why)
            return False
        try:
            seq = signal_seq(payload)
        except ValueError as e:
            self.counts.add(peer, "malformed")
            self.say(
                f"cell: malformed signals from {peer}",
                logging.WARNING,
                "cell: a malformed signal on %s dropped: %s",
                key[:200],
                str(e)[:200],
            )
            return False
        if not self._in_sequence(peer, name, seq):
            return False
        self.counts.add(peer, "taken")
        return True

    def _why_not_control(self, peer: str) -> str:
        if not self.net.secured:
            return "without TLS no signal is taken from the cell"
        if peer in self.listed:
            return "its certificate holds the read role only here (only control peers feed a mission)"
        return "its name is in neither [cell] control nor read"

    def _drop(self, peer: str, reason: str, why: str) -> None:
        who = self.who(peer)
        self.counts.add(who, reason)
        self.say(
            f"cell: signals from {who} dropped ({reason})",
            logging.WARNING,
            "cell: a signal from %s dropped: %s",
            peer[:64],
            why,
        )

    def _in_sequence(self, peer: str, name: str, seq: int) -> bool:
        """`sequence`'s rule: a duplicate dropped, a gap said, a peer counting again taken."""
        with self._lock:
            last = self.last_seq.get((peer, name), 0)
            verdict = sequence(last, seq)
            if verdict is not Seq.DUPLICATE:
                self.last_seq[(peer, name)] = seq
            if verdict is Seq.GAP and (peer, name) in self.skipped:
                verdict = Seq.NEXT  # the ones between were dropped here, over the rate: said so
            self.skipped.discard((peer, name))
        if verdict is Seq.NEXT:
            return True
        self.counts.add(peer, verdict.value)
        words = {
            Seq.DUPLICATE: "sequence %d again (after %d): dropped",
            Seq.GAP: "sequence %d after %d: the ones between missed",
            Seq.RESTART: "sequence %d after %d: it counts again (a new run of it): taken, counting from it",
        }[verdict]
        self.say(
            f"cell: {name} from {peer}: {verdict.value}",
            logging.WARNING,
            f"cell: %s from %s: {words}",
            name,
            peer,
            seq,
            last,
        )
        return verdict is not Seq.DUPLICATE


def signal_seq(payload: Payload) -> int:
    """A signal's sequence number; ValueError if its payload is longer than `SIGNAL_MAX` (not
    copied then) or not JSON `{"seq": N}` with N in [1, 2^63)."""
    if len(payload) > SIGNAL_MAX:
        raise ValueError(f"{len(payload)} bytes, more than {SIGNAL_MAX}")
    try:
        msg = json.loads(payload.to_bytes())
    except RecursionError:
        raise ValueError("nested too deep") from None
    seq = msg.get("seq") if isinstance(msg, dict) else None
    if not isinstance(seq, int) or isinstance(seq, bool) or not 1 <= seq <= SEQ_MAX:
        raise ValueError("no `seq` in [1, 2^63)")
    return seq


class TokenBucket:
    """`take(now_s)` is True while the peer keeps within `rate_hz` on average and `burst` at once."""

    def __init__(self, rate_hz: float, burst: int, now_s: float) -> None:
        self.rate_hz = rate_hz
        self.burst = float(burst)
        self.tokens = float(burst)
        self.t_s = now_s

    def take(self, now_s: float) -> bool:
        self.tokens = min(self.burst, self.tokens + max(0.0, now_s - self.t_s) * self.rate_hz)
        self.t_s = now_s
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


class InFlight:
    """Requests on one queryable being served now: at most `limit`; `refused` counts the rest."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.now = 0
        self.refused = 0
        self.served = 0
        self._lock = threading.Lock()

    def enter(self) -> bool:
        with self._lock:
            if self.now >= self.limit:
                self.refused += 1
                return False
            self.now += 1
            return True

    def leave(self) -> None:
        with self._lock:
            self.now -= 1
            self.served += 1

    def report(self) -> dict[str, int]:
        return {"in_flight": self.now, "max": self.limit, "served": self.served, "busy": self.refused}


class Seq(enum.Enum):
    """What a signal's sequence number says, after the last one taken from that peer."""

    NEXT = "next"  # the first, or the last + 1: taken
    GAP = "gaps"  # ahead of the next: taken, the ones between said missed
    DUPLICATE = "duplicate"  # the last again: dropped
    RESTART = "restarts"  # below the last: the peer counts again (it restarted): taken, from it


def sequence(last: int, seq: int) -> Seq:
    """The rule for a peer's sequence numbers (`last` 0: none taken yet). A number below the last
    is the peer counting again (a new run of it, or one far ahead before): taken, and counting
    goes on from it; so one number far ahead never blocks the later ones."""
    if last == 0 or seq == last + 1:
        return Seq.NEXT
    if seq == last:
        return Seq.DUPLICATE
    return Seq.GAP if seq > last else Seq.RESTART


class Counts:
    """Counters by (who, what): a peer (or a class of peers) and a reason or an outcome."""

    def __init__(self) -> None:
        self._by: dict[str, dict[str, int]] = {}
        self._lock = threading.Lock()

    def add(self, who: str, what: str, n: int = 1) -> int:
        """Add `n`; the new count."""
        with self._lock:
            mine = self._by.setdefault(who, {})
            mine[what] = mine.get(what, 0) + n
            return mine[what]

    def get(self, who: str, what: str) -> int:
        with self._lock:
            return self._by.get(who, {}).get(what, 0)

    def report(self) -> dict[str, dict[str, int]]:
        with self._lock:
            return {who: dict(sorted(c.items())) for who, c in sorted(self._by.items())}


class LogThrottle:
    """Log lines of one kind (`key`): the first `burst` in a window of `window_s`, then none; when
    the window ends (`flush`, or the next line of that kind), one summary: how many more there
    were. At most `keys_max` kinds are kept apart (beyond: one kind, "other")."""

    def __init__(
        self,
        logger: logging.Logger,
        clock: Callable[[], float] = time.monotonic,
        burst: int = 10,
        window_s: float = 10.0,
        keys_max: int = 256,
    ) -> None:
        self.log = logger
        self.clock = clock
        self.burst = burst
        self.window_s = window_s
        self.keys_max = keys_max
        self._kinds: dict[str, list[Any]] = {}  # key -> [window start s, lines, more, level]
        self._lock = threading.Lock()

    def __call__(self, key: str, level: int, msg: str, *args: Any) -> None:
        summary: tuple[int, str, int, float] | None = None
        now_s = self.clock()
        with self._lock:
            if key not in self._kinds and len(self._kinds) >= self.keys_max:
                key = "other"
            kind = self._kinds.setdefault(key, [now_s, 0, 0, level])
            if now_s - kind[0] >= self.window_s:
                if kind[2]:
                    summary = (kind[3], key, kind[2], now_s - kind[0])
                kind[:] = [now_s, 0, 0, level]
            say = kind[1] < self.burst
            if say:
                kind[1] += 1
            else:
                kind[2] += 1
        if summary is not None:
            self._summary(*summary)
        if say:
            self.log.log(level, msg, *args)

    def flush(self) -> None:
        """The summaries of the windows that have ended (call about once a second)."""
        now_s = self.clock()
        due: list[tuple[int, str, int, float]] = []
        with self._lock:
            for key, kind in self._kinds.items():
                if kind[2] and now_s - kind[0] >= self.window_s:
                    due.append((kind[3], key, kind[2], now_s - kind[0]))
                    kind[:] = [now_s, 0, 0, kind[3]]
        for d in due:
            self._summary(*d)

    def _summary(self, level: int, key: str, more: int, span_s: float) -> None:
        self.log.log(level, "%s: %d more like it in the last %.0f s", key, more, span_s)


class OutputLedger:
    """A mission's outputs to the cell, seen two ways on the event loop: `pushed` (the real-time
    process told the command daemon, which publishes it) and `traced` (its trace shows the
    instant that emitted it). A traced one with no push within `grace_s` is lost: `expire` counts
    it. A push with no trace record (the trace ring overran) is forgotten after `grace_s`. At
    most `pending_max` of each wait (beyond: the oldest traced one is counted lost)."""

    def __init__(self, grace_s: float = 5.0, pending_max: int = 10_000) -> None:
        self.grace_s = grace_s
        self.pending_max = pending_max
        self.traced_only: dict[str, deque[float]] = {}
        self.pushed_only: dict[str, deque[float]] = {}
        self.lost = 0
        self._said = 0

    def pushed(self, name: str, now_s: float) -> None:
        self._meet(name, now_s, self.traced_only, self.pushed_only)

    def traced(self, name: str, now_s: float) -> None:
        self._meet(name, now_s, self.pushed_only, self.traced_only)

    def _meet(
        self, name: str, now_s: float, other: dict[str, deque[float]], mine: dict[str, deque[float]]
    ) -> None:
        waiting = other.get(name)
        if waiting:
            waiting.popleft()
            return
        q = mine.setdefault(name, deque())
        if len(q) >= self.pending_max:
            q.popleft()
            if mine is self.traced_only:
                self.lost += 1
        q.append(now_s)

    def expire(self, now_s: float) -> int:
        """Count as lost the traced outputs not pushed within `grace_s`; how many were counted
        lost since the last call."""
        for q in self.traced_only.values():
            self.lost += _drop_older(q, now_s - self.grace_s)
        for q in self.pushed_only.values():
            _drop_older(q, now_s - self.grace_s)
        fresh, self._said = self.lost - self._said, self.lost
        return fresh


def _drop_older(q: deque[float], t_s: float) -> int:
    """Drop the times before `t_s` from the front of `q`; how many."""
    n = 0
    while q and q[0] <= t_s:
        q.popleft()
        n += 1
    return n
