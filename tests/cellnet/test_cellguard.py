"""What a cell's peers may cost a daemon, without Zenoh and on simulated time (`cmdd.cellguard`):
the signal intake (role, declared inputs, rate, size, sequence), the log throttle, the outputs'
ledger, the bound on requests in flight, a `CellPeer`'s signal callback fed directly; and the
daemon's Zenoh config (a read-only peer puts nothing; a message's size bounded)."""

from __future__ import annotations

import logging
import re

import pytest

from orccadd.cellnet.zconfig import DAEMON_RX_MESSAGE_MAX, access_control, zenoh_config
from orccadd.cmdd.cellguard import (
    SIGNAL_MAX,
    UNLISTED,
    InFlight,
    LogThrottle,
    OutputLedger,
    Seq,
    SignalIntake,
    TokenBucket,
    sequence,
)
from orccadd.cmdd.cellpeer import CellPeer
from orccadd.config.cellnet import CellNetConfig, load_cellnet
from orccadd.errors import ConfigError


class Clock:
    """Simulated monotonic time: moves only when told."""

    def __init__(self) -> None:
        self.t_s = 1000.0

    def __call__(self) -> float:
        return self.t_s


class Payload:
    """A sample's payload; `to_bytes` counts its copies."""

    def __init__(self, raw: bytes, size: int | None = None) -> None:
        self.raw = raw
        self.size = len(raw) if size is None else size
        self.copies = 0

    def __len__(self) -> int:
        return self.size

    def to_bytes(self) -> bytes:
        self.copies += 1
        return self.raw


def seq(n: int) -> Payload:
    return Payload(b'{"seq": %d, "wall_s": 0, "mission": "M"}' % n)


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@pytest.fixture
def lines() -> Lines:
    return Lines()


def throttle(lines: Lines, clock: Clock) -> LogThrottle:
    logger = logging.getLogger(f"test.cellguard.{id(lines)}")
    logger.propagate = False
    logger.addHandler(lines)
    logger.setLevel(logging.DEBUG)
    return LogThrottle(logger, clock)


def net(secured: bool = True, rate_hz: float = 200.0, burst: int = 50) -> CellNetConfig:
    roles = {"control": ("console", "arm-b"), "read": ("viewer",)} if secured else {}
    return CellNetConfig(
        name="test",
        robot="arm-a",
        ca="ca.pem" if secured else "",
        signal_rate_hz=rate_hz,
        signal_burst=burst,
        **roles,  # type: ignore[arg-type]
    )


def intake(lines: Lines, clock: Clock, **kw: object) -> SignalIntake:
    i = SignalIntake(net(**kw), throttle(lines, clock), clock)  # type: ignore[arg-type]
    i.mission_changed(frozenset({("console", "Ping"), ("viewer", "Ping"), ("arm-b", "Part")}))
    return i


def test_a_read_peer_feeds_no_mission(lines: Lines) -> None:
    clock = Clock()
    i = intake(lines, clock)
    assert not any(i.admit("viewer", "Ping", seq(k), "orccadd/test/viewer/signal/Ping") for k in range(1, 6))
    assert i.counts.get("viewer", "not_control") == 5 and i.counts.get("viewer", "taken") == 0
    assert "read role only" in lines.lines[0]
    assert i.admit("console", "Ping", seq(1), "k")  # a control peer's is taken


def test_without_tls_no_signal_is_taken(lines: Lines) -> None:
    i = intake(lines, Clock(), secured=False)
    assert not i.admit("arm-b", "Part", seq(1), "k")
    assert i.counts.get(UNLISTED, "not_control") == 1
    assert "without TLS" in lines.lines[0]


def test_undeclared_names_store_nothing(lines: Lines) -> None:
    i = intake(lines, Clock())
    p = seq(1)
    for k in range(100_000):
        assert not i.admit("console", f"N{k}", p, "k")
    assert i.last_seq == {} and i.skipped == set()
    assert i.counts.report() == {"console": {"undeclared": 100_000}}
    assert p.copies == 0 and lines.lines == []  # not decoded, not said (another daemon's business)


def test_unlisted_peers_are_counted_under_one_name(lines: Lines) -> None:
    i = intake(lines, Clock())
    for k in range(1000):
        i.admit(f"stranger{k}", "Ping", seq(1), "k")
    assert i.counts.report() == {UNLISTED: {"not_control": 1000}}


