"""What two runs may differ by and still compare the same (`orccadctl compare --tol-...`): the
defaults, each option's help and its check. Light (no numpy): the parser is built from it."""

from __future__ import annotations

from dataclasses import dataclass, fields

from orccadd.errors import OrccaddError


@dataclass(frozen=True)
class Tolerances:
    """Each field is an option `--tol-<name>` (underscores as dashes); all must be ≥ 0."""

    duration_s: float = 0.05  # a task's duration: the larger of this and duration_pct of it
    duration_pct: float = 5.0
    tracking_rad: float = 0.005  # a joint's tracking error (RMS, and p95) between the runs
    # the command's and the measured torque's difference B - A, aligned on the task's start: its
    # 95th percentile (a few ticks of real-time jitter do not fail a run; a difference over more
    # than 5 % of the task does)
    cmd_rad: float = 0.01  # a position command
    cmd_nm: float = 5.0  # a torque command
    q_rad: float = 0.01  # the measured position (the motion itself, whatever the command)
    # the measured torque: not judged unless given. On the simulated arm in position mode a tick
    # woken 1 ms late saturates the plant's servo torque for ~20 ticks (150 N.m on the shoulder),
    # in one run of two: ~10 % of a 1.2 s task differs by 10-150 N.m between two identical runs
    tau_nm: float | None = None
    timing_us: float | None = None  # wake_us' and compute_us' p99 between the runs (None: not judged)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is not None and not v >= 0:  # NaN too
                raise OrccaddError(f"{option(f.name)} (={v}) must be a number >= 0")


HELP = {
    "duration_s": "a task's duration may differ by the larger of this (s) and --tol-duration-pct",
    "duration_pct": "... and this percentage of the longer duration",
    "tracking_rad": "a joint's tracking error, RMS and p95 (q - cmd, position commands), A vs B (rad)",
    "cmd_rad": "a position command's difference: p95 of |B - A| aligned on the task's start (rad)",
    "cmd_nm": "a torque command's difference, the same way (N.m)",
    "q_rad": "the measured position's difference, the same way (rad; a torque task's reference)",
    "tau_nm": "the measured torque's difference, the same way (N.m; default: reported, not judged)",
    "timing_us": "p99 of wake_us and compute_us between the runs (us; default: reported, not judged)",
}


def option(name: str) -> str:
    return "--tol-" + name.replace("_", "-")
