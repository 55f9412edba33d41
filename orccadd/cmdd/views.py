"""What the command daemon reads out of the real-time process's telemetry block.

Status, monitor samples, the reactive trace and full-rate logs are all built here, from shared
memory, without asking the real-time process anything (it is only asked to `describe` itself
when a new mission was loaded, to learn the names behind the indices).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from orccadd.wire.schema import (
    TICK_FIELDS,
    TICK_VECTORS,
    TRACE_IDX,
    H,
    MachineState,
    MissionResult,
    OperatorAction,
    Phase,
    R,
    S,
    T,
    TickLayout,
    Trace,
    TuneRecord,
    status_names,
)
from orccadd.wire.telemetry import TelemetryBlock, read_status


class SignalSelection:
    """Signal names → columns of a tick record: `q`, `dq.3`, `tau.elbow_joint`, `wake_us`, ...
    In a station, one resource's (`resource`): its labels are named by it (`left/q.elbow_joint`),
    and a name may be so too."""

    def __init__(
        self,
        names: list[str],
        joints: list[str],
        resource: str = "",
        signals: Sequence[Mapping[str, Any]] = (),
    ) -> None:
        """`signals`: the resource's own (`describe`'s `tick_signals`: name, size, unit), after
        the joint vectors in each tick's record: `wrench` (all its values, `wrench.0` ...) or
        `wrench.2` (one)."""
        n = len(joints)
        self.joints = joints
        self.signals = [
            {"name": str(g["name"]), "size": int(g["size"]), "unit": str(g["unit"])} for g in signals
        ]
        self.units = {str(g["name"]): str(g["unit"]) for g in self.signals}  # the signals' own units
        layout = TickLayout(n, [(str(g["name"]), int(g["size"])) for g in signals])
        prefix = f"{resource}/" if resource else ""
        cols: list[int] = []
        labels: list[str] = []
        for named in names or ["q"]:
            raw = named.removeprefix(prefix) if prefix else named
            base, _, idx = raw.partition(".")
            if base in TICK_FIELDS and not idx and base != "seq":
                cols.append(TICK_FIELDS.index(base))
                labels.append(prefix + base)
                continue
            if base in layout.signals:
                where = layout.signals[base]
                size = where.stop - where.start
                if idx and not (idx.isascii() and idx.isdigit() and int(idx) < size):
                    raise ValueError(f"signal {raw!r}: {base} has {size} values (0..{size - 1})")
                for k in [int(idx)] if idx else range(size):
                    cols.append(where.start + k)
                    labels.append(f"{prefix}{base}.{k}" if size > 1 else prefix + base)
                continue
            if base not in TICK_VECTORS:
                allowed = ", ".join([*TICK_FIELDS[1:], *TICK_VECTORS, *layout.signals])
                raise ValueError(
                    f"unknown signal {raw!r} (signals: {allowed}; a joint: q.0 or q.<joint name>)"
                )
            start = layout.vector(base).start
            if not idx:
                picked = list(range(n))
            elif idx.isascii() and idx.isdigit() and int(idx) < n:  # not `q.٣`: ASCII digits only
                picked = [int(idx)]
            elif idx in joints:
                picked = [joints.index(idx)]
            else:
                raise ValueError(f"signal {raw!r}: no joint {idx!r} (0..{n - 1} or {', '.join(joints)})")
            for j in picked:
                cols.append(start + j)
                labels.append(f"{prefix}{base}.{joints[j]}")
        # a column named twice (`q q.0`, 12,000 × `q`) is sampled once: a selection is never wider
        # than the tick record, however long the list of names
        first = dict.fromkeys(range(len(cols)))
        seen: set[int] = set()
        for i, c in enumerate(cols):
            if c in seen:
                first.pop(i)
            seen.add(c)
        self.cols = [cols[i] for i in first]
        self.labels = [labels[i] for i in first]

    def values(self, rec: np.ndarray) -> list[float]:
        return [float(rec[c]) for c in self.cols]


def cell_selections(
    names: list[str],
    resources: list[tuple[str, list[str]]],
    signals: Mapping[str, Sequence[Mapping[str, Any]]] | None = None,
) -> dict[str, SignalSelection]:
    """A station's signals, by resource (name, joints), for those any name picks from: `left/q` is
    resource left's only; an unnamed one is every resource's that has it (`q` all of them,
    `q.finger` the one with that joint). `signals`: each resource's own (`tick_signals`), which
    a name picks from through its resource (`left/wrench`). `ValueError` naming what matches
    nothing."""
    known = [r for r, _ in resources]
    picks: dict[str, list[str]] = {r: [] for r in known}
    for raw in names or ["q"]:
        owner, slash, signal = raw.partition("/")
        if slash:
            if owner not in picks:
                raise ValueError(f"signal {raw!r}: no resource {owner!r} (resources: {', '.join(known)})")
            picks[owner].append(signal)
            continue
        idx = raw.partition(".")[2]
        having = [
            r
            for r, joints in resources
            if not idx or idx in joints or (idx.isascii() and idx.isdigit() and int(idx) < len(joints))
        ]
        if not having:
            raise ValueError(f"signal {raw!r}: no resource has joint {idx!r} (a resource's: left/q.0)")
        for r in having:
            picks[r].append(raw)
    joints_of = dict(resources)
    own = signals or {}
    return {r: SignalSelection(p, joints_of[r], r, own.get(r, ())) for r, p in picks.items() if p}


LATEST_BACK = 8  # records looked back for a consistent one


def latest_tick(tel: TelemetryBlock) -> np.ndarray | None:
    """A consistent copy of the newest tick record the ring holds (None before the first tick).
    The newest may be being written: then the one before, and so on back a few records."""
    for _ in range(10):
        head = int(tel.header[H.TICK_HEAD])
        if head == 0:
            return None
        for seq in range(head, max(0, head - LATEST_BACK), -1):
            slot = tel.ticks[(seq - 1) % tel.tick_len]
            rec = slot.copy()
            if rec[0] == seq and slot[0] == seq:
                return rec  # type: ignore[no-any-return]
    return None


def timing(tel: TelemetryBlock, window_s: float = 5.0) -> dict[str, float]:
    """Wake-up latency and compute time over the last `window_s` of ticks (µs)."""
    head = int(tel.header[H.TICK_HEAD])
    n = min(head, tel.tick_len, max(1, int(window_s / tel.period_s)))
    if n == 0:
        return {}
    idx = np.arange(head - n, head) % tel.tick_len
    rec = tel.ticks[idx]
    wake, comp = rec[:, T.WAKE_US], rec[:, T.COMPUTE_US]
    out: dict[str, float] = {"window_ticks": float(n)}
    for name, arr in (("wake", wake), ("compute", comp)):
        q = np.percentile(arr, [50, 99])
        out[f"{name}_median_us"] = round(float(q[0]), 1)
        out[f"{name}_p99_us"] = round(float(q[1]), 1)
        out[f"{name}_max_us"] = round(float(arr.max()), 1)
    return out


def status(
    block: TelemetryBlock,
    tel: TelemetryBlock,
    desc: dict[str, Any],
    log: dict[str, Any] | None,
    units: Sequence[tuple[dict[str, Any], TelemetryBlock]] = (),
) -> dict[str, Any]:
    """The daemon's state from its own block's status area (`block`), the loop of the resource a
    client addresses when it names none from that resource's block (`tel`), and, for several
    resources (`units`: each one's description and block), `resources`: each one's task, status,
    timing and joints from its own block."""
    st = read_status(block)
    out: dict[str, Any] = {
        "robot": desc.get("robot"),
        "state": MachineState(int(st[S.MACHINE])).name.lower(),
        "mission": (desc.get("mission") or {}).get("name"),
        "automaton_state": int(st[S.AUTOMATON_STATE]),
        "instants": int(st[S.INSTANTS]),
        "result": MissionResult(int(st[S.RESULT])).name.lower(),
        "faulted": bool(st[S.FAULTED]),
        "fault": desc.get("fault") or None if st[S.FAULTED] else None,  # why, in words
        "helper_pid": int(st[S.HELPER_PID]),
        **loop_status(tel, desc.get("tasks", []), desc.get("joints", [])),
        "log": log,
    }
    if units:
        tasks = desc.get("tasks", [])
        out["resources"] = [
            {"name": u["name"], "fault": u.get("fault"), **loop_status(t, tasks, u["joints"])}
            for u, t in units
        ]
    return out


def joint_states(
    tel: TelemetryBlock, desc: dict[str, Any], units: Sequence[tuple[dict[str, Any], TelemetryBlock]] = ()
) -> dict[str, Any]:
    """Each resource's newest measured joint state (rad, rad/s, N m) and its tick's time (s on
    the daemon's clock); a resource before its first tick is left out."""
    first = (desc.get("resources") or [{}])[0]
    blocks = [(str(u["name"]), list(u["joints"]), t) for u, t in units] or [
        (str(first.get("name", "arm")), list(desc.get("joints", [])), tel)
    ]
    out: list[dict[str, Any]] = []
    t_s = 0.0
    for name, joints, block in blocks:
        rec = latest_tick(block)
        if rec is None:
            continue
        layout = TickLayout(len(joints))
        t_s = max(t_s, float(rec[TICK_FIELDS.index("t_s")]))
        vectors = {v: [float(x) for x in rec[layout.vector(v)]] for v in ("q", "dq", "tau")}
        out.append({"name": name, "joints": joints, **vectors})
    return {"t_s": t_s, "resources": out}


def loop_status(tel: TelemetryBlock, tasks: list[str], joints: list[str]) -> dict[str, Any]:
    """One control loop's part of `status`, from its telemetry block: its counters and timing,
    and from its newest tick its task, phase, resource status and joints."""
    hdr = tel.header
    rec = latest_tick(tel)
    n = len(joints)
    out: dict[str, Any] = {
        "ticks": int(hdr[H.TICKS]),
        "overruns": int(hdr[H.OVERRUNS]),
        "switches": int(hdr[H.SWITCHES]),
        "heartbeat_age_s": round((time.monotonic_ns() - hdr[H.HEARTBEAT_NS]) * 1e-9, 4),
        "timing": timing(tel),
    }
    if rec is not None:
        tid = int(rec[T.TASK])
        out["active_task"] = tasks[tid] if 0 <= tid < len(tasks) else None
        out["task_phase"] = Phase(int(rec[T.PHASE])).name.lower()
        out["resource_status"] = status_names(int(rec[T.STATUS]))
        at = TickLayout(n)
        q, dq, tau, cmd = (
            rec[at.q].tolist(),
            rec[at.dq].tolist(),
            rec[at.tau].tolist(),
            rec[at.cmd].tolist(),
        )
        out["joints"] = [
            {
                "name": joints[j],
                "q_rad": round(q[j], 5),
                "dq_rad_s": round(dq[j], 5),
                "tau_nm": round(tau[j], 3),
                "cmd": round(cmd[j], 3),
            }
            for j in range(n)
        ]
    return out


def decode_trace(
    rec: np.ndarray, desc: dict[str, Any], missions: Mapping[int, dict[str, Any]] | None = None
) -> dict[str, Any]:
    """One trace record for people and programs. An instant's input and action indices are named
    by the mission that was loaded when it was written (`missions`: generation → the mission's
    description, kept by the command daemon), not by the one loaded now; one no longer known (the
    command daemon started after it was replaced) keeps its indices as `#i`."""
    kind = Trace(int(rec[R.KIND]))
    gen = int(rec[R.MISSION_GEN])
    current = desc.get("mission") if desc.get("generation") == gen else None
    mission = current or (missions or {}).get(gen) or {}
    inputs: list[str] = mission.get("inputs", [])
    actions: list[str] = mission.get("actions", [])
    events: list[str] = desc.get("events", [])  # the registry only grows: ids keep their names
    kinds: list[str] = desc.get("event_kinds", [])
    out: dict[str, Any] = {
        "seq": int(rec[R.SEQ]),
        "kind": kind.name.lower(),
        "t_s": round(float(rec[R.T_S]), 6),
        "time": _clock(float(rec[R.WALL_S])),
        "wall_s": round(float(rec[R.WALL_S]), 6),  # Unix time: a cell's events merge by it
    }
    code = int(rec[R.CODE])
    if kind is Trace.INSTANT:
        n_in, n_act = int(rec[R.N_IN]), int(rec[R.N_ACT])
        base = len(R)
        ins = [int(i) for i in rec[base : base + n_in]]
        acts = [int(i) for i in rec[base + TRACE_IDX : base + TRACE_IDX + n_act]]
        out["mission"] = mission.get("name")
        out["from"] = int(rec[R.STATE_FROM])
        out["to"] = int(rec[R.STATE_TO])
        out["inputs"] = [inputs[i] if i < len(inputs) else f"#{i}" for i in ins]
        kind_of = dict(zip(events, kinds, strict=False))
        faults = set(mission.get("fault_inputs", []))  # a resource's fault: the type 3 of its Hold
        out["input_kinds"] = [
            kind_of.get(name, "t3" if name in faults else "input") for name in out["inputs"]
        ]
        out["actions"] = [actions[i] if i < len(actions) else f"#{i}" for i in acts]
    elif kind is Trace.EVENT:
        known = 0 <= code < len(events)
        out["event"] = events[code] if known else f"#{code}"
        out["event_kind"] = kinds[code] if 0 <= code < len(kinds) else "?"
    elif kind is Trace.FAULT:
        cause = next((f for f in desc.get("faults", []) if f.get("n") == code), None)
        out["fault"] = cause if cause is not None else {"n": code}  # beyond those kept: its number
    else:
        known_action = code in OperatorAction._value2member_map_
        out["command"] = OperatorAction(code).name.lower() if known_action else code
        if code == OperatorAction.TUNE and int(rec[R.N_IN]) >= 5:
            out["tune"] = _tune(rec, desc, mission)
    return out


def _tune(rec: np.ndarray, desc: dict[str, Any], mission: dict[str, Any]) -> dict[str, Any]:
    """A tune record in names: `TASK.MODULE.PARAM[i]`, the values before and after, the tick."""
    base = len(R)
    values = rec[base + TRACE_IDX : base + TRACE_IDX + int(rec[R.N_ACT])].tolist()
    r = TuneRecord.decode(rec[base : base + 5].tolist(), values)
    # the Hold tasks first (one per resource: ids 0, 1, ...), the same whatever mission is loaded
    old_daemon = [{"hold_task": "Hold", "hold_tunables": desc.get("hold_tunables", [])}]
    units = desc.get("resources") or old_daemon
    tasks = [*(u.get("hold_task", "Hold") for u in units), *mission.get("tasks", [])]
    tunables = [*(u.get("hold_tunables", []) for u in units), *mission.get("tunables", [])]
    task = tasks[r.task] if 0 <= r.task < len(tasks) else f"#{r.task}"
    names = tunables[r.task] if 0 <= r.task < len(tunables) else []
    param = names[r.param] if 0 <= r.param < len(names) else f"#{r.param}"
    path = f"{task}.{param}" + (f"[{r.element}]" if r.element >= 0 else "")
    return {"path": path, "old": r.old, "new": r.new, "n": r.n, "tick": r.tick}


def _clock(wall_s: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(wall_s)) + f".{int(wall_s % 1 * 1000):03d}"