def test_a_flood_beyond_the_rate_is_dropped_counted_and_said_in_few_lines(lines: Lines) -> None:
    clock = Clock()
    i = intake(lines, clock, rate_hz=200.0, burst=50)
    taken = 0
    for k in range(1, 20_001):  # 20,000 signals in 2 s of simulated time: 10,000/s
        clock.t_s += 1e-4
        taken += i.admit("console", "Ping", seq(k), "k")
    assert taken == pytest.approx(50 + 200 * 2.0, abs=2)
    assert i.counts.get("console", "over_rate") == 20_000 - taken
    assert i.counts.get("console", "gaps") == 0  # the ones between were dropped here, and said so
    clock.t_s += 10.0
    i.say.flush()
    assert len(lines.lines) <= 11, lines.lines
    assert lines.lines[-1].endswith(f"{20_000 - taken - 10} more like it in the last 12 s")
    assert "signal_rate_hz" in lines.lines[0]


def test_each_peer_has_its_own_rate(lines: Lines) -> None:
    clock = Clock()
    i = intake(lines, clock, rate_hz=10.0, burst=5)
    assert sum(i.admit("console", "Ping", seq(k), "k") for k in range(1, 101)) == 5
    assert sum(i.admit("arm-b", "Part", seq(k), "k") for k in range(1, 101)) == 5
    clock.t_s += 1.0
    assert sum(i.admit("console", "Ping", seq(k), "k") for k in range(101, 201)) == 5  # 10/s, burst 5


def test_a_payload_above_the_limit_is_dropped_before_it_is_copied(lines: Lines) -> None:
    i = intake(lines, Clock())
    big = Payload(b"", size=200 << 20)
    assert not i.admit("console", "Ping", big, "orccadd/test/console/signal/Ping")
    assert big.copies == 0
    assert i.counts.get("console", "malformed") == 1 and i.last_seq == {}
    assert f"more than {SIGNAL_MAX}" in lines.lines[0]


@pytest.mark.parametrize(
    "raw", [b"", b"\xff\xfe\x00", b"{", b"[1]", b'{"seq": "1"}', b'{"seq": 0}', b'{"seq": true}',
            b'{"seq": 1e400}', b"[" * 4000, b'{"seq": %d}' % (1 << 63)],
)  # fmt: skip
def test_malformed_signals_are_dropped_and_store_nothing(lines: Lines, raw: bytes) -> None:
    i = intake(lines, Clock())
    assert not i.admit("console", "Ping", Payload(raw), "k")
    assert i.counts.get("console", "malformed") == 1 and i.last_seq == {}


def test_a_huge_sequence_number_does_not_block_the_later_ones(lines: Lines) -> None:
    i = intake(lines, Clock())
    taken = [i.admit("console", "Ping", seq(n), "k") for n in (10**15, 1, 2, 2, 3)]
    assert taken == [True, True, True, False, True]  # the peer counts again; a duplicate dropped
    assert i.counts.get("console", "restarts") == 1 and i.counts.get("console", "duplicate") == 1
    assert any("counts again" in line for line in lines.lines)


def test_a_restarted_peer_is_taken_again(lines: Lines) -> None:
    i = intake(lines, Clock())
    assert all(i.admit("console", "Ping", seq(n), "k") for n in (1, 2, 3))
    i.joined("console")  # its new liveliness token: a new run of it
    assert i.last_seq == {}
    assert i.admit("console", "Ping", seq(1), "k")
    assert i.counts.get("console", "restarts") == 0


def test_sequence_rule() -> None:
    assert sequence(0, 7) is Seq.NEXT  # the first from a peer: whatever its number
    assert sequence(7, 8) is Seq.NEXT
    assert sequence(7, 7) is Seq.DUPLICATE
    assert sequence(7, 9) is Seq.GAP
    assert sequence(7, 1) is Seq.RESTART
    assert sequence(10**15, 1) is Seq.RESTART


def test_a_new_mission_keeps_state_only_for_its_inputs(lines: Lines) -> None:
    i = intake(lines, Clock())
    i.admit("console", "Ping", seq(1), "k")
    i.admit("arm-b", "Part", seq(1), "k")
    i.mission_changed(frozenset({("arm-b", "Part")}))
    assert i.last_seq == {("arm-b", "Part"): 1}
    assert not i.admit("console", "Ping", seq(2), "k")  # no longer declared


def test_token_bucket() -> None:
    b = TokenBucket(rate_hz=100.0, burst=3, now_s=0.0)
    assert [b.take(0.0) for _ in range(4)] == [True, True, True, False]
    assert b.take(0.01) and not b.take(0.01)
    assert [b.take(10.0) for _ in range(4)] == [True, True, True, False]  # never above the burst


def test_log_throttle_says_the_first_then_how_many_more(lines: Lines) -> None:
    clock = Clock()
    say = throttle(lines, clock)
    for k in range(1000):
        say("kind A", logging.WARNING, "a %d", k)
        say("kind B", logging.INFO, "b %d", k)
    assert lines.lines == [f"{x} {k}" for k in range(10) for x in "ab"]
    clock.t_s += 5.0
    say.flush()
    assert len(lines.lines) == 20  # the window has not ended
    clock.t_s += 5.0
    say.flush()
    assert sorted(lines.lines[20:]) == [
        "kind A: 990 more like it in the last 10 s",
        "kind B: 990 more like it in the last 10 s",
    ]
    say("kind A", logging.WARNING, "a again")
    assert lines.lines[-1] == "a again"  # a new window


