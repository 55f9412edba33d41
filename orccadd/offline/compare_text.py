"""The words of `orccadctl compare`'s report (from `Report.as_json()`, so that the text and
`--json` say the same): the two runs, the trace, a table per task, the verdict."""

from __future__ import annotations

import math
from typing import Any


def compare_text(rep: dict[str, Any]) -> str:
    a, b = rep["a"], rep["b"]
    lines = [
        f"A {a['file']} ({_when(a)})",
        f"B {b['file']} ({_when(b)})",
        f"one mission: {rep['mission']['what']}",
    ]
    tr = rep["trace"]
    if tr["same"]:
        lines.append(f"trace: the same ({tr['instants'][0]} instants, inputs and actions alike)")
    else:
        d = tr["first_divergence"]
        lines.append(
            f"trace: differs at instant {d['n']} (A {tr['instants'][0]} instants, B {tr['instants'][1]})"
        )
        for side in ("a", "b"):
            lines.append(f"  {side.upper()}: {_instant(d[side]) if side in d else '(no such instant)'}")
    for t in rep["tasks"]:
        lines.extend(_task(t))
    diffs = rep["differences"]
    tol = rep["tolerances"]
    tau = "not judged" if tol["tau_nm"] is None else f"{tol['tau_nm']:g} N.m (p95 of |B - A|)"
    timing = "not judged" if tol["timing_us"] is None else f"p99 ±{tol['timing_us']:g} us"
    lines.append(
        f"tolerances: duration ±max({tol['duration_s']:g} s, {tol['duration_pct']:g} %), tracking error "
        f"±{tol['tracking_rad']:g} rad (RMS and p95), position {tol['q_rad']:g} rad, command "
        f"{tol['cmd_rad']:g} rad / {tol['cmd_nm']:g} N.m (p95 of |B - A|), torque {tau}, timing {timing}"
    )
    if not diffs:
        lines.append("verdict: the same within the tolerances")
    else:
        lines.append(f"verdict: different ({len(diffs)} difference{'s' if len(diffs) > 1 else ''})")
        lines.extend(f"  - {d['text']}" for d in diffs)
    return "\n".join(lines)


def _when(r: dict[str, Any]) -> str:
    return ", ".join(str(x) for x in (r.get("start_utc"), r.get("robot")) if x) or "no header"


def _instant(i: dict[str, Any]) -> str:
    acts = " ".join(i["actions"]) or "(no action)"
    return f"{i['inputs']} -> {acts} (state {i['from']} -> {i['to']}) at {i['time_s']:.3f} s"


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "-" if v is None or math.isnan(v) else format(v, fmt)


def _task(t: dict[str, Any]) -> list[str]:
    d = t["duration_s"]
    stopped = "" if all(t["stopped"]) else " (not stopped in " + ("A" if not t["stopped"][0] else "B") + ")"
    mode = t["mode"][0] if t["mode"][0] == t["mode"][1] else f"{t['mode'][0]} in A, {t['mode'][1]} in B"
    out = [
        f"task {t['task']}: {d['a']:.3f} s in A, {d['b']:.3f} s in B ({d['diff']:+.3f} s){stopped}; {mode}"
    ]
    tra, trb = t["tracking"]["a"], t["tracking"]["b"]
    cmd, tau, qd = t["cmd_diff"], t["tau_diff"], t["q_diff"]
    unit = {"position": "rad", "torque": "N.m", "velocity": "rad/s"}.get(t["mode"][0], "?")
    joints = list(dict.fromkeys([*tra.get("rms_rad", {}), *cmd.get("rms", {}), *tau.get("rms", {})]))
    notes = []
    if "unavailable" in tra or "unavailable" in trb:
        notes.append(f"tracking error: {tra.get('unavailable') or trb.get('unavailable')}")
    else:
        notes.append(f"tracking error: {tra['signals']}, rad")
    for name, dd in (("position (q)", qd), ("command", cmd), ("torque (tau)", tau)):
        if "unavailable" in dd:
            notes.append(f"{name} difference: {dd['unavailable']}")
        else:
            notes.append(f"{name} difference B - A over {dd['over_s']:.3f} s from the task's start")
    out.extend(f"  {n}" for n in notes)
    if joints:
        head = f"  {'joint':<20s} {'tracking RMS A / B':>19s} {'tracking max A / B':>19s}"
        out.append(
            f"{head} {'q B-A RMS/p95/max':>22s} {'cmd B-A RMS/p95/max':>22s} {'tau B-A RMS/p95/max':>22s}"
        )
        out.append(f"  {'':<20s} {'rad':>19s} {'rad':>19s} {'rad':>22s} {unit:>22s} {'N.m':>22s}")
        for j in joints:
            track = f"{_two(tra, trb, 'rms_rad', j):>19s} {_two(tra, trb, 'max_rad', j):>19s}"
            out.append(f"  {j:<20s} {track} {_three(qd, j):>22s} {_three(cmd, j):>22s} {_three(tau, j):>22s}")
    for side in ("a", "b"):
        tm = t["timing"][side]
        if tm:
            parts = [f"{k} {v['median']:.0f} / {v['p99']:.0f} / {v['max']:.0f}" for k, v in tm.items()]
            out.append(f"  timing {side.upper()} (median / p99 / max, us): {'; '.join(parts)}")
    return out


def _two(x: dict[str, Any], y: dict[str, Any], key: str, joint: str) -> str:
    return f"{_num(x.get(key, {}).get(joint))} / {_num(y.get(key, {}).get(joint))}"


def _three(d: dict[str, Any], joint: str) -> str:
    return "/".join(_num(d.get(k, {}).get(joint), ".3g") for k in ("rms", "p95", "max"))
