"""The measured joint state, shared by the resources that fill it and the modules that read it."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class JointState:
    """Measured state, preallocated once and updated in place by `PhysicalResource.read()`.

    `q_rad`, `dq_rad_s` and `tau_nm` are consecutive views of one array, `vector` (and `q_dq`
    is its first two): a backend fills them in one copy, the limit check reads them in one call.
    `tau_nm` is measured or estimated as the resource's description says.
    """

    __slots__ = ("dq_rad_s", "fault_code", "q_dq", "q_rad", "status", "t_s", "tau_nm", "vector")

    def __init__(self, dof: int) -> None:
        self.t_s = 0.0
        self.vector: FloatArray = np.zeros(3 * dof)
        self.q_dq: FloatArray = self.vector[: 2 * dof]
        self.q_rad: FloatArray = self.vector[:dof]
        self.dq_rad_s: FloatArray = self.vector[dof : 2 * dof]
        self.tau_nm: FloatArray = self.vector[2 * dof :]
        self.status = 0
        self.fault_code = 0  # backend-specific (EMCY code, UR safety mode, Dynamixel error bits)