def test_log_throttle_keeps_a_bounded_number_of_kinds(lines: Lines) -> None:
    say = LogThrottle(logging.getLogger("test.cellguard.kinds"), Clock(), keys_max=4)
    for k in range(1000):
        say(f"kind {k}", logging.DEBUG, "x")
    assert len(say._kinds) == 5  # four, and "other"


def test_output_ledger_counts_an_output_traced_and_never_pushed() -> None:
    led = OutputLedger(grace_s=5.0)
    led.pushed("Pong", 0.0)  # told before its trace record was read
    led.traced("Pong", 0.1)
    led.traced("Pong", 0.2)  # ... and one never told of
    led.traced("Pong", 0.3)
    led.pushed("Pong", 1.0)  # told late, within the grace
    assert led.expire(4.0) == 0
    assert led.expire(5.5) == 1 and led.lost == 1
    assert led.expire(100.0) == 0
    led.pushed("Pong", 200.0)  # its trace record lost (the ring overran): forgotten, not counted
    assert led.expire(300.0) == 0 and led.lost == 1


def test_output_ledger_is_bounded() -> None:
    led = OutputLedger(grace_s=5.0, pending_max=100)
    for k in range(1000):
        led.traced("Pong", k * 1e-3)
    assert len(led.traced_only["Pong"]) == 100 and led.lost == 900
    assert led.expire(10.0) == 1000


def test_in_flight_bound() -> None:
    gate = InFlight(2)
    assert gate.enter() and gate.enter() and not gate.enter()
    gate.leave()
    assert gate.enter()
    assert gate.report() == {"in_flight": 2, "max": 2, "served": 1, "busy": 1}


def test_a_read_only_peer_may_put_nothing() -> None:
    acl = access_control(net())
    own = {r["id"]: r["messages"] for r in acl["rules"] if r["id"].startswith("own:")}
    assert own["own:viewer"] == ["liveliness_token"]  # its token: its loss is news
    assert "put" in own["own:console"] and "put" in own["own:arm-b"]


def test_a_daemon_takes_no_message_beyond_its_bound() -> None:
    assert zenoh_config(net(secured=False), daemon=True)["transport"]["link"]["rx"] == {
        "max_message_size": DAEMON_RX_MESSAGE_MAX
    }
    assert "rx" not in zenoh_config(net(secured=False), daemon=False)["transport"]["link"]  # a console's


@pytest.mark.parametrize(
    ("key", "value", "allowed"),
    [("signal_rate_hz", 0.5, "[1, 1000]"), ("signal_rate_hz", 5000.0, "[1, 1000]"),
     ("signal_burst", 0, "[1, 1000]"), ("read_requests_max", 1000, "[1, 256]"),
     ("control_requests_max", 0, "[1, 256]")],
)  # fmt: skip
def test_the_bounds_are_bounded(key: str, value: float, allowed: str) -> None:
    with pytest.raises(
        ConfigError, match=re.escape(f"robot.toml: cell.{key} (={value}) must be in {allowed}")
    ):
        load_cellnet({"name": "test", key: value}, "robot.toml", "arm-a")


class Sample:
    """What `CellPeer._on_signal` reads of a `zenoh.Sample`."""

    def __init__(self, key: str, payload: Payload) -> None:
        self.key_expr = key
        self.payload = payload


def test_a_cell_peer_stores_nothing_for_signals_it_does_not_take() -> None:
    async def answer(line: bytes, role: object, who: str) -> dict[str, object]:
        return {}

    peer = CellPeer(net(), answer, "/nonexistent")  # no Zenoh session: its callbacks alone
    peer.mission_changed({"remote_inputs": [["Ping", "console"]], "cell_outputs": ["Pong"]})
    p = seq(1)
    for k in range(50_000):
        peer._on_signal(Sample(f"orccadd/test/console/signal/N{k}", p))  # type: ignore[arg-type]
        peer._on_signal(Sample(f"orccadd/test/viewer/signal/N{k}", p))  # type: ignore[arg-type]
        peer._on_signal(Sample(f"orccadd/test/stranger{k}/signal/Ping", p))  # type: ignore[arg-type]
    assert peer.intake.last_seq == {} and p.copies == 0
    assert peer.report()["signals"] == {
        "console": {"undeclared": 50_000},
        "viewer": {"not_control": 50_000},
        UNLISTED: {"not_control": 50_000},
    }
    assert len(peer.say._kinds) <= 3
