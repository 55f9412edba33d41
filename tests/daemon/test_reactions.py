"""A unit process's tick taking the automaton's published reaction (`daemon.reactions`): only
one event, only with a table, only when the automaton is idle and has consumed every earlier
event of every unit; then its own switch in the tick, the others' posted, every table gone and
what it took left for the automaton to book."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from orccadd.daemon.reactions import ChannelReactor
from orccadd.daemon.unitshm import NO_TASK, TryLock, UnitChannel

EVENT = 7  # the event the table of unit 0 has a row for


@pytest.fixture
def station(tmp_path: Path) -> Iterator[tuple[list[UnitChannel], TryLock, TryLock]]:
    """Two units' channels, unit 0's table: on EVENT, unit 0 to task 3, unit 1 to task 4; the
    station's lock as the automaton holds it and as unit 0 tries it."""
    channels = [UnitChannel.create(ring_len=16, units=2, index=k) for k in range(2)]
    automaton, unit = TryLock(str(tmp_path / "lock")), TryLock(str(tmp_path / "lock"))
    channels[0].publish([(EVENT, [3.0, 4.0])])
    try:
        yield channels, automaton, unit
    finally:
        for ch in channels:
            ch.close()
        automaton.close()
        unit.close()


def tick(reactor: ChannelReactor, channel: UnitChannel, *events: int) -> tuple[bool, list[Any]]:
    """A tick of unit 0 pushing `events`: whether it took a reaction, and what it switched to."""
    first = channel.pushed
    for e in events:
        channel.push(0.5, e)
    switched: list[Any] = []
    hold = SimpleNamespace(name="Hold")
    took = reactor.react(SimpleNamespace(hold=hold), 0.5, first, channel.pushed, hold, switched.append)  # type: ignore[arg-type]
    return took, switched


def reactor_of(channels: list[UnitChannel], unit: TryLock) -> ChannelReactor:
    r = ChannelReactor(channels, 0, unit)
    r.tasks = [SimpleNamespace(name=f"T{i}") for i in range(5)]  # type: ignore[misc]
    return r


def test_one_event_with_a_row_switches_here_posts_there_and_leaves_it_to_book(
    station: tuple[list[UnitChannel], TryLock, TryLock],
) -> None:
    channels, _, unit = station
    reactor = reactor_of(channels, unit)
    took, switched = tick(reactor, channels[0], EVENT)
    assert took and [t.name for t in switched] == ["T3"]  # its own law, in this tick
    assert channels[1].words[3] == 4 and not channels[1].requests_applied()  # posted: unit 1's next tick
    assert channels[0].wanted_task == 3
    assert not channels[0].has_table() and not channels[1].has_table()  # every table gone
    assert channels[0].taken() == (EVENT, 0.5, 0, 1)  # for the automaton to book, once
    assert channels[0].taken() is None
    assert tick(reactor, channels[0], EVENT)[0] is False  # no table: the automaton's way


def test_a_tick_leaves_it_to_the_automaton_when_it_is_busy_or_behind_or_has_two_events(
    station: tuple[list[UnitChannel], TryLock, TryLock],
) -> None:
    channels, automaton, unit = station
    reactor = reactor_of(channels, unit)
    assert tick(reactor, channels[0], EVENT, EVENT) == (False, [])  # two events in one tick
    channels[0].drain()  # the automaton consumed them
    automaton.acquire()  # the automaton at work
    assert tick(reactor, channels[0], EVENT) == (False, [])
    automaton.release()
    channels[0].drain()
    channels[1].push(0.4, 2)  # an event of unit 1 the automaton has not consumed yet
    assert tick(reactor, channels[0], EVENT) == (False, [])
    channels[0].drain()
    channels[1].drain()
    assert tick(reactor, channels[0], 9)[0] is False  # an event without a row
    channels[0].drain()
    assert tick(reactor, channels[0], EVENT)[0]  # up to date, idle: taken
    assert reactor.deferred == 2 and reactor.inline == 1


def test_a_row_that_leaves_a_unit_alone_posts_nothing_to_it(
    station: tuple[list[UnitChannel], TryLock, TryLock],
) -> None:
    channels, _, unit = station
    channels[0].publish([(EVENT, [NO_TASK, 2.0])])  # unit 0's law unchanged, unit 1 to task 2
    took, switched = tick(reactor_of(channels, unit), channels[0], EVENT)
    assert took and switched == [] and channels[1].words[3] == 2
