"""Ad-hoc motion on a running orccadd (sim-ur5e): `move`, `jog` and `follow` arrive; what is out
of the joints' limits, too fast, away from the arm or malformed is refused before anything
moves, in words that name what is wrong; the daemon answers after every refusal."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.modules.follow import JointTrajectory, Spline
from orccadd.robot import load_robot_config
from orccadd.types import Phase
from orccadd.wire.schema import H, T, TickLayout
from orccadd.wire.telemetry import RingReader, TelemetryBlock
from tests.daemon.conftest import Daemon

WAIT_S = 60.0  # a bound on how long a short motion may take to end, never a timing claim


def joints(d: Daemon) -> tuple[list[str], list[float]]:
    js = d.status()["joints"]
    return [j["name"] for j in js], [j["q_rad"] for j in js]


def ended(d: Daemon) -> dict[str, object]:
    """The status once the run has ended."""
    return d.wait(lambda s: s["state"] not in ("running", "holding"), timeout_s=WAIT_S)


def refused(d: Daemon, cmd: str, **args: object) -> str:
    """The refusal of `cmd`, the daemon still answering after it (and nothing started)."""
    r = d.reply(cmd, **args)
    assert not r["ok"], r
    s = d.status()
    assert s["state"] != "running" and not s["faulted"], s
    return str(r["error"])


def test_move_and_jog_arrive_and_out_of_range_targets_are_refused(daemon: Daemon) -> None:
    _, q0 = joints(daemon)
    target = [q + (0.15 if i == 0 else 0.0) for i, q in enumerate(q0)]
    r = daemon.call("move", joints_rad=target)
    assert r["mode"] == "torque" and r["task_file"].endswith("move_joints.toml"), r
    assert r["started"] == "MoveOnce"
    s = ended(daemon)
    assert s["result"] == "success", s
    np.testing.assert_allclose(joints(daemon)[1], target, atol=0.006)  # the task's tolerance

    bad = [*target[:2], 3.5, *target[3:]]
    err = refused(daemon, "move", joints_rad=bad)
    assert "elbow_joint (joint 2) = 3.5 rad is outside its range [-3.1415, 3.1415] rad" in err, err
    err = refused(daemon, "move", joints_rad=target[:5])
    assert "5 values for the 6 joints of arm" in err, err
    err = refused(daemon, "move", joints_rad="0,0,0")  # malformed: not a list
    assert "'joints_rad' must be a list" in err, err
    err = refused(daemon, "move", joints_rad=target, speed_scale=3.0)
    assert "speed_scale (=3) must be in [0.01, 1]" in err, err
    err = refused(daemon, "jog", joint="elbow", by_rad=0.1)
    assert "no joint 'elbow'" in err, err

    before = joints(daemon)[1]
    # 0.1 rad at speed_scale 0.5 (5 rad/s^2, 50 rad/s^3) is exactly where Ruckig 0.19.4 raised
    # "error in step 1" (a type 3 LawError): `trajectory.ruckig_step` plans it
    daemon.call("jog", joint="wrist_1_joint", by_rad=-0.1)
    assert ended(daemon)["result"] == "success"
    after = joints(daemon)[1]
    np.testing.assert_allclose(after[3], before[3] - 0.1, atol=0.006)
    others = [i for i in range(6) if i != 3]
    np.testing.assert_allclose(np.take(after, others), np.take(before, others), atol=0.006)
    err = refused(daemon, "jog", joint="elbow_joint", by_rad=10.0)
    assert "jog elbow_joint by 10 rad: elbow_joint (joint 2)" in err and "outside its range" in err, err

    # through orccadctl: a negative first value, the wait for the end, the words
    out = daemon.ctl("move", "--joints", ",".join(str(q) for q in q0), "--speed-scale", "0.8")
    assert out.returncode == 0, out.stderr
    assert "move: started on arm (torque: move_joints.toml)" in out.stdout
    assert out.stdout.strip().endswith("arrived (mission ended: success)"), out.stdout
    out = daemon.ctl("move", "--joints", "-9,0,0,0,0,0")
    assert out.returncode == 1 and "shoulder_pan_joint (joint 0) = -9 rad is outside" in out.stderr
    assert daemon.status()["state"] == "ready"


def trajectory_csv(names: Sequence[str], q0: Sequence[float], joint: int, amp: float, dur_s: float) -> str:
    """`joint` out by `amp` and back, as a raised cosine over `dur_s`, sampled every 0.05 s."""
    rows = ["t_s," + ",".join(names)]
    n = round(dur_s / 0.05)
    for k in range(n + 1):
        q = list(q0)
        q[joint] += amp * 0.5 * (1.0 - math.cos(2.0 * math.pi * k / n))
        rows.append(",".join([f"{k * 0.05:g}", *(f"{x:.6f}" for x in q)]))
    return "\n".join(rows) + "\n"


class TickCollector:
    """The telemetry ring's ticks from now on, gathered while the run goes (the ring keeps 16 s:
    read only after the run, on a machine slow to answer the status, its start was gone)."""

    def __init__(self, d: Daemon) -> None:
        self.desc = d.call("describe")
        self.tel = TelemetryBlock.attach(str(self.desc["telemetry"]))
        self.reader = RingReader(self.tel.ticks, self.tel.header, H.TICK_HEAD, from_now=True)
        self.parts: list[np.ndarray] = []

    def poll(self) -> None:
        got = self.reader.poll()
        if len(got):
            self.parts.append(got.copy())

    def close(self) -> np.ndarray:
        self.poll()
        self.tel.close()
        return np.concatenate(self.parts) if self.parts else np.zeros((0, 1))


def follow_ticks(d: Daemon, rec: np.ndarray, desc: dict[str, object]) -> tuple[np.ndarray, np.ndarray]:
    """The loop time since the follow law started and the measured q, of each of its ticks."""
    tasks = desc["tasks"]
    assert isinstance(tasks, list)
    task = tasks.index("Follow")
    mine = rec[(rec[:, T.TASK] == task) & (rec[:, T.PHASE] == Phase.RUN)]
    return mine[:, T.T_S] - mine[0, T.T_S], mine[:, TickLayout(6).q]


def test_follow_tracks_the_interpolation_to_the_last_point_and_bad_trajectories_are_refused(
    daemon: Daemon,
) -> None:
    names, q0 = joints(daemon)
    text = trajectory_csv(names, q0, joint=2, amp=0.3, dur_s=1.0)
    ticks = TickCollector(daemon)
    r = daemon.call("follow", csv=text, name="out_and_back.csv")
    assert r["points"] == 21 and r["duration_s"] == 1.0 and r["task_file"].endswith("follow_joints.toml")
    s = daemon.wait(lambda s: ticks.poll() or s["state"] not in ("running", "holding"), timeout_s=WAIT_S)
    rec = ticks.close()
    assert s["result"] == "success", s
    np.testing.assert_allclose(joints(daemon)[1], q0, atol=0.006)
    t, q = follow_ticks(daemon, rec, daemon.call("describe"))
    lines = [row.split(",") for row in text.split()[1:]]
    points = np.array(lines, dtype=float)
    spline = Spline(JointTrajectory(points[:, 0], points[:, 1:]))
    q_des = spline.at(t)[0]
    assert t[-1] >= 1.0  # the whole trajectory was played, then the arm settled at its end
    # tracked: within move_joints' TrackingDrift threshold all along (the arm started 1e-5 rad
    # from the first point: the status rounds)
    assert np.abs(q - q_des).max() < 0.02, np.abs(q - q_des).max()

    _, q1 = joints(daemon)
    # refused before it moves, however long: 4.5 rad out and back in 4 s peaks at 3.5 rad/s,
    # first over the limit on the way from row 14 to 15
    fast = trajectory_csv(names, q1, joint=0, amp=4.5, dur_s=4.0)
    err = refused(daemon, "follow", csv=fast, name="fast.csv")
    assert err.startswith(
        "fast.csv: row 14 to 15 (t_s = 0.65): shoulder_pan_joint's velocity reaches 3.149 rad/s, "
        "beyond its limit 3.1415 rad/s (max_velocity_rad_s"
    ), err
    jerky = trajectory_csv(names, q1, joint=2, amp=0.3, dur_s=0.5)  # 24 rad/s^2
    err = refused(daemon, "follow", csv=jerky, name="jerky.csv")
    assert "jerky.csv: row 1 to 2 (t_s = 0): elbow_joint's acceleration reaches" in err, err
    assert "beyond its limit 6 rad/s^2 (max_acceleration_rad_s2" in err, err
    away = trajectory_csv(names, [q + 0.05 * (i == 4) for i, q in enumerate(q1)], 2, 0.1, 1.0)
    err = refused(daemon, "follow", csv=away, name="away.csv")
    assert "away.csv: the trajectory starts 0.05 rad from where joint wrist_2_joint is" in err, err
    bad = text.replace("\n0.1,", "\n0.1x,", 1)
    err = refused(daemon, "follow", csv=bad, name="bad.csv")
    assert "bad.csv:4: t_s = '0.1x' is not a finite number" in err, err
    err = refused(daemon, "follow", csv="t_s,a,b\n0,1,2\n", name="bad.csv")
    assert "bad.csv:1: the header is t_s,a,b; want t_s and each joint" in err, err
    backwards = text.replace("\n0.1,", "\n0.02,", 1)
    err = refused(daemon, "follow", csv=backwards, name="back.csv")
    assert "back.csv:4: t_s = 0.02 after 0.05: the times must increase strictly" in err, err
    assert daemon.call("ping")


def test_move_to_a_pose_goes_along_a_straight_line_and_a_bad_pose_is_refused(
    daemon: Daemon, tmp_path: Path
) -> None:
    kin = ToolKinematics(RobotModel.from_config(load_robot_config(tmp_path / "robot.toml")))
    start = kin.pose(np.array(joints(daemon)[1]))
    goal = start.translation + np.array([0.05, 0.05, -0.05])
    err = refused(daemon, "move", pose=[0.1, 0.2])
    assert "pose has 2 values: want x, y, z (m) and, optionally, roll, pitch, yaw (rad)" in err, err
    err = refused(daemon, "move", pose=[*goal, 0.0, 4.0, 0.0])
    assert "pose's pitch (=4 rad) must be in [-pi, pi]" in err, err
    assert "either joints_rad" in refused(daemon, "move", pose=list(goal), joints_rad=[0.0] * 6)
    p = daemon.ctl("move", "--pose", ",".join(f"{v:.6f}" for v in goal))  # the orientation kept
    assert p.returncode == 0, p.stdout + p.stderr
    assert "move: started on arm (move_to_pose.toml), the tool to (" in p.stdout and "arrived" in p.stdout, (
        p.stdout
    )
    end = kin.pose(np.array(joints(daemon)[1]))
    assert np.linalg.norm(end.translation - goal) < 1e-3
    assert np.linalg.norm(pin.log3(end.rotation @ start.rotation.T)) < 0.01
