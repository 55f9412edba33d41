"""The command table: every operator command declared once, and the request format.

Each `CommandSpec` names the command, the role it needs, its arguments (types, default, help),
which process executes it (`rt`: the real-time process, `cmdd`: the command daemon) and its help
text. From this one table derive: request validation (`parse_request`), dispatch (`Dispatcher`:
each side's handlers are bound by name with `@handles` and checked complete against the table),
`orccadctl`'s help, and the command list of docs/protocol.md (`markdown_table`, checked by a test).

Wire format: newline-delimited JSON over the daemon's Unix socket.

Request:  {"id": <any>, "cmd": "<command>", "args": {...}}            (one line, ≤ 64 KiB)
          optional "protocol": <PROTOCOL_VERSION>: refused if it is not this daemon's
Reply:    {"id": <same>, "ok": true, "result": {...}}
          {"id": <same>, "ok": false, "error": "<what and why>"}
Streams (`monitor`, `events` with follow): several `{"id", "ok": true, "stream": {...}}` lines,
then a final reply; the client may close the connection at any time.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Literal, TypeVar

from orccadd.wire.schema import PROTOCOL_VERSION

MAX_LINE = 65536
# what `log start` records when no signal is named: everything `orccadctl compare` and `replay`
# need (the tick's time, task, phase, whether it wrote and in which mode, the resource's status;
# the measured state and the command sent), at full rate
LOG_SIGNALS = ("t_s", "task", "phase", "wrote", "mode", "status", "q", "dq", "tau", "cmd")
DEFAULT_LOG = " ".join(LOG_SIGNALS) + " and the resource's own signals"
MAX_INT = 2**53  # integers a JSON peer can represent exactly; beyond: refused
MAX_ID_CHARS = 256  # a request id is echoed in the reply: a short one
NUMBER = (int, float)


class Role(StrEnum):
    """`control` ⊃ `read`: a control client may do everything a read-only one may."""

    READ = "read"
    CONTROL = "control"
    CELL = "cell"  # the command daemon's own, from its cell link: never a client's


Where = Literal["rt", "cmdd"]


@dataclass(frozen=True)
class Arg:
    """One argument: its JSON types (`bool` only if listed), default, help."""

    name: str
    types: tuple[type, ...]
    help: str
    required: bool = False
    default: Any = None
    choices: tuple[str, ...] = ()
    items: tuple[type, ...] = (str,)  # a list argument's item types


# how long a reply may take, declared here for every layer: the command daemon waits this long
# for the real-time process, `orccadctl` a margin more for the command daemon
RT_REPLY_S = 5.0  # most commands: answered at the automaton thread's next turn
LOAD_TIMEOUT_MAX_S = 3600.0  # `daemon.load_timeout_s`'s bound: a load's refusal comes within it
LOAD_REPLY_S = LOAD_TIMEOUT_MAX_S + 30.0
RESET_REPLY_S = 40.0  # a reset's device work: an unlock, a reconnection, a servo's reboot (≤ 32 s)
CLIENT_MARGIN_S = 5.0
SPEED_SCALE_HELP = "fraction of the joints' velocity, acceleration and jerk limits, 0.01 to 1"


@dataclass(frozen=True)
class CommandSpec:
    name: str
    role: Role
    where: Where
    help: str
    args: tuple[Arg, ...] = ()
    stream: bool = False  # replies with stream lines before the final reply
    urgent: bool = False  # served ahead of everything (the urgent socket, a kept place)
    reply_s: float = RT_REPLY_S  # the longest its reply may take (a stream's first line)
    loads: bool = False  # done, it has loaded a mission: the command daemon reads `describe` again

    @property
    def client_wait_s(self) -> float:
        """How long `orccadctl` waits for the reply."""
        return self.reply_s + CLIENT_MARGIN_S

    def arg(self, name: str) -> Arg:
        return next(a for a in self.args if a.name == name)


R, C = Role.READ, Role.CONTROL

COMMANDS: dict[str, CommandSpec] = {
    s.name: s
    for s in (
        CommandSpec("ping", R, "cmdd", "the command daemon answers (its pid and the protocol version)"),
        CommandSpec(
            "status",
            R,
            "cmdd",
            "state, mission, automaton state, active task and phase, joints, loop timing (last 5 s), log",
        ),
        CommandSpec("describe", R, "rt", "robot, joints, resource, tasks, the mission's inputs and actions"),
        CommandSpec(
            "params",
            R,
            "rt",
            "tunable parameters: value, bounds, unit, tunable",
            (Arg("task", (str,), "one task's parameters (default: every task)", default=""),),
        ),
        CommandSpec(
            "events",
            R,
            "cmdd",
            "the reactive trace: instants (inputs → actions, states), task events, commands, time-stamped",
            (
                Arg("last", (int,), "how many past records", default=50),
                Arg("follow", (bool,), "keep streaming new records", default=False),
                Arg("duration_s", NUMBER, "stop following after this long (0: never)", default=0.0),
            ),
            stream=True,
        ),
        CommandSpec(
            "monitor",
            R,
            "cmdd",
            "stream of `{t_s, values}`: `q`, `dq`, `tau`, `cmd` (sent to the device, in `mode`: "
            "1 position, 2 velocity, 3 torque) (or `q.3`, `q.<joint>`), `wake_us`, `compute_us`, `task`, "
            "`phase`, `status`, `mode`; in a station every resource's (labels `left/q.<joint>`), or one's "
            "(`left/q`)",
            (
                Arg("signals", (list,), "signal names (default: q)", default=None),
                Arg("rate_hz", NUMBER, "samples per second, 0.01 to the control rate", default=10.0),
                Arg("count", (int,), "stop after this many samples (0: never)", default=0),
                Arg("duration_s", NUMBER, "stop after this long (0: never)", default=0.0),
            ),
            stream=True,
        ),
        CommandSpec(
            "load",
            C,
            "rt",
            "compile, verify, prepare the tasks; refused with the failing checks' counterexamples",
            (
                Arg(
                    "path",
                    (str,),
                    "the mission file (absolute), in one of daemon.mission_dirs; or a deployed "
                    "mission's name or hash (`deploy`)",
                    required=True,
                ),
            ),
            reply_s=LOAD_REPLY_S,
            loads=True,
        ),
        CommandSpec(
            "deploy",
            C,
            "rt",
            "store a mission sent from a workstation with every task file it names: checked as `load` "
            "checks a file (refused with the counterexamples, nothing stored), then kept by content "
            "hash in the daemon's deployments directory; `load NAME` or `load HASH` loads it",
            (
                Arg("name", (str,), "the mission's name (its file's stem)", required=True),
                Arg("mission", (str,), "the mission's text", required=True),
                Arg(
                    "task_files",
                    (list,),
                    'the task files as the mission names them (`from "..."`)',
                    default=[],
                ),
                Arg("task_texts", (list,), "their texts, in the same order", default=[]),
                Arg(
                    "by",
                    (str,),
                    "who deploys: the command daemon's name of the client (a client's own is replaced)",
                    default="",
                ),
            ),
            reply_s=LOAD_REPLY_S,
        ),
        CommandSpec(
            "start",
            C,
            "rt",
            "run the loaded mission's main procedure",
            (Arg("procedure", (str,), "the main procedure's name (checked if given)", default=""),),
        ),
        CommandSpec(
            "move",
            C,
            "rt",
            "move to a joint target, or the tool along a straight line to a pose, without a mission "
            "file: the daemon writes a mission of one task (the shipped move_joints or move_to_pose "
            "task of the resource's command mode), loads it as `load` does (same compiler and checks) "
            "and starts it; a value outside its joint's range, the wrong count, a pose outside the "
            "workspace is refused before anything moves",
            (
                Arg("joints_rad", (list,), "the target, one per joint (rad); or `pose`", items=NUMBER),
                Arg(
                    "pose",
                    (list,),
                    "the tool's target: x, y, z (m, base frame), then roll, pitch, yaw (rad, about the "
                    "base's x, y, z; left out: the tool keeps its orientation); or `joints_rad`",
                    items=NUMBER,
                ),
                Arg("resource", (str,), "the resource (default: the only one)", default=""),
                Arg("speed_scale", NUMBER, SPEED_SCALE_HELP, default=0.5),
            ),
            reply_s=LOAD_REPLY_S,
            loads=True,
        ),
        CommandSpec(
            "jog",
            C,
            "rt",
            "move one joint by an amount from where it is now, as `move` does",
            (
                Arg("joint", (str,), "the joint's name", required=True),
                Arg("by_rad", NUMBER, "how far (rad; negative: the other way)", required=True),
                Arg("resource", (str,), "the resource (default: the one with that joint)", default=""),
                Arg("speed_scale", NUMBER, SPEED_SCALE_HELP, default=0.5),
            ),
            reply_s=LOAD_REPLY_S,
            loads=True,
        ),
        CommandSpec(
            "follow",
            C,
            "rt",
            "follow a planner's joint trajectory (CSV `t_s,<joints>`), interpolated by a clamped cubic "
            "spline: checked whole against the joints' position, velocity and acceleration limits and "
            "the arm's position before anything moves, then run as `move` is",
            (
                Arg("csv", (str,), "the CSV's text (within the request's 64 KiB)", required=True),
                Arg("name", (str,), "its file's name, for messages", default="trajectory.csv"),
                Arg("resource", (str,), "the resource (default: the only one)", default=""),
            ),
            reply_s=LOAD_REPLY_S,
            loads=True,
        ),
        CommandSpec("stop", C, "rt", "graceful: the mission's `Stop` operator input", urgent=True),
        CommandSpec("abort", C, "rt", "immediate safe stop; the mission ends `aborted`", urgent=True),
        CommandSpec(
            "cell_input",
            Role.CELL,
            "rt",
            "a peer's signal, or the loss of a peer, entering the running mission as one input of one "
            "instant: sent by the command daemon from its cell link, refused to clients",
            (
                Arg(
                    "input",
                    (str,),
                    'the mission\'s input (`input X from "peer"`, or `lost_PEER`)',
                    required=True,
                ),
                Arg("peer", (str,), "the peer it came from", required=True),
            ),
        ),
        CommandSpec("hold", C, "rt", "suspend the mission on the Hold task"),
        CommandSpec("resume", C, "rt", "restart the suspended task from the measured state"),
        CommandSpec(
            "reset",
            C,
            "rt",
            "clear a safe stop (and a device fault) once the arm is at rest",
            (Arg("resource", (str,), "the resource to reset (default: every safe-stopped one)", default=""),),
            reply_s=RESET_REPLY_S,
        ),
        CommandSpec(
            "send",
            C,
            "rt",
            "any operator input of the mission",
            (Arg("input", (str,), "the input's name", required=True),),
        ),
        CommandSpec(
            "tune",
            C,
            "rt",
            "`TASK.MODULE.PARAM` (a vector: a list of one per joint, or `…PARAM[i]`, one joint's): "
            "bounds and shape checked, applied at one tick boundary (its number in "
            "the reply), traced",
            (
                Arg(
                    "path",
                    (str,),
                    "TASK.MODULE.PARAM, or TASK.MODULE.PARAM[i] for one joint's",
                    required=True,
                ),
                Arg(
                    "value",
                    (*NUMBER, list),
                    "a number, or a list of one per joint for a vector",
                    required=True,
                    items=NUMBER,
                ),
            ),
        ),
        CommandSpec(
            "log",
            C,
            "cmdd",
            "start/stop a full-rate log, CSV and MCAP beside it, written by the command daemon into its "
            "own log directory (daemon.log_dir); the reply names the files (`file`, `mcap` parts), the "
            "wall-clock start (`start_utc`) and the loop time rows count from (`origin_t_s`); in a station "
            "a CSV per resource (`files`, `resources`: `<name>.<resource>.csv`) and one MCAP",
            (
                Arg("action", (str,), "start or stop", required=True, choices=("start", "stop")),
                Arg("signals", (list,), f"signal names (default: {DEFAULT_LOG})", default=None),
                Arg("name", (str,), "start: the file's name in the daemon's log directory", default=""),
            ),
        ),
        CommandSpec(
            "logs",
            R,
            "cmdd",
            "the daemon's logs (its log directory): each CSV with its MCAP parts, size, start, and the "
            "mission and result its events show; `fetch` copies one to the console",
        ),
        CommandSpec(
            "fetch",
            R,
            "cmdd",
            "a chunk of one of the daemon's log files (a log's CSV or an MCAP part), base64, with the "
            "file's size; the chunk that reaches its end carries its sha256 (orccadctl fetch reads them "
            "in turn and checks the whole)",
            (
                Arg("name", (str,), "the file, as `logs` names it", required=True),
                Arg("offset", (int,), "where the chunk starts (bytes)", default=0),
                Arg("length", (int,), "how many bytes, at most 32768", default=32768),
            ),
        ),
        CommandSpec(
            "inject",
            C,
            "rt",
            "inject a fault for tests and commissioning (only with `orccadd --allow-fault-injection`)",
            (
                Arg(
                    "fault",
                    (str,),
                    "resource (the device's fault), overrun, control_thread (its next tick raises), "
                    "hang (its next tick waits extra_ms, as a device call that does not return) or "
                    'unit_process (its unit\'s process dies at once: [daemon] units = "processes")',
                    required=True,
                    choices=("resource", "overrun", "control_thread", "hang", "unit_process"),
                ),
                Arg("ticks", (int,), "overrun: how many ticks", default=20),
                Arg(
                    "extra_ms",
                    NUMBER,
                    "overrun: extra compute per tick (0: 1.5 periods); hang: how long (0: 1 s)",
                    default=0.0,
                ),
                Arg("resource", (str,), "the resource (default: the first listed)", default=""),
            ),
        ),
    )
}


# served ahead of everything: on the real-time process's urgent socket, and on the command
# daemon's main socket even when every control place is taken (a place kept for them)
URGENT_COMMANDS = frozenset(name for name, spec in COMMANDS.items() if spec.urgent)


def client_wait_s(cmd: str) -> float:
    """How long a client waits for the reply to `cmd` (a composite one of `orccadctl`'s, such
    as `top`, as a command the real-time process answers)."""
    spec = COMMANDS.get(cmd)
    return spec.client_wait_s if spec is not None else RT_REPLY_S + CLIENT_MARGIN_S


class ProtocolError(Exception):
    """A request that is not well formed; the message says why, in the client's terms, and
    `rid` is the request's id when it could be read (the error reply carries it)."""

    def __init__(self, message: str, rid: Any = None) -> None:
        super().__init__(message)
        self.rid = rid


