"""Each online command's reply in words, for people (`--json` prints the reply itself).

`format_reply(cmd, result, context)` takes the `result` of a successful reply as the daemon
sends it (orccadd/daemon/commands.py, orccadd/cmdd/server.py) and, for the commands whose reply
names things without their context, what orccadctl asked the daemon next (`context_requests`):
the parameters for `describe` (modules and parameters of each task).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from orccadd.ctl.format import format_status, format_trace, num, param_lines, table
from orccadd.fault import cause_words

Formatter = Callable[[dict[str, Any], dict[str, Any]], str]


def context_requests(cmd: str, args: dict[str, Any]) -> dict[str, tuple[str, dict[str, Any]]]:
    """What to ask the daemon, after a successful `cmd`, to say it in words: name → (command,
    arguments). Read-only requests; if one fails the words are shorter, nothing else."""
    if cmd == "describe":
        return {"params": ("params", {})}
    return {}


def format_reply(
    cmd: str,
    result: dict[str, Any],
    context: dict[str, Any] | None = None,
    args: dict[str, Any] | None = None,
) -> str:
    """`result` in words; `context`: the replies to `context_requests` (by name), `args`: the
    request's arguments (`log` says `start` and `stop` differently)."""
    return FORMATTERS.get(cmd, _generic)(result, {**(context or {}), "args": args or {}})


def _generic(r: dict[str, Any], _: dict[str, Any]) -> str:
    return ", ".join(f"{k} {num(v)}" for k, v in r.items())


def _describe(r: dict[str, Any], ctx: dict[str, Any]) -> str:
    period = float(r["period_s"])
    units = r.get("resources") or []
    if len(units) > 1:  # a station: each resource on its own clock
        lines = [f"robot {r['robot']}: {len(units)} resources, each on its own control thread"]
        lines += table([("config", str(r["config"]))], "  ")
        for u in units:
            p = float(u["period_s"])
            lines.append(
                f"{u['name']}: {len(u['joints'])} joints, period {p * 1e3:g} ms ({1 / p:g} Hz), "
                f"clock {u['clock']}, task {u['task']}"
            )
            lines += table([("config", str(u["config"])), ("telemetry", str(u["telemetry"]))], "  ")
            lines += ["  " + line for line in _resource(u["description"])]
            lines += ["  " + line for line in _joint_limits(u)]
    else:
        lines = [
            f"robot {r['robot']}: {r['dof']} joints, control period {period * 1e3:g} ms ({1 / period:g} Hz)"
        ]
        lines += table([("config", str(r["config"])), ("telemetry", str(r["telemetry"]))], "  ")
        lines += _resource(r["resource"])
        lines += _joint_limits(r)
    m = r.get("mission")
    if m:
        lines.append(f"mission {m['name']} ({m['file']})")
        lines += table(
            [
                ("main procedure", str(m["main_procedure"])),
                ("automaton", f"{m['states']} states, {m['transitions']} transitions"),
                ("operator inputs", ", ".join(m["operator_inputs"]) or "none"),
                ("inputs", f"{len(m['inputs'])} (events of the tasks and operator inputs)"),
            ],
            "  ",
        )
    else:
        lines.append("mission: none loaded (`orccadctl load FILE`)")
    params = (ctx.get("params") or {}).get("params")
    on = _task_resources(m, len(units) > 1)
    if params:
        lines.append("tasks: modules and their parameters (values: `orccadctl params TASK`)")
        lines += table(_modules({f"{t}{on.get(t, '')}": p for t, p in params.items()}), "  ")
    else:
        lines.append("tasks: " + ", ".join(f"{t}{on.get(t, '')}" for t in r["tasks"]))
    if r.get("fault"):
        lines.append(f"fault: {cause_words(r['fault'])} (`reset` needed)")
    if r.get("log"):
        lines.append("recent")
        lines += ["  " + str(n) for n in r["log"]]
    return "\n".join(lines)


def _task_resources(mission: dict[str, Any] | None, station: bool) -> dict[str, str]:
    """In a station, " (on RESOURCE)" by task name, from the mission's description; else nothing."""
    if not mission or not station:
        return {}
    pairs = zip(mission.get("tasks") or [], mission.get("task_resources") or [], strict=False)
    return {t: f" (on {res})" for t, res in pairs}


