"""The e-Series flange force/torque sensor, as the controller reports it over RTDE.

- `actual_TCP_force`: the external wrench on the tool at the TCP, in the base frame (force N,
  torque N·m about the TCP), the payload's weight compensated (the simulator's payload is the
  one `set_payload` declares), minus the offset `zero_ftsensor` took: after `zero_ftsensor()`
  the reading is the change of the wrench since, as URScript's zero_ftsensor says ("zeroes the
  TCP force/torque measurement ... by subtracting the current measurement from the
  subsequent").
- `ft_raw_wrench`: the same wrench, neither zeroed nor compensated for the payload's weight
  (base frame, about the TCP).

The sign is the controller's "external" wrench: the force the environment exerts on the tool
(pressing the tool down on a table reads +Fz). Optional noise: white, Gaussian, seeded.
"""

from __future__ import annotations

import numpy as np

from orccadd.state import FloatArray

G_M_S2 = 9.80665


class FtSensor:
    """One reading per controller cycle (`measure`), into the arrays the RTDE fields read."""

    def __init__(self, tcp_force: FloatArray, raw_wrench: FloatArray) -> None:
        self.tcp_force = tcp_force  # RobotState.actual_tcp_force, updated in place
        self.raw_wrench = raw_wrench  # RobotState.ft_raw_wrench
        self.offset = np.zeros(6)
        self.compensated = np.zeros(6)  # the last reading before the zero offset
        self.noise_force_n = 0.0
        self.noise_torque_nm = 0.0
        self._rng = np.random.default_rng(0)
        self._noise = np.zeros(6)

    def set_noise(self, force_n: float, torque_nm: float, seed: int) -> None:
        """Standard deviations of the noise on each force and torque component."""
        if force_n < 0.0 or torque_nm < 0.0:
            raise ValueError(f"noise (force_n={force_n!r}, torque_nm={torque_nm!r}) must be >= 0")
        self.noise_force_n, self.noise_torque_nm = force_n, torque_nm
        self._rng = np.random.default_rng(seed)

    def zero(self) -> None:
        """`zero_ftsensor()`: later readings have the present one subtracted."""
        self.offset[:] = self.compensated

    def reset(self) -> None:
        self.offset[:] = 0.0

    def measure(self, external: FloatArray, payload_kg: float, cog_from_tcp_m: FloatArray) -> None:
        """A reading of the external wrench `external` (base frame, at the TCP) with a payload
        of `payload_kg` whose centre of gravity is `cog_from_tcp_m` from the TCP (base frame)."""
        c = self.compensated
        c[:] = external
        if self.noise_force_n or self.noise_torque_nm:
            self._rng.standard_normal(out=self._noise)
            self._noise[0:3] *= self.noise_force_n
            self._noise[3:6] *= self.noise_torque_nm
            c += self._noise
        raw = self.raw_wrench
        raw[:] = c
        if payload_kg:  # its weight w = [0, 0, −m·g] at the centre of gravity: r × w about the TCP
            w = -payload_kg * G_M_S2
            raw[2] += w
            raw[3] += float(cog_from_tcp_m[1]) * w
            raw[4] -= float(cog_from_tcp_m[0]) * w
        np.subtract(c, self.offset, out=self.tcp_force)
