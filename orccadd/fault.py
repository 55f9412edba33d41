"""Why an arm was stopped, as one typed value from the device to the operator (standard library
only: the command daemon and the clients decode it without loading a backend).

A backend says what went wrong (`Fault`: kind, resource, joint, the device's own code, words);
the daemon adds the type 3 event it raised (`StopCause`); the status area, the logs and the
clients carry both as they are and print them with `str`, never by parsing names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from enum import StrEnum
from typing import Any


class FaultKind(StrEnum):
    """What stopped the arm (a closed set: clients may switch on it)."""

    DEVICE = "device"  # the device reports a fault: drive fault, protective stop, hardware error
    LIMIT = "limit"  # a measured position or velocity beyond the configured limits
    COMMAND = "command"  # a command the resource refused to send (NaN, beyond a limit)
    COMM_LOST = "comm_lost"  # the device went silent or its link closed
    OVERRUN = "overrun"  # the control thread missed too many deadlines in a row
    TIMEOUT = "timeout"  # a task outlived its time limit or waited too long for its preconditions
    MISSION = "mission"  # a type 3 exception the mission's own tasks raised (a watcher)
    ABORT = "abort"  # an operator's abort, or the daemon's own on a lost command daemon
    INTERNAL = "internal"  # the controller itself failed (a bug: the control thread ended)


@dataclass(frozen=True)
class Fault:
    """A fault in one resource: `joint` ("" for the whole resource) and the device's `code` (CiA 402
    error code, UR safety mode, Dynamixel hardware error bits; 0 when it gives none) as the device
    states them, `text` in words without the resource's name (with the joint's, or the joints')."""

    kind: FaultKind
    resource: str
    text: str
    joint: str = ""
    code: int = 0

    def __str__(self) -> str:  # the words name the joint where it matters (several may)
        return f"{self.resource}: {self.text}" if self.resource else self.text

    def to_wire(self) -> dict[str, Any]:
        d = asdict(self)
        d["kind"] = self.kind.value
        return d

    @staticmethod
    def from_wire(d: dict[str, Any]) -> Fault:
        return Fault(
            FaultKind(d["kind"]), str(d["resource"]), str(d["text"]), str(d["joint"]), int(d["code"])
        )


@dataclass(frozen=True)
class StopCause:
    """Why the daemon safe-stopped: the type 3 event it raised (`Move.T3.CommLost`; "" for an
    abort) and the fault behind it."""

    event: str
    fault: Fault

    def __str__(self) -> str:
        return f"{self.event} ({self.fault})" if self.event else str(self.fault)

    def to_wire(self) -> dict[str, Any]:
        return {"event": self.event, **self.fault.to_wire()}

    @staticmethod
    def from_wire(d: dict[str, Any]) -> StopCause:
        return StopCause(str(d["event"]), Fault.from_wire(d))


def cause_words(d: Mapping[str, Any] | None) -> str:
    """A stop cause as the wire carries it (`StopCause.to_wire`), in words for people."""
    if not d:
        return "?"
    if "kind" not in d:  # a trace's fault record whose cause the daemon no longer keeps
        return f"safe stop #{d.get('n', '?')} (cause no longer kept)"
    return str(StopCause.from_wire(dict(d)))
