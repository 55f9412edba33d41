"""Signal filters. `LowPass` is also the worked example of docs/writing-a-module.md."""

from __future__ import annotations

import math

from orccadd.modules.base import Module, ModuleContext, register
from orccadd.state import JointState


@register("low_pass")
class LowPass(Module):
    """First-order low-pass filter on a joint vector: y += a·(x − y), a = min(1, 2π·fc·T)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.x = self.add_input("x", (n,), "rad/s")
        self.y = self.add_output("y", (n,), "rad/s")
        self.cutoff = self.add_parameter("cutoff_hz", 10.0, bounds=(0.1, 500.0), unit="Hz", tunable=True)
        self._a = 0.0
        self.on_parameter_change("cutoff_hz")

    def on_parameter_change(self, name: str) -> None:
        self._a = min(1.0, 2.0 * math.pi * float(self.cutoff.value) * self.ctx.period_s)

    def start(self, state: JointState) -> None:
        self.y.value[:] = state.dq_rad_s  # start from the measured value: no jump

    def update(self, t_s: float) -> None:
        y = self.y.value
        y += self._a * (self.x.value - y)