def _modules(params: dict[str, list[dict[str, Any]]]) -> list[tuple[str, ...]]:
    """(task, module, its parameters) rows, each task and module named once."""
    rows: list[tuple[str, ...]] = []
    for task, plist in params.items():
        modules: dict[str, list[str]] = {}
        for p in plist:
            module, _, name = str(p["name"]).rpartition(".")
            modules.setdefault(module, []).append(name + ("" if p.get("tunable", True) else " (fixed)"))
        for i, (module, names) in enumerate(modules.items()):
            rows.append((task if i == 0 else "", module, ", ".join(names)))
    return rows


RESOURCE_SHOWN = {
    "backend", "modes", "mode_switch_needs_disable", "position", "velocity", "torque", "brakes",
    "stop_categories", "read_time_s", "write_time_s", "clock", "device_period_s", "fault_reset",
    "fault_injection", "diagnostics", "protocol_version", "signals", "inputs", "outputs", "tool",
}  # fmt: skip


def _resource(res: dict[str, Any]) -> list[str]:
    d = res.get("diagnostics") or {}
    status = ", ".join(d.get("status") or []) or "ok"
    head = f"resource {res['backend']}: {d.get('lifecycle', '?')}, mode {d.get('mode', '?')}, status {status}"
    clock = str(res["clock"])
    if res.get("device_period_s"):
        clock += f" (the device's cycle, {float(res['device_period_s']) * 1e3:g} ms)"
    switch = "motors disabled to switch" if res["mode_switch_needs_disable"] else "switched live"
    rows = [
        ("modes", f"{', '.join(res['modes'])} ({switch})"),
        ("measures", f"position {res['position']}, velocity {res['velocity']}, torque {res['torque']}"),
        ("brakes", "yes" if res["brakes"] else "no"),
        ("stop categories", ", ".join(str(c) for c in res["stop_categories"])),
        ("clock", clock),
        ("bus time", f"read {num(res['read_time_s'])} s, write {num(res['write_time_s'])} s"),
        ("fault reset", "yes" if res["fault_reset"] else "no"),
        ("fault injection", ", ".join(res["fault_injection"]) or "none"),
    ]
    rows += [("signal", str(g)) for g in res.get("signals") or []]
    rows += _tool(res.get("tool"))
    if res.get("inputs") or res.get("outputs"):
        rows.append(
            (
                "digital I/O",
                f"inputs {', '.join(res.get('inputs') or []) or 'none'}; "
                f"outputs {', '.join(res.get('outputs') or []) or 'none'}",
            )
        )
    rows += [(k, str(v)) for k, v in res.items() if k not in RESOURCE_SHOWN]
    if d.get("fault_message") or d.get("fault_code"):
        rows.append(("device fault", f"{d.get('fault_message')} (code {d.get('fault_code')})"))
    if d.get("helper_pid"):
        rows.append(("helper pid", str(d["helper_pid"])))
    # the live details, less what the description already said (a chain's port and baud rate)
    rows += [(str(k), num(v)) for k, v in (d.get("details") or {}).items() if k not in res]
    return [head, *table(rows, "  ")]


def _tool(t: dict[str, Any] | None) -> list[tuple[str, str]]:
    """The tool the Cartesian tasks move, its limits and workspace, where its wrench comes from."""
    if not t:
        return []
    at = f"{t['urdf_frame']}" + (f" + {num(t['offset_m'])} m" if any(t["offset_m"]) else "")
    if any(t["offset_rpy_rad"]):
        at += f", turned rpy {num(t['offset_rpy_rad'])} rad"
    limits = (
        f"{num(t['max_linear_velocity_m_s'])} m/s, {num(t['max_linear_acceleration_m_s2'])} m/s^2; "
        f"{num(t['max_angular_velocity_rad_s'])} rad/s; "
        f"{num(t['max_force_n'])} N, {num(t['max_torque_nm'])} N.m"
    )
    w = t.get("workspace")
    parts = []
    if w and w["box_min_m"]:
        parts.append(f"box {num(w['box_min_m'])}..{num(w['box_max_m'])} m")
    if w and w["sphere_radius_m"]:
        parts.append(f"sphere of {num(w['sphere_radius_m'])} m about {num(w['sphere_center_m'])} m")
    space = " and ".join(parts) + f" (± {num(w['tolerance_m'])} m)" if w else "none configured"
    return [("tool", at), ("tool limits", limits), ("workspace", space), ("wrench", str(t["wrench"]))]


def _load(r: dict[str, Any], _: dict[str, Any]) -> str:
    m = r["mission"]
    return (
        f"loaded mission {m['name']} from {m['file']}; `orccadctl start` runs {m['main_procedure']}\n"
        + str(r["report"])
    )


