"""Ad-hoc motion without a mission file: `orccadctl move`, `jog` and `follow`.

Each builds a one-task mission for one resource (`AdHoc.text`), which the daemon then loads
exactly as a file's (`Loader.load_text`: the same compiler process, checks and refusals) and
starts. What a mission's `set` line would check only when the task is built is checked here,
first, in the operator's terms: the number of values, each joint's range, a trajectory's
velocities and accelerations; nothing has moved when one is refused.

The task file is the shipped one that fits the resource's command mode, found in
`daemon.task_dirs`: the mode of the resource's Hold task (the one its config chose to hold it
in: position for drives and servos whose own loops track, torque for the simulated arm), or,
if the resource cannot take that one, torque, then position. `move_joints.toml` /
`move_joints_csp.toml`, `follow_joints.toml` / `follow_joints_csp.toml`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.config.station import StationConfig
from orccadd.daemon.replies import CommandError
from orccadd.daemon.view import Machine, UnitView
from orccadd.kinematics import ToolKinematics
from orccadd.modules.cartesian import inside_workspace
from orccadd.modules.follow import MAX_POINTS, JointTrajectory, Spline, first_excess
from orccadd.types import CommandMode

FOLLOW_START_TOLERANCE_RAD = 0.01  # how far a trajectory's first point may be from the arm
SETTLE_S = 10.0  # a trajectory ends this long before its task's timeout, at least
TASK_FILES = {
    ("move", CommandMode.TORQUE): "move_joints.toml",
    ("move", CommandMode.POSITION): "move_joints_csp.toml",
    ("follow", CommandMode.TORQUE): "follow_joints.toml",
    ("follow", CommandMode.POSITION): "follow_joints_csp.toml",
    ("pose", CommandMode.TORQUE): "move_to_pose.toml",
    ("pose", CommandMode.POSITION): "move_to_pose_csp.toml",
}
LINE_T2 = ("PathLost", "NearSingularity", "OutsideWorkspace")  # a line task's type 2 exceptions


@dataclass(frozen=True)
class AdHoc:
    """A generated mission: its name in messages, its text, the data its modules take."""

    name: str
    text: str
    data: dict[str, object] = field(default_factory=dict)
    detail: dict[str, Any] = field(default_factory=dict)  # for the reply


def unit_for(units: Sequence[UnitView], resource: str, joint: str = "") -> UnitView:
    """The resource named (default: the only one, or the one with `joint`)."""
    if resource:
        for u in units:
            if u.name == resource:
                return u
        raise CommandError(f"no resource {resource!r} (resources: {', '.join(u.name for u in units)})")
    having = [u for u in units if not joint or joint in u.cfg.joint_names]
    if joint and not having:
        joints = ", ".join(j for u in units for j in u.cfg.joint_names)
        raise CommandError(f"no joint {joint!r} (joints: {joints})")
    if len(having) > 1:
        names = ", ".join(u.name for u in having)
        raise CommandError(
            f"several resources ({names}){' have ' + joint if joint else ''}: name one (--resource)"
        )
    return having[0]


def mode_for(unit: UnitView) -> CommandMode:
    """The command mode of ad-hoc motion on `unit` (see the module's docstring)."""
    modes = unit.resource.description.modes
    held = unit.loop.hold.signature.command
    for mode in (held, CommandMode.TORQUE, CommandMode.POSITION):
        if mode in modes and mode in (CommandMode.TORQUE, CommandMode.POSITION):
            return mode
    have = ", ".join(m.name.lower() for m in modes)
    raise CommandError(f"resource {unit.name} takes neither torque nor position commands (it takes {have})")


def task_file(cfg: StationConfig, kind: str, mode: CommandMode) -> Path:
    """The shipped task file for `kind` in `mode`, from the first of `daemon.task_dirs` with it
    (`cfg`: the daemon's, whose directories the compiler reads)."""
    name = TASK_FILES[(kind, mode)]
    dirs = [cfg.resolve(d) for d in cfg.daemon.task_dirs]
    for d in dirs:
        if (d / name).is_file():
            return d / name
    raise CommandError(
        f"no {name} in daemon.task_dirs ({', '.join(map(str, dirs))}): it ships in configs/tasks"
    )


def check_target(cfg: RobotConfig, target: Sequence[float], what: str) -> None:
    """`CommandError` unless `target` has one value per joint, each within the joint's range."""
    names = cfg.joint_names
    if len(target) != len(names):
        raise CommandError(
            f"{what}: {len(target)} values for the {len(names)} joints of {cfg.resource.name} "
            f"({', '.join(names)})"
        )
    for i, (j, q) in enumerate(zip(cfg.joints, target, strict=True)):
        if not j.position_min_rad <= q <= j.position_max_rad:
            raise CommandError(
                f"{what}: {j.name} (joint {i}) = {q:g} rad is outside its range "
                f"[{j.position_min_rad:g}, {j.position_max_rad:g}] rad "
                f"(joints[{i}].position_min_rad/max_rad in {cfg.source or 'the robot config'})"
            )


def mission_text(
    kind: str,
    task: str,
    resource: str,
    source: Path,
    sets: Sequence[str],
    t2: Sequence[str] = ("TrackingLost",),
) -> str:
    """A mission of one task: it runs until its postcondition (success), a graceful `Stop`
    (success: held where it is), or one of its type 2 exceptions `t2` or a type 3 (the safe
    procedure, which ends at once: result `safe`; a type 3 has safe-stopped the arm, `reset`
    clears it)."""
    lines = "".join(f"  set {s}\n" for s in sets)
    declared = "".join(f"  T2 {name}\n" for name in t2)
    caught = " or ".join(f"{task}.{name}" for name in t2)
    return (
        f"-- written by orccadd for `orccadctl {kind}`\n"
        f"mission {task}\n\nresource {resource}\ninput Stop\n\n"
        f'task {task} on {resource} from "{source}"\n{lines}  post\n{declared}end\n\n'
        f"main procedure {task}Once\n  handle\n    do\n      {task}\n    until Stop\n"
        f"  on {caught} do\n    safe\n  on fatal do\n    safe\n  end\nend\n\n"
        "safe procedure Held\n  nothing\nend\n"
    )


def move(m: Machine, target: Sequence[float], resource: str, speed_scale: float) -> AdHoc:
    """`move`: to the joint target, at `speed_scale` of the joints' limits."""
    u = unit_for(m.units, resource)
    check_target(u.cfg, target, "move")
    return _move(m.station, u, list(target), speed_scale, "move")


def move_pose(m: Machine, pose: Sequence[float], resource: str, speed_scale: float) -> AdHoc:
    """`move --pose`: the tool along a straight line to `pose` (x, y, z in m, base frame; then
    roll, pitch, yaw in rad about the base's axes, or none: the orientation the tool has now),
    time-optimal within the tool's limits ([tool]) times `speed_scale`."""
    u = unit_for(m.units, resource)
    if len(pose) not in (3, 6):
        raise CommandError(
            f"move: pose has {len(pose)} values: want x, y, z (m) and, optionally, roll, pitch, yaw (rad)"
        )
    if not 0.01 <= speed_scale <= 1.0:
        raise CommandError(f"move: speed_scale (={speed_scale:g}) must be in [0.01, 1]")
    model = u.resource.model
    position = [float(v) for v in pose[:3]]
    if len(pose) == 6:
        rpy = [float(v) for v in pose[3:]]
        for name, v in zip(("roll", "pitch", "yaw"), rpy, strict=True):
            if not -math.pi <= v <= math.pi:
                raise CommandError(f"move: pose's {name} (={v:g} rad) must be in [-pi, pi]")
    else:
        now = ToolKinematics(model).pose(u.resource.state.q_rad).rotation
        rpy = [float(v) for v in pin.rpy.matrixToRpy(now)]
    if not inside_workspace(model, np.array(position)):
        raise CommandError(
            f"move: the pose's position ({', '.join(f'{v:g}' for v in position)}) m is outside the "
            f"workspace ([workspace] in {u.cfg.source or 'the robot config'})"
        )
    source = task_file(m.station, "pose", mode_for(u))
    sets = [
        f"line.target_position_m = [{', '.join(map(repr, position))}]",
        f"line.target_rpy_rad = [{', '.join(map(repr, rpy))}]",
        f"line.speed_scale = {float(speed_scale)!r}",
    ]
    text = mission_text("move", "MoveTo", u.name, source, sets, LINE_T2)
    detail = {"resource": u.name, "pose": [*position, *rpy], "task_file": str(source)}
    return AdHoc("(orccadctl move --pose)", text, detail=detail)


def jog(m: Machine, joint: str, by_rad: float, resource: str, speed_scale: float) -> AdHoc:
    """`jog`: one joint by `by_rad` from where it is now, the others held where they are."""
    u = unit_for(m.units, resource, joint)
    if joint not in u.cfg.joint_names:
        raise CommandError(
            f"resource {u.name} has no joint {joint!r} (joints: {', '.join(u.cfg.joint_names)})"
        )
    target = u.resource.state.q_rad.tolist()
    target[u.cfg.joint_names.index(joint)] += by_rad
    check_target(u.cfg, target, f"jog {joint} by {by_rad:g} rad")
    return _move(m.station, u, target, speed_scale, "jog")


def _move(cfg: StationConfig, u: UnitView, target: list[float], speed_scale: float, kind: str) -> AdHoc:
    if not 0.01 <= speed_scale <= 1.0:
        raise CommandError(f"{kind}: speed_scale (={speed_scale:g}) must be in [0.01, 1]")
    mode = mode_for(u)
    source = task_file(cfg, "move", mode)
    values = ", ".join(repr(float(q)) for q in target)
    sets = [f"traj.target_rad = [{values}]", f"traj.speed_scale = {float(speed_scale)!r}"]
    text = mission_text(kind, kind.capitalize(), u.name, source, sets)
    detail = {"resource": u.name, "target_rad": target, "mode": mode.name.lower(), "task_file": str(source)}
    return AdHoc(f"(orccadctl {kind})", text, detail=detail)


def follow(m: Machine, csv: str, name: str, resource: str) -> AdHoc:
    """`follow`: the trajectory of CSV text `csv` (`name`: its file, for messages), checked."""
    u = unit_for(m.units, resource)
    traj = parse_csv(csv, name, u.cfg.joint_names)
    check_trajectory(u.cfg, traj, name, u.resource.state.q_rad.tolist())
    mode = mode_for(u)
    source = task_file(m.station, "follow", mode)
    text = mission_text("follow", "Follow", u.name, source, [])
    detail = {
        "resource": u.name, "points": len(traj.t_s), "duration_s": float(traj.t_s[-1]),
        "target_rad": traj.q_rad[-1].tolist(), "mode": mode.name.lower(), "task_file": str(source),
    }  # fmt: skip
    return AdHoc("(orccadctl follow)", text, {"Follow.traj": traj}, detail)


def parse_csv(text: str, name: str, joints: Sequence[str]) -> JointTrajectory:
    """The points of a CSV with the header `t_s,<joint names>` (every joint once, any order),
    a row of numbers per point; `CommandError` naming the line otherwise."""
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise CommandError(f"{name}: empty: a trajectory is a CSV with the header t_s,{','.join(joints)}")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "t_s" or sorted(header[1:]) != sorted(joints):
        raise CommandError(
            f"{name}:1: the header is {','.join(header)[:300]}; want t_s and each joint of this "
            f"resource once: t_s,{','.join(joints)}"
        )
    rows = [(k, line) for k, line in enumerate(lines[1:], start=2) if line.strip()]
    if not 2 <= len(rows) <= MAX_POINTS:
        raise CommandError(f"{name}: {len(rows)} points: a trajectory has 2 to {MAX_POINTS}")
    values = np.empty((len(rows), len(header)))
    for r, (k, line) in enumerate(rows):
        cells = line.split(",")
        if len(cells) != len(header):
            raise CommandError(f"{name}:{k}: {len(cells)} values, the header names {len(header)}")
        for c, cell in enumerate(cells):
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise CommandError(f"{name}:{k}: {header[c]} = {cell.strip()[:40]!r} is not a finite number")
            values[r, c] = v
    t = values[:, 0]
    if t[0] != 0.0:
        raise CommandError(
            f"{name}:{rows[0][0]}: the first point's t_s is {t[0]:g}: a trajectory starts at 0"
        )
    for r in np.flatnonzero(np.diff(t) <= 0.0).tolist():
        k = rows[r + 1][0]
        raise CommandError(f"{name}:{k}: t_s = {t[r + 1]:g} after {t[r]:g}: the times must increase strictly")
    order = [header.index(j) for j in joints]
    return JointTrajectory(t.copy(), values[:, order].copy())


def check_trajectory(cfg: RobotConfig, traj: JointTrajectory, name: str, q_now: Sequence[float]) -> None:
    """`CommandError` if the interpolated motion leaves a joint's limits anywhere, lasts too long
    for its task's timeout, or does not start where the arm is (within 0.01 rad)."""
    if why := traj.problem(cfg.dof):
        raise CommandError(f"{name}: {why}")
    j = cfg.joints
    excess = first_excess(
        Spline(traj),
        np.array([x.position_min_rad for x in j]),
        np.array([x.position_max_rad for x in j]),
        np.array([x.max_velocity_rad_s for x in j]),
        np.array([x.max_acceleration_rad_s2 for x in j]),
    )
    if excess is not None:
        e, joint = excess, j[excess.joint]
        key = {"position": "position_min_rad/max_rad", "velocity": "max_velocity_rad_s"}.get(
            e.quantity, "max_acceleration_rad_s2"
        )
        unit = {"position": "rad", "velocity": "rad/s"}.get(e.quantity, "rad/s^2")
        where = f"row {e.row + 1}" + (f" to {e.row + 2}" if e.between else "")
        t_s = float(traj.t_s[e.row])
        raise CommandError(
            f"{name}: {where} (t_s = {t_s:g}): {joint.name}'s {e.quantity} reaches {e.value:.4g} {unit}, "
            f"beyond its limit {e.limit:g} {unit} ({key}; the points are interpolated by a cubic spline)"
        )
    timeout_s = cfg.daemon.task_timeout_s
    if traj.t_s[-1] > timeout_s - SETTLE_S:
        raise CommandError(
            f"{name}: lasts {traj.t_s[-1]:g} s; a task may run {timeout_s:g} s (daemon.task_timeout_s), "
            f"the trajectory {SETTLE_S:g} s less"
        )
    gap = np.abs(traj.q_rad[0] - np.asarray(q_now))
    i = int(np.argmax(gap))
    if gap[i] > FOLLOW_START_TOLERANCE_RAD:
        raise CommandError(
            f"{name}: the trajectory starts {gap[i]:.4g} rad from where joint {j[i].name} is "
            f"({traj.q_rad[0, i]:.4g} rad, the joint at {q_now[i]:.4g} rad; at most "
            f"{FOLLOW_START_TOLERANCE_RAD:g} rad): start it from the arm's position (orccadctl status)"
        )
