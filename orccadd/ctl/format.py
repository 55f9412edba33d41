"""Text for people: trace records, status, parameters, numbers (what `orccadctl` and the demo
print). Every word for a state is the daemon's own (`idle`, `ready`, `running`, `holding`,
`faulted`, `safe`, ...): a person reading `status`, `events` and `top` meets the same names."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from orccadd.fault import cause_words
from orccadd.wire.schema import tune_words

PROG = "orccadctl"


def error_line(message: str) -> str:
    """An error as orccadctl prints it: the daemon's (or the client's) words, verbatim."""
    return f"{PROG}: error: {message}"


def format_trace(e: dict[str, Any]) -> str:
    head = f"{e['time']} t={e['t_s']:.3f}"
    if e["kind"] == "instant":
        ins = ", ".join(e["inputs"]) or "-"
        acts = ", ".join(e["actions"]) or "-"
        return f"{head}  instant {e['from']}->{e['to']}  inputs {{{ins}}}  actions {{{acts}}}"
    if e["kind"] == "event":
        return f"{head}  event   {e['event']}"
    if e["kind"] == "fault":
        return f"{head}  fault   {cause_words(e['fault'])}"
    if e.get("tune"):
        return f"{head}  command tune {tune_words(e['tune'])}"
    return f"{head}  command {e['command']}"


def num(v: Any) -> str:
    """A number in few characters (%g); a list of equal numbers as `v (×n)`."""
    if isinstance(v, list):
        if v and all(x == v[0] for x in v) and len(v) > 1:
            return f"{num(v[0])} (×{len(v)})"
        return "[" + ", ".join(num(x) for x in v) + "]"
    if isinstance(v, bool) or not isinstance(v, int | float):
        return str(v)
    return f"{v:g}"


def bounds(b: Any) -> str:
    """`[lo, hi]`; per element (lists) as `±[h0, h1, ...]` when symmetric, else `[lo] .. [hi]`."""
    if not (isinstance(b, list) and len(b) == 2):
        return num(b)
    lo, hi = b
    if isinstance(lo, list) and isinstance(hi, list):
        if all(x == v[0] for v in (lo, hi) for x in v):
            return f"[{num(lo[0])}, {num(hi[0])}]"
        if [-x for x in lo] == hi:
            return "±" + num(hi)
        return f"{num(lo)} .. {num(hi)}"
    return f"[{num(lo)}, {num(hi)}]"


def state_words(s: dict[str, Any]) -> str:
    """The machine's state as status names it, with the safe procedure made visible: a faulted
    arm while the mission still runs is the mission's safe procedure running."""
    state = str(s.get("state"))
    if s.get("faulted"):
        return f"{state} (safe procedure), faulted" if state == "running" else f"{state}, faulted"
    return state


def joint_lines(s: dict[str, Any]) -> list[str]:
    lines = [f"{'joint':22s} {'q rad':>10s} {'dq rad/s':>10s} {'tau N.m':>10s} {'cmd':>10s}"]
    for j in s.get("joints", []):
        lines.append(
            f"{j['name']:22s} {j['q_rad']:10.4f} {j['dq_rad_s']:10.4f} {j['tau_nm']:10.2f} {j['cmd']:10.2f}"
        )
    return lines


def timing_line(s: dict[str, Any]) -> str:
    t = s.get("timing") or {}
    head = f"{s['ticks']} ticks, {s['overruns']} overruns, {s['switches']} switches"
    if not t:
        return head
    return (
        f"{head}; wake-up median {t['wake_median_us']} p99 {t['wake_p99_us']} max {t['wake_max_us']} µs; "
        f"compute median {t['compute_median_us']} p99 {t['compute_p99_us']} µs"
    )


def format_status(s: dict[str, Any]) -> str:
    automaton = f", automaton state {s['automaton_state']}" if s["automaton_state"] >= 0 else ""
    head = (
        f"{s.get('robot')}: {state_words(s)}"
        + (f", mission {s['mission']}" if s.get("mission") else "")
        + automaton
        + (f"; fault: {cause_words(s.get('fault'))} (`reset` needed)" if s.get("faulted") else "")
    )
    if s.get("resources"):  # a station: each resource, its loop and joints
        lines = [head, f"last result {s['result']}"]
        for r in s["resources"]:
            fault = f"; fault: {cause_words(r['fault'])}" if r.get("fault") else ""
            lines += [
                "",
                f"{r['name']}: task {r.get('active_task')} ({r.get('task_phase')}), "
                f"resource {', '.join(r.get('resource_status') or ['ok'])}{fault}",
                "  loop: " + timing_line(r),
                *("  " + line for line in joint_lines(r)),
            ]
    else:
        lines = [
            head,
            f"active task {s.get('active_task')} ({s.get('task_phase')}), last result {s['result']}, "
            f"resource {', '.join(s.get('resource_status') or ['ok'])}",
            "loop: " + timing_line(s),
            *joint_lines(s),
        ]
    if s.get("log"):
        lg = s["log"]
        lines.append(
            f"log: {', '.join(lg.get('files') or [lg['file']])} ({lg['rows']} rows, {lg['lost']} lost)"
        )
    return "\n".join(lines)


def table(rows: Iterable[tuple[str, ...]], indent: str = "") -> list[str]:
    """Rows aligned in columns (the last column unpadded)."""
    rows = list(rows)
    if not rows:
        return []
    widths = [max(len(r[i]) for r in rows if len(r) > i) for i in range(max(len(r) for r in rows))]
    out = []
    for r in rows:
        cells = [c.ljust(widths[i]) for i, c in enumerate(r[:-1])] + [r[-1]]
        out.append((indent + "  ".join(cells)).rstrip())
    return out


def param_lines(params: dict[str, list[dict[str, Any]]], indent: str = "") -> list[str]:
    """Each task, then its parameters by module: value, unit, bounds, tunable or fixed."""
    lines: list[str] = []
    for task, plist in params.items():
        lines.append(f"{indent}{task}")
        rows: list[tuple[str, ...]] = []
        last_module = ""
        for p in plist:
            module, _, name = str(p["name"]).rpartition(".")
            shown = module if module != last_module else ""
            last_module = module
            flag = "" if p.get("tunable", True) else "  (fixed)"
            rows.append((shown, name, num(p["value"]), str(p["unit"]), f"in {bounds(p['bounds'])}{flag}"))
        lines.extend(table(rows, indent + "  "))
    return lines
