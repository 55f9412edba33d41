"""`orccadctl compare A.mcap B.mcap`: two runs of one mission (the simulated arm and the robot;
before and after a change), offline.

- The reactive traces, instant by instant (inputs and actions, in order): the same, or the
  first instant where they differ, with both sides.
- Per task (its windows from the trace, paired by name and occurrence): its duration in each
  run; the tracking error in each (q − cmd at the ticks whose command is a position: RMS, p95
  and max per joint); the measured position's, the command's and the measured torque's
  difference between the runs (the position's: a torque task's only reference), aligned
  on time since the task's start (B interpolated at A's times, over the shorter of the two);
  the loop's timing (wake_us, compute_us: median, p99, max) where logged.
- A verdict against `Tolerances`: `findings` lists every difference beyond them.

The report is a JSON-able dict (`Report.data`); `compare_text` words it.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from orccadd.offline.runs import Run, TaskWindow, same_mission
from orccadd.offline.tolerances import Tolerances

CMD_UNITS = {"position": "rad", "velocity": "rad/s", "torque": "N.m"}
TIMING = ("wake_us", "compute_us")
RUN_RECORD = ("mission", "mission_file", "mission_deployment", "config_sha256", "orccadd_version")


@dataclass(frozen=True)
class Finding:
    """One difference beyond its tolerance."""

    kind: str  # trace, task, duration, mode, tracking, cmd, tau, timing
    task: str
    text: str


@dataclass
class Report:
    data: dict[str, Any]
    findings: list[Finding] = field(default_factory=list)

    @property
    def same(self) -> bool:
        return not self.findings

    def as_json(self) -> dict[str, Any]:
        """The report as JSON takes it (NaN, where a statistic has no sample: null)."""
        out: dict[str, Any] = _clean({
            "verdict": "same" if self.same else "different",
            **self.data,
            "differences": [asdict(f) for f in self.findings],
        })  # fmt: skip
        return out


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def compare_runs(a: Run, b: Run, tol: Tolerances) -> Report:
    """The comparison of two runs (`RunError` if they are not of one mission)."""
    how, mission = same_mission(a, b)
    data: dict[str, Any] = {
        "a": _run_info(a),
        "b": _run_info(b),
        "mission": {"told_by": how, "what": mission, "a": a.mission, "b": b.mission},
        "tolerances": asdict(tol),
    }
    rep = Report(data)
    data["trace"] = _trace(a, b, rep)
    wb = {w.key: w for w in b.windows}
    tasks = []
    for w in a.windows:
        if w.key in wb:
            tasks.append(_task(a, w, b, wb[w.key], tol, rep))
        else:
            rep.findings.append(Finding("task", w.key, f"{w.key} ran in A only"))
    for w in b.windows:
        if w.key not in {x.key for x in a.windows}:
            rep.findings.append(Finding("task", w.key, f"{w.key} ran in B only"))
    data["tasks"] = tasks
    return rep


def _run_info(r: Run) -> dict[str, Any]:
    return {
        "file": str(r.path),
        "start_utc": r.log.meta.get("start_utc"),
        "robot": r.log.meta.get("robot"),
        "instants": len(r.instants),
        "tasks": [w.key for w in r.windows],
        "signals": sorted({c.partition(".")[0] for c in r.log.columns[1:]}),
    } | {k: r.log.meta[k] for k in RUN_RECORD if r.log.meta.get(k)}


def _instant(i: Any) -> dict[str, Any]:
    return {"n": i.n, "time_s": round(i.time_s, 6), "inputs": i.inputs, "actions": list(i.actions),
            "from": i.src, "to": i.dst}  # fmt: skip


def _trace(a: Run, b: Run, rep: Report) -> dict[str, Any]:
    out: dict[str, Any] = {"instants": [len(a.instants), len(b.instants)], "first_divergence": None}
    for ia, ib in zip(a.instants, b.instants, strict=False):
        if not ia.same_reaction(ib):
            out["first_divergence"] = {"n": ia.n, "a": _instant(ia), "b": _instant(ib)}
            rep.findings.append(
                Finding("trace", "", f"instant {ia.n} differs: A {ia.words()}; B {ib.words()}")
            )
            break
    else:
        if len(a.instants) != len(b.instants):
            longer, name = (a, "A") if len(a.instants) > len(b.instants) else (b, "B")
            n = min(len(a.instants), len(b.instants))
            extra = longer.instants[n]
            out["first_divergence"] = {"n": n + 1, name.lower(): _instant(extra)}
            rep.findings.append(
                Finding(
                    "trace",
                    "",
                    f"instant {n + 1} only in {name}: {extra.words()} "
                    f"(A {len(a.instants)} instants, B {len(b.instants)})",
                )
            )
    out["same"] = out["first_divergence"] is None
    return out


def _task(a: Run, wa: TaskWindow, b: Run, wb: TaskWindow, tol: Tolerances, rep: Report) -> dict[str, Any]:
    key = wa.key
    da, db = wa.end_s(a.end_s) - wa.start_s, wb.end_s(b.end_s) - wb.start_s
    out: dict[str, Any] = {
        "task": key,
        "duration_s": {"a": round(da, 6), "b": round(db, 6), "diff": round(db - da, 6)},
        "stopped": [wa.stop_s is not None, wb.stop_s is not None],
    }
    allowed = max(tol.duration_s, tol.duration_pct / 100.0 * max(da, db))
    if abs(db - da) > allowed:
        rep.findings.append(
            Finding(
                "duration",
                key,
                f"{key}: {da:.3f} s in A, {db:.3f} s in B ({db - da:+.3f} s, beyond ±{allowed:.3f} s)",
            )
        )
    if (wa.stop_s is None) != (wb.stop_s is None):
        rep.findings.append(Finding("task", key, f"{key}: stopped in {'A' if wa.stop_s else 'B'} only"))
    ma, mb = _task_mode(a, wa), _task_mode(b, wb)
    out["mode"] = [ma, mb]
    if ma != mb:
        rep.findings.append(Finding("mode", key, f"{key}: command mode {ma} in A, {mb} in B"))
    out["tracking"] = {"a": _tracking(a, wa), "b": _tracking(b, wb)}
    _judge_tracking(key, out["tracking"], tol, rep)
    out["cmd_diff"] = (
        _aligned_diff(a, wa, b, wb, "cmd") if ma == mb else {"unavailable": "command modes differ"}
    )
    if ma in ("position", "torque"):
        limit = tol.cmd_rad if ma == "position" else tol.cmd_nm
        _judge_diff(key, "cmd", f"{ma} command", out["cmd_diff"], limit, CMD_UNITS[ma], rep)
    # the motions themselves: for a torque task, the only reference q has in a log
    out["q_diff"] = _aligned_diff(a, wa, b, wb, "q")
    _judge_diff(key, "q", "measured position", out["q_diff"], tol.q_rad, "rad", rep)
    out["tau_diff"] = _aligned_diff(a, wa, b, wb, "tau")
    if tol.tau_nm is not None:
        _judge_diff(key, "tau", "measured torque", out["tau_diff"], tol.tau_nm, "N.m", rep)
    out["timing"] = {"a": _timing(a, wa), "b": _timing(b, wb)}
    if tol.timing_us is not None:
        _judge_timing(key, out["timing"], tol.timing_us, rep)
    return out


def _task_mode(r: Run, w: TaskWindow) -> str:
    """The command mode of most of a task's ticks (`?` when the log has no mode events)."""
    modes = Counter(r.mode_at(r.t[r.rows(w)]).tolist())
    return str(modes.most_common(1)[0][0]) if modes else "?"


