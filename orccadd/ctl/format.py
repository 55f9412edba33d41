"""Text for people: one line per trace record (what `orccadctl events` and the demo print)."""

from __future__ import annotations

from typing import Any


def format_trace(e: dict[str, Any]) -> str:
    head = f"{e['time']} t={e['t_s']:.3f}"
    if e["kind"] == "instant":
        ins = ", ".join(e["inputs"]) or "-"
        acts = ", ".join(e["actions"]) or "-"
        return f"{head}  instant {e['from']}->{e['to']}  inputs {{{ins}}}  actions {{{acts}}}"
    if e["kind"] == "event":
        return f"{head}  event   {e['event']}"
    return f"{head}  command {e['command']}"
