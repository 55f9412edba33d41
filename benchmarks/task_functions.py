"""How well the task functions do their job: a straight line's tracking, a press's force.

1. Line tracking, in simulated time (deterministic, the plant stepped by the loop): the shipped
   line tasks (move_line: resolved rate + joint computed torque; move_line_csp: the same sent as
   position commands to the simulated arm's servos; move_line_os: operational-space computed
   torque) on the simulated UR5e and Panda, out and back 0.3 m along the base's -y and then
   0.2 m diagonally: the tool's distance from the line (max, RMS) and from the goal at the end.
2. Force regulation, in simulated time: press.toml and press_csp.toml pressing 10 N on a table of
   5,000 N/m: the settling time and, over the second after the postcondition, |Fz - 10 N| (max,
   RMS).
3. With --daemon, line_demo.mission through orccadd on the simulated arm (its plant in its own
   process, real time) and on the UR controller simulator (servoJ): the same distances, from the
   daemon's own full-rate log.

    python benchmarks/task_functions.py [--daemon]

The law's cost per tick is benchmarks/tick_profile.py's (--task configs/tasks/move_line.toml).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from harness import ROOT, config_with

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.types import CommandMode, Phase

TASKS = ROOT / "configs/tasks"
ROBOTS = {
    "sim-ur5e": (ROOT / "configs/robots/sim-ur5e.toml", [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]),
    "sim-panda": (ROOT / "configs/robots/sim-panda.toml", [0.0, -0.7854, 0.0, -2.3562, 0.0, 1.5708, 0.7854]),
}
LINE_TASKS = {
    "move_line": (CommandMode.TORQUE, "move_joints.toml"),
    "move_line_csp": (CommandMode.POSITION, "move_joints_csp.toml"),
    "move_line_os": (CommandMode.TORQUE, "move_joints.toml"),
}
OFFSETS = ([0.0, -0.3, 0.0], [0.0, 0.3, 0.0], [0.2, 0.0, -0.2])


def module(task: RobotTask, name: str):  # type: ignore[no-untyped-def]
    return next(m for m in task.modules if m.name == name)


def off_line(path: np.ndarray, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Each point's distance from the segment start-goal (m)."""
    u = (goal - start) / np.linalg.norm(goal - start)
    d = path - start
    along = np.clip(d @ u, 0.0, float(np.linalg.norm(goal - start)))
    return np.asarray(np.linalg.norm(d - np.outer(along, u), axis=1))


def line_tracking(robot: str, task_name: str) -> str:
    config, home = ROBOTS[robot]
    mode, joint_task = LINE_TASKS[task_name]
    s = Session.open(config, mode)
    try:
        loop = s.loop(SimClock())
        go_home = s.task(TASKS / joint_task)
        module(go_home, "traj").configure({"target_rad": home})
        if loop.run_task(go_home, timeout_s=20.0) is not Phase.DONE:
            return f"{robot:10s} {task_name:14s} home not reached: {s.event_names()[-1]}"
        kin = ToolKinematics(s.resource.model)
        dist, ends, path = [], [], []
        for offset in OFFSETS:
            task = s.task(TASKS / f"{task_name}.toml")
            line = module(task, "line")
            line.configure({"offset_m": offset})

            def step(t_s: float, task: RobotTask = task) -> None:
                task.tick(t_s)
                path.append(kin.pose(s.resource.state.q_rad).translation.copy())

            loop.executor.step = step
            path.clear()
            phase = loop.run_task(task, timeout_s=20.0)
            if phase is not Phase.DONE:
                return f"{robot:10s} {task_name:14s} ended {phase.name}: {s.event_names()[-1]}"
            goal = np.asarray(line.outputs["position_goal_m"].value)
            dist.append(off_line(np.array(path), path[0], goal))
            ends.append(float(np.linalg.norm(path[-1] - goal)))
        d = np.concatenate(dist) * 1e3
        rms = float(np.sqrt(np.mean(d**2)))
        return (
            f"{robot:10s} {task_name:14s} off the line: max {d.max():.3f} mm, RMS {rms:.3f} mm; "
            f"at the end {max(ends) * 1e3:.3f} mm from the goal (worst of {len(OFFSETS)} lines)"
        )
    finally:
        s.close()