def parse_request(line: bytes) -> tuple[Any, str, dict[str, Any]]:
    """(id, cmd, args) of a well-formed request; `ProtocolError` (with the id if known) otherwise.

    Checks the fields, the command, each argument's name and type (numbers finite, integers
    within ±2^53, list items scalars), choices and required arguments. Defaults are not filled in.
    """
    try:
        msg = json.loads(line)
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise ProtocolError(f"not JSON: {type(e).__name__}: {str(e)[:200]}") from None
    if not isinstance(msg, dict):
        raise ProtocolError('a request is a JSON object {"cmd": ..., "args": {...}}')
    rid = msg.get("id")
    if not isinstance(rid, str | int | float | None) or isinstance(rid, bool) or _scalar_problem(rid):
        raise ProtocolError("'id' must be a finite number (within ±2^53), a string or null")
    if isinstance(rid, str) and len(rid) > MAX_ID_CHARS:
        raise ProtocolError(f"'id' must be at most {MAX_ID_CHARS} characters")
    unknown = set(msg) - {"id", "cmd", "args", "protocol"}
    if unknown:
        names = ", ".join(sorted(map(str, unknown)))[:200]
        raise ProtocolError(f"unknown request fields: {names} (fields: id, cmd, args, protocol)", rid)
    version = msg.get("protocol", PROTOCOL_VERSION)
    if version != PROTOCOL_VERSION:
        raise ProtocolError(
            f"this orccadd speaks protocol {PROTOCOL_VERSION}, the client {str(version)[:20]}: use the "
            "orccadctl of the same release (`orccadd --version`, `orccadctl --version`)",
            rid,
        )
    cmd = msg.get("cmd")
    if not isinstance(cmd, str):
        raise ProtocolError("'cmd' must be a string", rid)
    spec = COMMANDS.get(cmd)
    if spec is None:
        raise ProtocolError(f"unknown command {cmd[:64]!r} (commands: {', '.join(sorted(COMMANDS))})", rid)
    args = msg.get("args", {})
    if not isinstance(args, dict):
        raise ProtocolError("'args' must be an object", rid)
    try:
        check_args(spec, args)
    except ProtocolError as e:
        raise ProtocolError(str(e), rid) from None
    return rid, cmd, args