def _stats(v: np.ndarray) -> tuple[float, float, float]:
    """RMS, 95th percentile and max of |v| over the finite values."""
    v = np.abs(v[np.isfinite(v)])
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    return float(np.sqrt(np.mean(v * v))), float(np.percentile(v, 95)), float(np.max(v))


def _tracking(r: Run, w: TaskWindow) -> dict[str, Any]:
    """q − cmd at the task's ticks whose command is a position: RMS and max per joint, rad."""
    q, cmd = r.joint_cols("q"), r.joint_cols("cmd")
    if not q or not cmd:
        missing = " and ".join(s for s, c in (("q", q), ("cmd", cmd)) if not c)
        return {"unavailable": f"the log has no {missing} (`log start q cmd ...`)"}
    rows = r.rows(w)
    rows = rows[r.mode_at(r.t[rows]) == "position"]
    if rows.size == 0:
        return {"unavailable": "no position command in this task (the log has no other reference for q)"}
    rms: dict[str, float] = {}
    p95: dict[str, float] = {}
    mx: dict[str, float] = {}
    for joint, c in q.items():
        if joint in cmd:
            rms[joint], p95[joint], mx[joint] = _stats(r.log.data[rows, c] - r.log.data[rows, cmd[joint]])
    return {
        "signals": "q - cmd (position commands)",
        "ticks": int(rows.size),
        "rms_rad": rms,
        "p95_rad": p95,
        "max_rad": mx,
    }


