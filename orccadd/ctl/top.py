"""`orccadctl top`: a live view of status and the reactive trace, with a few keys.

`render` is a pure function (status, events, terminal size → the frame's lines); `Top` holds
what the keys change and talks to the daemon through any object with `reply(cmd, **args)`;
the terminal itself (cbreak keys, ANSI output) is orccadd/ctl/terminal.py. So each part is
tested alone: frames from status dicts, keys from a scripted key source.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from orccadd.ctl.client import ClientError
from orccadd.ctl.format import format_trace, joint_lines, state_words, timing_line
from orccadd.ctl.human import format_reply
from orccadd.fault import cause_words
from orccadd.wire.schema import exception_of

KEY_COMMANDS = {"h": "hold", "r": "resume"}  # key → the daemon's command of that name
KEYS_HELP = "q quit  p pause  h hold  r resume"
MIN_WIDTH = 66  # the joint table
HEAD_LINES = 8  # title, state, goal, error, resource, loop, note, joint header
EVENTS_FETCHED = 50

RED, GREEN, YELLOW = "31", "32", "33"


def state_colour(s: dict[str, Any]) -> str:
    """Red: faulted (a safe stop, the safe procedure) or a device fault; yellow: holding, or a
    stop under way; green: running. Idle and ready: no colour."""
    flags = set(s.get("resource_status") or [])
    if s.get("faulted") or flags & {"fault", "comm_lost"}:
        return RED
    if s.get("state") == "holding" or "stopping" in flags:
        return YELLOW
    return GREEN if s.get("state") == "running" else ""


def goal(s: dict[str, Any]) -> str:
    """What the arm is doing: the active task and its phase (status has no target to show)."""
    task = s.get("active_task")
    if task is None:
        return "-"
    text = f"{task} ({s.get('task_phase')})"
    if s.get("state") == "holding":
        text += ": the mission is suspended (r resumes)"
    return text


def newest_exception(events: Sequence[dict[str, Any]]) -> tuple[int, str] | None:
    """(seq, words) of the newest exception in the trace (by the kinds the records carry): an
    instant's type 2 or 3 input, a task event, or a safe stop's cause."""
    for e in reversed(events):
        if not exception_of(e):
            continue
        if e["kind"] == "fault":
            return int(e["seq"]), f"{e['time']} safe stop: {cause_words(e['fault'])}"
        if e["kind"] == "instant":
            kinds = e.get("input_kinds", [])
            found = [n for n, k in zip(e.get("inputs", []), kinds, strict=False) if k in ("t2", "t3")]
        else:
            found = [str(e.get("event", ""))]
        return int(e["seq"]), f"{e['time']} {', '.join(found)}"
    return None


def _fit(text: str, width: int, colour: str = "", start: int = 0, end: int | None = None) -> str:
    """`text` cut to `width`; `text[start:end]` in `colour` (an SGR code) if given."""
    text = text[:width]
    if not colour:
        return text
    end = len(text) if end is None else min(end, len(text))
    if start >= end:
        return text
    return f"{text[:start]}\x1b[{colour}m{text[start:end]}\x1b[0m{text[end:]}"


def render(
    status: dict[str, Any],
    events: Sequence[dict[str, Any]],
    size: tuple[int, int],
    *,
    colour: bool = False,
    paused: bool = False,
    note: str = "",
    last_error: str = "",
) -> list[str]:
    """The frame for a terminal of `size` (columns, lines), each line at most `columns` wide.
    `last_error`: the newest error seen so far (an exception of the trace, a refused key
    command); a fault of status (faulted) goes first."""
    width, height = size
    units = status.get("resources") or []
    joints = len(status.get("joints", []))
    if units:  # a station: a goal, resource and loop line and the joints of each
        joints = sum(len(u.get("joints", [])) + 4 for u in units) - 3
    need = (MIN_WIDTH, HEAD_LINES + joints + 2)
    if width < need[0] or height < need[1]:
        return [f"terminal too small: need {need[0]}x{need[1]}"[:width]]
    title = f"orccadd top: {status.get('robot')}" + ("  [paused]" if paused else "")
    title = title.ljust(max(len(title) + 2, width - len(KEYS_HELP))) + KEYS_HELP
    words = state_words(status)
    state = f"state    {words}"
    if status.get("mission"):
        state += f", mission {status['mission']}"
    if status.get("automaton_state", -1) >= 0:
        state += f", automaton state {status['automaton_state']}"
    state += f", last result {status.get('result')}"
    fault = cause_words(status.get("fault")) if status.get("faulted") else ""
    error = f"fault: {fault} (`reset` needed)" if fault else last_error
    flags = ", ".join(status.get("resource_status") or []) or "ok"
    c = state_colour(status) if colour else ""
    # a type 2 the mission handled is no error: shown as handled, not in red
    handled = bool(error) and not fault and ".T2." in error and ".T3." not in error and "stop" not in error
    label = "handled  " if handled else "error    "
    error_line = _fit(f"{label}{error or '-'}", width, RED if colour and error and not handled else "", 9)
    head = [_fit(title, width), _fit(state, width, c, 9, 9 + len(words))]
    note_line = _fit(f"> {note}" if note else "", width)
    if units:  # a station: each resource's goal, status, loop and joints
        body = [error_line, note_line]
        for u in units:
            u_flags = ", ".join(u.get("resource_status") or []) or "ok"
            bad = colour and (u_flags != "ok" or bool(u.get("fault")))
            body += [
                _fit(f"{u['name']}: {goal({**u, 'state': status.get('state')})}", width),
                _fit(f"  resource {u_flags}", width, RED if bad else "", 11),
                _fit(f"  loop     {timing_line(u)}", width),
                *(_fit("  " + x, width) for x in joint_lines(u)),
            ]
    else:
        body = [
            _fit(f"goal     {goal(status)}", width),
            error_line,
            _fit(f"resource {flags}", width, RED if colour and flags != "ok" else "", 9),
            _fit(f"loop     {timing_line(status)}", width),
            note_line,
            *(_fit(x, width) for x in joint_lines(status)),
        ]
    lines = [*head, *body, _fit("last events:", width)]
    room = height - len(lines)
    shown = list(events)[-room:] if room > 0 else []
    lines += [_fit(format_trace(e), width) for e in shown]
    return lines


class Caller(Protocol):
    def reply(self, cmd: str, **args: Any) -> dict[str, Any]: ...


class KeySource(Protocol):
    def read(self, timeout_s: float) -> str | None:
        """The next key pressed within `timeout_s`, or None."""


class Screen(Protocol):
    colour: bool

    def size(self) -> tuple[int, int]: ...
    def draw(self, lines: list[str]) -> None: ...


@dataclass
class Top:
    client: Caller
    keys: KeySource
    screen: Screen
    rate_hz: float = 4.0
    count: int = 0  # frames before ending (0: until q or Ctrl-C)
    paused: bool = False
    note: str = ""
    last_error: str = ""
    error_seq: int = 0

    def __post_init__(self) -> None:
        self.status: dict[str, Any] = {}
        self.events: list[dict[str, Any]] = []

    def _call(self, cmd: str, **args: Any) -> Any:
        r = self.client.reply(cmd, **args)
        if not r.get("ok"):
            raise ClientError(str(r.get("error")))
        return r["result"]

    def refresh(self) -> None:
        self.status = self._call("status")
        self.events = self._call("events", last=EVENTS_FETCHED)["events"]
        found = newest_exception(self.events)
        if found and found[0] > self.error_seq:
            self.error_seq, self.last_error = found

    def frame(self) -> list[str]:
        return render(
            self.status,
            self.events,
            self.screen.size(),
            colour=self.screen.colour,
            paused=self.paused,
            note=self.note,
            last_error=self.last_error,
        )

    def press(self, key: str) -> bool:
        """Act on one key; False: quit."""
        if key in ("q", "Q"):
            return False
        if key == "p":
            self.paused = not self.paused
            self.note = "display paused (p: go on)" if self.paused else ""
        elif key in KEY_COMMANDS:
            cmd = KEY_COMMANDS[key]
            r = self.client.reply(cmd)
            if r.get("ok"):
                self.note = format_reply(cmd, r["result"])
            else:
                self.note = f"{cmd} refused: {r.get('error')}"
                self.last_error = f"{_now()} {cmd}: {r.get('error')}"
        elif key.strip():
            self.note = f"keys: {KEYS_HELP}"
        return True

    def run(self) -> None:
        period = 1.0 / self.rate_hz
        self.refresh()
        frames = 0
        while True:
            self.screen.draw(self.frame())
            frames += 1
            if self.count and frames >= self.count:
                return
            key = self.keys.read(period)
            if key is not None and not self.press(key):
                return
            if not self.paused:
                self.refresh()


def _now() -> str:
    t = time.time()
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t % 1 * 1000):03d}"