def request_id(msg: Any) -> Any:
    """The id of a decoded request if it is one a reply may echo (a finite number within ±2^53, a
    string of at most `MAX_ID_CHARS`, null), else None: never NaN or Infinity, which are not JSON."""
    rid = msg.get("id") if isinstance(msg, dict) else None
    if isinstance(rid, bool) or not isinstance(rid, str | int | float) or _scalar_problem(rid):
        return None
    return None if isinstance(rid, str) and len(rid) > MAX_ID_CHARS else rid


def check_args(spec: CommandSpec, args: dict[str, Any]) -> None:
    names = {a.name for a in spec.args}
    for k, v in args.items():
        if k not in names:
            allowed = ", ".join(a.name for a in spec.args) or "none"
            raise ProtocolError(f"{spec.name}: unknown argument {str(k)[:64]!r} (arguments: {allowed})")
        a = spec.arg(k)
        if isinstance(v, bool) and bool not in a.types:
            raise ProtocolError(f"{spec.name}: argument {k!r} must be {_types(a.types)}, not a boolean")
        if isinstance(v, float) and int in a.types and float not in a.types:
            raise ProtocolError(f"{spec.name}: argument {k!r} must be an integer, not {v!r}")
        if not isinstance(v, a.types):
            raise ProtocolError(f"{spec.name}: argument {k!r} must be {_types(a.types)}, not {_json_type(v)}")
        for item in v if isinstance(v, list) else [v]:
            problem = _scalar_problem(item)
            if (
                not problem
                and isinstance(v, list)
                and (isinstance(item, bool) or not isinstance(item, a.items))
            ):
                problem = f"list items must be {_types(a.items)}, not {_json_type(item)}"
            if problem:
                raise ProtocolError(f"{spec.name}: argument {k!r}: {problem}")
        if a.choices and v not in a.choices:
            raise ProtocolError(f"{spec.name}: argument {k!r} (={v!r}) must be one of {', '.join(a.choices)}")
    for a in spec.args:
        if a.required and a.name not in args:
            raise ProtocolError(f"{spec.name}: argument {a.name!r} is required")