def _aligned_diff(a: Run, wa: TaskWindow, b: Run, wb: TaskWindow, signal: str) -> dict[str, Any]:
    """B − A per joint, aligned on time since the task's start: B interpolated at A's ticks over
    the shorter of the two windows."""
    ca, cb = a.joint_cols(signal), b.joint_cols(signal)
    if not ca or not cb:
        return {"unavailable": f"{'A' if not ca else 'B'} has no {signal}"}
    span = min(wa.end_s(a.end_s) - wa.start_s, wb.end_s(b.end_s) - wb.start_s)
    ra, rb = a.rows(wa), b.rows(wb)
    ta, tb = a.t[ra] - wa.start_s, b.t[rb] - wb.start_s
    keep = ta <= span
    stats: dict[str, dict[str, float]] = {"rms": {}, "p95": {}, "max": {}}
    for joint, c in ca.items():
        if joint not in cb:
            continue
        ya, yb = a.log.data[ra, c], b.log.data[rb, cb[joint]]
        fb = np.isfinite(yb)
        if fb.sum() < 2:
            continue
        values = _stats(np.interp(ta[keep], tb[fb], yb[fb]) - ya[keep])
        for k, v in zip(stats, values, strict=True):
            stats[k][joint] = v
    if not stats["rms"]:
        return {"unavailable": f"too few {signal} samples in this task"}
    return {"over_s": round(span, 6), **stats}


def _timing(r: Run, w: TaskWindow) -> dict[str, Any]:
    rows = r.rows(w)
    out: dict[str, Any] = {}
    for name in TIMING:
        for res, c in r.scalar_cols(name).items():
            v = r.log.data[rows, c]
            v = v[np.isfinite(v)]
            if v.size:
                label = f"{res}/{name}" if res else name
                out[label] = {"median": float(np.median(v)), "p99": float(np.percentile(v, 99)),
                              "max": float(v.max())}  # fmt: skip
    return out


def _judge_tracking(key: str, tr: dict[str, Any], tol: Tolerances, rep: Report) -> None:
    """One finding per statistic (RMS, p95) naming every joint whose tracking error differs (its
    max is reported, not judged: one tick woken late makes it, in one run of two alike)."""
    ta, tb = tr["a"], tr["b"]
    if "unavailable" in ta or "unavailable" in tb:
        return
    for stat in ("rms_rad", "p95_rad"):
        beyond = [
            f"{joint} {va:.4g} / {tb[stat][joint]:.4g}"
            for joint, va in ta[stat].items()
            if joint in tb[stat] and abs(tb[stat][joint] - va) > tol.tracking_rad
        ]
        if beyond:
            what = f"{key}: tracking error ({stat[:3].upper()}, rad, A / B) beyond ±{tol.tracking_rad:g} rad"
            rep.findings.append(Finding("tracking", key, f"{what}: {', '.join(beyond)}"))


def _judge_diff(
    key: str, kind: str, what: str, d: dict[str, Any], limit: float, unit: str, rep: Report
) -> None:
    """One finding naming every joint whose difference's p95 is beyond `limit`."""
    if "unavailable" in d:
        return
    beyond = [f"{joint} {v:.4g} (max {d['max'][joint]:.4g})" for joint, v in d["p95"].items() if v > limit]
    if beyond:
        head = f"{key}: the {what} differs beyond {limit:g} {unit} (p95 of |B - A|, {unit})"
        rep.findings.append(Finding(kind, key, f"{head}: {', '.join(beyond)}"))


def _judge_timing(key: str, tm: dict[str, Any], limit_us: float, rep: Report) -> None:
    for label, sa in tm["a"].items():
        sb = tm["b"].get(label)
        if sb is not None and abs(sb["p99"] - sa["p99"]) > limit_us:
            rep.findings.append(
                Finding(
                    "timing",
                    key,
                    f"{key}: {label} p99 {sa['p99']:.0f} us in A, {sb['p99']:.0f} us in B "
                    f"(beyond ±{limit_us:g} us)",
                )
            )