def force_regulation(task_name: str, tmp: Path) -> str:
    mode = CommandMode.TORQUE if task_name == "press" else CommandMode.POSITION
    table = (
        "world_planes = [{ point_m = [0.0, 0.0, 0.45], normal = [0.0, 0.0, 1.0], stiffness_n_m = 5000.0 }]\n"
    )
    src, home = ROBOTS["sim-ur5e"]
    config = tmp / f"table-{task_name}.toml"
    config.write_text(
        src.read_text().replace('"../', f'"{src.parent.parent}/').replace("seed = 1\n", "seed = 1\n" + table)
    )
    s = Session.open(config, mode)
    try:
        loop = s.loop(SimClock())
        go_home = s.task(
            TASKS / ("move_joints.toml" if mode is CommandMode.TORQUE else "move_joints_csp.toml")
        )
        module(go_home, "traj").configure({"target_rad": home})
        loop.run_task(go_home, timeout_s=20.0)
        task = s.task(TASKS / f"{task_name}.toml")
        fz: list[float] = []

        def step(t_s: float) -> None:
            task.tick(t_s)
            fz.append(float(s.resource.signals["wrench"][2]))

        loop.executor.step = step
        phase = loop.run_task(task, timeout_s=20.0)
        done_s = len(fz) * s.config.control_period_s
        if phase is not Phase.DONE:
            return f"{task_name:12s} ended {phase.name}: {s.event_names()[-1]}"
        settled = len(fz)
        loop.executor.run(max_ticks=round(1.0 / s.config.control_period_s))  # a second more, pressing
        err = np.abs(np.array(fz[settled:]) - 10.0)
        rms = float(np.sqrt(np.mean(err**2)))
        return (
            f"{task_name:12s} 10 N on 5,000 N/m: done (within 1 N for 0.5 s) {done_s:.2f} s after the "
            f"start; the second after: |Fz - 10 N| max {err.max():.3f} N, RMS {rms:.3f} N"
        )
    finally:
        s.close()


def daemon_line_demo(backend: str, tmp: Path) -> str:
    """line_demo through orccadd on `backend` ("sim" or "ur_rtde"), from its full-rate log."""
    from orccadd.launch import DaemonProcess
    from orccadd.ursim.process import UrSimProcess

    source = ROOT / (
        "configs/robots/sim-ur5e.toml" if backend == "sim" else "configs/robots/ur5e-rtde-sim.toml"
    )
    config = config_with(source, tmp, "")
    ur = UrSimProcess(source, "--boot", "running", "--priority", "70") if backend == "ur_rtde" else None
    try:
        d = DaemonProcess(config, tmp / "orccadd.sock", tmp / "orccadd.log")
        try:
            out = tmp / f"line-{backend}.csv"
            for args in (("log", "start", "q", "--name", out.name), ("load", "line_demo"), ("start",)):
                if d.ctl(*args).returncode != 0:
                    return f"{backend}: orccadctl {' '.join(args)} failed"
            s = d.wait(lambda s: s["state"] != "running", timeout_s=120)
            stop = json.loads(d.ctl("log", "stop", "-o", str(out), "--json").stdout)["result"]
            events = d.call("events", last=100)["events"]  # type: ignore[index]
        finally:
            d.stop()
    finally:
        if ur is not None:
            ur.stop()
    if s["result"] != "success":
        return f"{backend}: line_demo ended {s['result']}"
    starts = {a: e["t_s"] for e in events if e["kind"] == "instant" for a in e["actions"]}
    lines = out.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    rows = np.loadtxt(lines[header + 1 :], delimiter=",", ndmin=2)
    t_s = rows[:, 0] + float(stop["origin_t_s"])
    kin = ToolKinematics(RobotModel.from_config(load_robot_config(config)))
    tool = np.array([kin.pose(q).translation for q in rows[:, 1:7]])
    out_t, back_t = starts["start Out"], starts["start Back"]
    a = tool[np.searchsorted(t_s, out_t)]
    dist = []
    for first, last, goal in ((out_t, back_t, a + np.array([0.0, -0.3, 0.0])), (back_t, t_s[-1], a)):
        seg = tool[(t_s >= first) & (t_s <= last)]
        dist.append(off_line(seg, seg[0], goal))
    d_mm = np.concatenate(dist) * 1e3
    rms = float(np.sqrt(np.mean(d_mm**2)))
    ticks = d_mm.size
    return f"line_demo on {backend:8s} off the line: max {d_mm.max():.3f} mm, RMS {rms:.3f} mm, {ticks} ticks"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--daemon", action="store_true", help="line_demo through orccadd on the sim and the UR simulator"
    )
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="orccadd-taskfn-"))
    print("line tracking, simulated time (0.3 m out and back along -y, then 0.2 m diagonally):")
    for robot in ROBOTS:
        for task_name in LINE_TASKS:
            print("  " + line_tracking(robot, task_name), flush=True)
    print("force regulation, simulated time (sim-ur5e, the tool pressing down on a table):")
    for task_name in ("press", "press_csp"):
        print("  " + force_regulation(task_name, tmp), flush=True)
    if args.daemon:
        print("line_demo through orccadd, real time:")
        for backend in ("sim", "ur_rtde"):
            print(
                "  " + daemon_line_demo(backend, tmp),
                flush=True,
            )
    return None


if __name__ == "__main__":
    sys.exit(main())