def _scalar_problem(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return ""
    if isinstance(v, int) and not -MAX_INT <= v <= MAX_INT:
        return f"integer out of range (±2^53): {str(v)[:20]}…"
    if isinstance(v, float) and not math.isfinite(v):
        return f"{v} is not a finite number"
    if isinstance(v, list | dict):
        return "nested lists or objects are not accepted"
    return ""


def with_defaults(spec: CommandSpec, args: dict[str, Any]) -> dict[str, Any]:
    """Every argument of `spec`, the client's value or the table's default."""
    return {a.name: args.get(a.name, a.default) for a in spec.args}


def _types(types: tuple[type, ...]) -> str:
    names = {int: "an integer", float: "a number", str: "a string", list: "a list", bool: "a boolean"}
    if float in types:  # a number, integers included
        types = tuple(t for t in types if t is not int)
    return " or ".join(dict.fromkeys(names.get(t, t.__name__) for t in types))


def _json_type(v: Any) -> str:
    names = {dict: "an object", list: "a list", str: "a string", int: "a number", float: "a number"}
    return "null" if v is None else names.get(type(v), type(v).__name__)


def encode(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, default=str) + "\n").encode()


def error_reply(rid: Any, message: str) -> dict[str, Any]:
    return {"id": rid, "ok": False, "error": message}


