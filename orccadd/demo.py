"""`make demo`: a short mission by hand on the simulated UR5e, on the wall clock.

Moves home with Ruckig + computed torque, then to two more targets, one progress line per
motion, and the loop's timing statistics at the end. A motion stopped by the type 3 exception
Overrun (this shared VM can stall the loop for tens of ms) is retried, as an operator would:
the safe stop completes, the stop is cleared, the motion restarts from the measured state.
(The execution-machine issue turns this into the daemon running a verified Robot-Procedure.)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from orccadd.runtime import WallClock, enter_realtime, leave_realtime
from orccadd.session import Session

ROOT = Path(__file__).resolve().parent.parent
TARGETS_RAD = {
    "home": None,
    "reach": [0.8, -1.2, 1.2, -1.6, -1.2, 0.4],
    "tuck": [-0.5, -2.0, 2.2, -1.8, -1.57, -0.3],
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--robot", default=str(ROOT / "configs/robots/sim-ur5e.toml"))
    ap.add_argument("--task", default=str(ROOT / "configs/tasks/move_joints.toml"))
    ap.add_argument("--priority", type=int, default=80, help="SCHED_FIFO priority (0: none)")
    ap.add_argument("--spin-us", type=float, default=0.0, help="wake early and spin (µs)")
    ap.add_argument("--overrun-limit", type=int, default=3, help="overruns in a row that raise T3 Overrun")
    ap.add_argument("--retries", type=int, default=2, help="retries of a motion stopped by T3 Overrun")
    args = ap.parse_args(argv)

    session = Session.open(args.robot)
    task = session.task(args.task)
    loop = session.loop(WallClock(spin_margin_s=args.spin_us * 1e-6), overrun_limit=args.overrun_limit)
    traj = next(m for m in task.modules if m.type_name == "ruckig_trajectory")
    cfg = session.config
    rt = enter_realtime(args.priority)
    for w in rt.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(
        f"orccadd demo: {cfg.name} ({cfg.dof} joints, {cfg.resource.backend}), "
        f"period {cfg.control_period_s * 1e3:g} ms, {rt.describe()}"
    )
    failures = 0
    try:
        for i, (name, target) in enumerate(TARGETS_RAD.items(), start=1):
            goal = session.resource.model.home_rad if target is None else np.array(target)
            for attempt in range(args.retries + 1):
                traj.configure({"target_rad": goal})
                t0 = time.monotonic()
                phase = loop.run_task(task, timeout_s=10.0)
                elapsed = time.monotonic() - t0
                err = float(np.abs(session.resource.state.q_rad - goal).max())
                names = [n.split(".", 1)[1] for n in session.event_names() if not n.endswith(".pre")]
                print(
                    f"motion {i}/{len(TARGETS_RAD)} {name:6s} target {np.round(goal, 2).tolist()}: "
                    f"{phase.name.lower()} in {elapsed:5.2f} s, final error {err:.4f} rad "
                    f"[events: {', '.join(names) or 'none'}]"
                )
                if names != ["T3.Overrun"] or attempt == args.retries:
                    break
                # The machine stalled the loop, not the arm: let the safe stop finish, clear, retry.
                loop.run_for(1.0)
                session.resource.clear_stop()
                print(f"  {args.overrun_limit} overrun(s) in a row (the machine stalled the loop): "
                      "the arm safe-stopped; stop cleared, retrying")  # fmt: skip
            failures += phase.name != "DONE"
        loop.run_for(0.2)  # hold at the last target
    finally:
        leave_realtime(rt)
        session.close()
    print(loop.stats.report("control loop"))
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