def _joint_limits(r: dict[str, Any]) -> list[str]:
    limits = r.get("joint_limits")
    if not limits:  # a daemon before protocol 4 names the joints only
        return ["joints", *table([(str(i), str(name)) for i, name in enumerate(r["joints"])], "  ")]
    head = ("joint", "q min rad", "q max rad", "v max rad/s", "a max rad/s^2", "tau max N.m")
    rows = [head] + [
        (
            str(j["name"]),
            *(
                f"{float(j[k]):.4g}"
                for k in ("position_min_rad", "position_max_rad", "max_velocity_rad_s",
                          "max_acceleration_rad_s2", "max_torque_nm")
            ),
        )
        for j in limits
    ]  # fmt: skip
    return ["joints", *table(rows, "  ")]


def _start(r: dict[str, Any], ctx: dict[str, Any]) -> str:
    return f"started mission {r['mission']} (procedure {r['started']}, run {r['run']})"


def _tune(r: dict[str, Any], ctx: dict[str, Any]) -> str:
    """In one round trip: the reply names the value applied, its unit and the tick."""
    unit = "" if r["unit"] in ("", "1") else " " + str(r["unit"])
    change = f"{num(r['previous'])} → {num(r['value'])}{unit}"
    where = f"applied at tick {r['applied_at_tick']}"
    if r.get("task_active") is False:
        task = str(r["tuned"]).split(".", 1)[0]
        where += f"; {task} is not running now: it takes effect the next time it runs"
    return f"{r['tuned']}: {change} ({where})"


def _stop(r: dict[str, Any], _: dict[str, Any]) -> str:
    if r["stopped"]:
        return f"stopped: the mission has ended, orccadd is {r['state']}"
    return f"Stop sent: the mission is still {r['state']} (its Stop handling goes on)"


def _reset(r: dict[str, Any], _: dict[str, Any]) -> str:
    if not r["reset"]:
        return f"reset: {r.get('detail') or 'nothing done'}"
    if r.get("resources"):
        names = ", ".join(r["resources"])
        return f"reset: {names}: the safe stops are cleared; each Hold task holds its resource"
    return "reset: the safe stop is cleared; the Hold task holds the arm"


def _resume(r: dict[str, Any], _: dict[str, Any]) -> str:
    task = r.get("resumed")
    if task:
        return f"resumed: {task} restarts from the measured state"
    return "resumed: no task was active (the mission's next reaction chooses one)"


def _params(r: dict[str, Any], _: dict[str, Any]) -> str:
    return "\n".join(param_lines(r["params"]))


def _events(r: dict[str, Any], _: dict[str, Any]) -> str:
    lines = [format_trace(e) for e in r["events"]]
    if r.get("lost"):
        lines.append(f"({r['lost']} records lost: the trace ring was overwritten before they were read)")
    return "\n".join(lines) if lines else "no events yet"


def _log(r: dict[str, Any], ctx: dict[str, Any]) -> str:
    if ctx.get("args", {}).get("action") == "start":
        files = ", ".join(r.get("files") or [r["file"]])
        return f"logging {len(r['signals'])} signals to {files} (`log stop -o FILE` copies it to FILE)"
    text = f"log: {r['rows']} rows ({r['lost']} lost) in {', '.join(r.get('files') or [r['file']])}"
    if r.get("mcap"):  # the same run for Foxglove, when the daemon writes it
        text += f", MCAP {', '.join(r['mcap'])}"
    if r.get("gap"):
        text += f"; {r['gap']}"
    return text + (f"; then: {r['error']}" if r.get("error") else "")


FORMATTERS: dict[str, Formatter] = {
    "status": lambda r, _: format_status(r),
    "describe": _describe,
    "params": _params,
    "events": _events,
    "load": _load,
    "start": _start,
    "stop": _stop,
    "abort": lambda r, _: (
        "aborted: safe stop at the next tick, the mission ends `aborted`; "
        "`orccadctl reset` once the arm is at rest"
    ),
    "hold": lambda r, _: (
        "holding: the mission is suspended, the Hold task holds the arm "
        "(`orccadctl resume` restarts the task)"
    ),
    "resume": _resume,
    "reset": _reset,
    "send": lambda r, _: f"sent {r['sent']}",
    "tune": _tune,
    "log": _log,
    "inject": lambda r, _: f"injected fault: {r['injected']} on {r.get('resource', 'the arm')}",
}