# ---- dispatch -------------------------------------------------------------------------------
F = TypeVar("F", bound=Callable[..., Any])
_MARK = "__orccadd_command__"


def handles(name: str) -> Callable[[F], F]:
    """Mark a method as the handler of command `name` (which must be in `COMMANDS`)."""
    if name not in COMMANDS:
        raise KeyError(f"@handles({name!r}): no such command in orccadd.wire.commands.COMMANDS")

    def mark(fn: F) -> F:
        setattr(fn, _MARK, name)
        return fn

    return mark


class Dispatcher:
    """The handlers of one side (`rt` or `cmdd`), bound from `owner`'s `@handles` methods.

    Refuses to build unless every command the table gives that side has exactly one handler and
    no handler serves a command of the other side.
    """

    def __init__(self, owner: object, where: Where) -> None:
        self.where = where
        self.handlers: dict[str, Callable[..., Any]] = {}
        for attr in dir(type(owner)):
            name = getattr(getattr(type(owner), attr), _MARK, None)
            if name is None:
                continue
            if name in self.handlers:
                raise TypeError(f"{type(owner).__name__}: two handlers for {name!r}")
            self.handlers[name] = getattr(owner, attr)
        wanted = {n for n, s in COMMANDS.items() if s.where == where}
        missing, extra = wanted - set(self.handlers), set(self.handlers) - wanted
        if missing or extra:
            raise TypeError(
                f"{type(owner).__name__} ({where}): no handler for {sorted(missing)}; "
                f"handlers of commands that are not this side's: {sorted(extra)}"
            )

    def handler(self, cmd: str) -> Callable[..., Any]:
        return self.handlers[cmd]


def markdown_table() -> str:
    """The command list of docs/protocol.md."""
    rows = ["| command | role | runs in | arguments | what |", "|---|---|---|---|---|"]
    where = {"rt": "real-time process", "cmdd": "command daemon"}
    for s in COMMANDS.values():
        args = ", ".join(
            f"`{a.name}`" + ("" if a.required else "?") + (f" ({'/'.join(a.choices)})" if a.choices else "")
            for a in s.args
        )
        rows.append(f"| `{s.name}` | {s.role.value} | {where[s.where]} | {args} | {s.help} |")
    return "\n".join(rows) + "\n"
