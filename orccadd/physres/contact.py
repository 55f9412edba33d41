"""What a simulated tool can touch: planes and holes in a plane, as a penalty contact model.

Shared by the simulated arm (`sim`, `sim_process` and its plant: `sim_contact.ToolContact`) and,
for the wall's law and the parameters' checks, by the UR controller simulator
(`orccadd.ursim.world`). Everything is in the base frame, SI units.

The tool is a sphere of radius `r` (`tool_radius_m`, 0: a point) about the tool point
(`[tool]` of the robot config). A shape is a rigid solid with a spring-damper surface:

- a **plane**: the half-space behind a surface through `point_m` with the outward unit normal
  `normal` (pointing into free space);
- a **hole**: the same half-space with a cylindrical pocket in it, of `radius_m` about the axis
  through `center_m` (a point of the surface) along `normal`, `depth_m` deep (its flat bottom at
  `center_m − depth_m·normal`; no `depth_m`: no bottom, a hole through).

For a shape, φ is the signed distance from the tool point to the solid's surface (> 0 in free
space, < 0 inside the solid) and `u` the unit direction out of the solid at the nearest surface
point. For a hole this is worked out in the (ρ, z) half-plane of the axis (ρ the distance from
the axis, z the height above the surface) against the three pieces of its boundary — the top
(z = 0, ρ ≥ R), the wall (ρ = R, −D ≤ z ≤ 0) and the bottom (z = −D, ρ ≤ R) — so that the
hole's rim is a rounded edge: a sphere landing on it is pushed both up and toward the axis, as a
peg's tip slides into a chamfered hole; inside the pocket, the wall pushes the tool back toward
the axis and the bottom up. Then, with the tool point moving at `v`,

    penetration δ = r − φ                                (contact while δ > 0)
    normal force f_n = max(0, k·δ − c·(v·u))             (only pushes, never pulls)
    tangential slip v_t = v − (v·u)·u
    friction F_t = −(b + μ·f_n / max(|v_t|, V_SLIP))·v_t
    force F = f_n·u + F_t,   torque about the tool point τ = (−r·u) × F_t

with k `stiffness_n_m`, c `damping_n_s_m`, μ `friction` (Coulomb) and b `viscous_friction_n_s_m`.
The Coulomb part is regularised: below `V_SLIP` (1 cm/s) of slip it is a viscous drag of slope
μ·f_n / V_SLIP (an explicit integrator cannot hold true stiction), so a tool at rest under a
sideways force below μ·f_n creeps slowly instead of sticking. The world's wrench is the sum over
its shapes: the force and torque the world exerts on the tool, at the tool point, on the base
axes ([Fx, Fy, Fz] N, [Tx, Ty, Tz] N·m; pressing the tool down on a table reads +Fz), the sign of
a UR's `actual_TCP_force`. The arm feels it as τ_ext = Jᵀ·W, J the tool point's frame Jacobian on
the base axes (Pinocchio's LOCAL_WORLD_ALIGNED, linear rows first).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from orccadd.state import FloatArray

Vec3 = tuple[float, float, float]
DEFAULT_DAMPING_N_S_M = 100.0
V_SLIP_M_S = 0.01  # the regularised Coulomb friction's slip speed
TINY = 1e-12


class ShapeError(ValueError):
    """A shape's parameter is wrong: `key` names it, the message says its value and what is allowed."""

    def __init__(self, key: str, detail: str) -> None:
        self.key, self.detail = key, detail
        super().__init__(f'"{key}" {detail}')


# ---- the parameters' checks (the control channel's and the config's) -------------------------
def _shown(raw: Any) -> Any:
    return list(raw) if isinstance(raw, tuple) else raw


def vector3(params: dict[str, Any], key: str, default: Any = None) -> Vec3:
    """Three finite numbers `params[key]` (or `default`); `ShapeError` otherwise."""
    raw = params.get(key, default)
    if raw is None:
        raise ShapeError(key, "is required (3 numbers)")
    if not isinstance(raw, list | tuple) or len(raw) != 3:
        raise ShapeError(key, f"(={_shown(raw)!r}) must be 3 numbers")
    try:
        x, y, z = (float(v) for v in raw)
    except (TypeError, ValueError):
        raise ShapeError(key, f"(={_shown(raw)!r}) must be 3 numbers") from None
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise ShapeError(key, f"(={_shown(raw)!r}) must be finite")
    return x, y, z


def non_negative(params: dict[str, Any], key: str, default: float | None, allow_zero: bool = False) -> float:
    """A finite number `params[key]` (or `default`), > 0 (or >= 0 with `allow_zero`)."""
    raw = params.get(key, default)
    if raw is None:
        raise ShapeError(key, "is required")
    try:
        v = float(raw)
    except (TypeError, ValueError):
        raise ShapeError(key, f"(={raw!r}) must be a number") from None
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        raise ShapeError(key, f"(={raw!r}) must be {'>= 0' if allow_zero else '> 0'}")
    return v


def only(params: dict[str, Any], allowed: Sequence[str], what: str) -> None:
    """`ValueError` naming the unknown keys of `params`."""
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise ValueError(f"{what}: unknown parameter(s) {', '.join(unknown)} (allowed: {', '.join(allowed)})")


def unit_normal(params: dict[str, Any], key: str = "normal") -> Vec3:
    nx, ny, nz = vector3(params, key)
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if norm < 1e-9:
        raise ShapeError(key, f"(={_shown(params[key])!r}) must not be zero")
    return nx / norm, ny / norm, nz / norm


def normal_force(stiffness_n_m: float, damping_n_s_m: float, depth_m: float, speed_out_m_s: float) -> float:
    """The spring-damper's push out of a surface, `depth_m` inside it and leaving at
    `speed_out_m_s`: max(0, k·d − c·v), 0 when not inside (d <= 0)."""
    if depth_m <= 0.0:
        return 0.0
    return max(0.0, stiffness_n_m * depth_m - damping_n_s_m * speed_out_m_s)


# ---- the shapes ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Surface:
    """A shape's contact law: stiffness N/m, damping N·s/m, Coulomb coefficient, viscous N·s/m."""

    stiffness_n_m: float
    damping_n_s_m: float = DEFAULT_DAMPING_N_S_M
    friction: float = 0.0
    viscous_friction_n_s_m: float = 0.0


SURFACE_KEYS = ("stiffness_n_m", "damping_n_s_m", "friction", "viscous_friction_n_s_m")
PLANE_KEYS = ("point_m", "normal", *SURFACE_KEYS)
HOLE_KEYS = ("center_m", "normal", "radius_m", "depth_m", *SURFACE_KEYS)


def surface_from_params(params: dict[str, Any]) -> Surface:
    return Surface(
        non_negative(params, "stiffness_n_m", None),
        non_negative(params, "damping_n_s_m", DEFAULT_DAMPING_N_S_M, allow_zero=True),
        non_negative(params, "friction", 0.0, allow_zero=True),
        non_negative(params, "viscous_friction_n_s_m", 0.0, allow_zero=True),
    )


@dataclass(frozen=True)
class Plane:
    """The half-space behind the surface through `point_m`, `normal` (unit) out of it."""

    point_m: Vec3
    normal: Vec3
    surface: Surface

    def distance(self, p: Vec3, out_u: list[float]) -> float:
        """φ (see the module docstring); `out_u` gets u."""
        n = self.normal
        out_u[:] = n
        return (
            (p[0] - self.point_m[0]) * n[0]
            + (p[1] - self.point_m[1]) * n[1]
            + (p[2] - self.point_m[2]) * n[2]
        )

    def describe(self) -> dict[str, Any]:
        return {
            "shape": "plane",
            "point_m": list(self.point_m),
            "normal": list(self.normal),
            **_law(self.surface),
        }


@dataclass(frozen=True)
class Hole:
    """A plane through `center_m` with a cylindrical pocket of `radius_m`, `depth_m` deep
    (math.inf: through) about the axis through `center_m` along `normal`."""

    center_m: Vec3
    normal: Vec3
    radius_m: float
    depth_m: float
    surface: Surface

    def distance(self, p: Vec3, out_u: list[float]) -> float:
        """φ (see the module docstring); `out_u` gets u."""
        n, c, big_r, big_d = self.normal, self.center_m, self.radius_m, self.depth_m
        d = (p[0] - c[0], p[1] - c[1], p[2] - c[2])
        z = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
        radial = (d[0] - z * n[0], d[1] - z * n[1], d[2] - z * n[2])
        rho = math.sqrt(radial[0] ** 2 + radial[1] ** 2 + radial[2] ** 2)
        e = tuple(v / rho for v in radial) if rho > TINY else _perpendicular(n)
        # the nearest point of each boundary piece in (rho, z), and that piece's outward normal
        pieces = [((max(rho, big_r), 0.0), (0.0, 1.0)), ((big_r, min(0.0, max(z, -big_d))), (-1.0, 0.0))]
        if math.isfinite(big_d):
            pieces.append(((min(rho, big_r), -big_d), (0.0, 1.0)))
        best, (qr, qz), (nr, nz) = min((math.hypot(rho - q[0], z - q[1]), q, nrm) for q, nrm in pieces)
        inside = (z < 0.0 and rho > big_r) or z < -big_d
        if best > TINY:
            sign = -1.0 if inside else 1.0
            nr, nz = sign * (rho - qr) / best, sign * (z - qz) / best
        out_u[:] = (nr * e[0] + nz * n[0], nr * e[1] + nz * n[1], nr * e[2] + nz * n[2])
        return -best if inside else best

    def describe(self) -> dict[str, Any]:
        depth = self.depth_m if math.isfinite(self.depth_m) else None
        return {
            "shape": "hole",
            "center_m": list(self.center_m),
            "normal": list(self.normal),
            "radius_m": self.radius_m,
            "depth_m": depth,
            **_law(self.surface),
        }


Shape = Plane | Hole


def _law(s: Surface) -> dict[str, float]:
    return {k: getattr(s, k) for k in SURFACE_KEYS}


def _perpendicular(n: Vec3) -> Vec3:
    """A unit vector perpendicular to the unit vector `n` (the radial direction on the axis)."""
    a = (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)
    x, y, z = a[1] * n[2] - a[2] * n[1], a[2] * n[0] - a[0] * n[2], a[0] * n[1] - a[1] * n[0]
    norm = math.sqrt(x * x + y * y + z * z)
    return x / norm, y / norm, z / norm


def plane_from_params(params: dict[str, Any]) -> Plane:
    """A plane from `{"inject": "plane", ...}` or a config's `world_planes` entry (`ValueError`,
    a `ShapeError` naming the key, if bad)."""
    only(params, PLANE_KEYS, "plane")
    return Plane(vector3(params, "point_m"), unit_normal(params), surface_from_params(params))


def hole_from_params(params: dict[str, Any]) -> Hole:
    """A hole from `{"inject": "hole", ...}` or a config's `world_holes` entry."""
    only(params, HOLE_KEYS, "hole")
    depth = params.get("depth_m")
    return Hole(
        vector3(params, "center_m"),
        unit_normal(params),
        non_negative(params, "radius_m", None),
        math.inf if depth is None else non_negative(params, "depth_m", None),
        surface_from_params(params),
    )


# ---- the world ----------------------------------------------------------------------------
class ContactWorld:
    """The shapes a tool of `tool_radius_m` touches. `shapes` is replaced whole, never changed in
    place, so another thread (a control channel) may set it while the dynamics read it."""

    def __init__(self, shapes: Sequence[Shape] = (), tool_radius_m: float = 0.0) -> None:
        self.shapes: tuple[Shape, ...] = tuple(shapes)
        self.tool_radius_m = tool_radius_m
        self._u = [0.0, 0.0, 0.0]

    def add(self, shape: Shape) -> None:
        self.shapes = (*self.shapes, shape)

    def clear(self) -> None:
        self.shapes = ()

    def wrench_at(
        self, p_m: FloatArray | Sequence[float], v_m_s: FloatArray | Sequence[float], out: FloatArray
    ) -> bool:
        """The world's wrench on the tool at `p_m` moving at `v_m_s` into `out` (6: N, N·m about
        the tool point, base axes); False (and `out` zero) when nothing touches it."""
        out[:] = 0.0
        shapes = self.shapes
        if not shapes:
            return False
        r, u = self.tool_radius_m, self._u
        p = (float(p_m[0]), float(p_m[1]), float(p_m[2]))
        v = (float(v_m_s[0]), float(v_m_s[1]), float(v_m_s[2]))
        touched = False
        for shape in shapes:
            depth = r - shape.distance(p, u)
            if depth <= 0.0:
                continue
            law = shape.surface
            vn = v[0] * u[0] + v[1] * u[1] + v[2] * u[2]
            fn = normal_force(law.stiffness_n_m, law.damping_n_s_m, depth, vn)
            if fn <= 0.0:
                continue
            touched = True
            f = [fn * u[0], fn * u[1], fn * u[2]]
            if law.friction or law.viscous_friction_n_s_m:
                vt = (v[0] - vn * u[0], v[1] - vn * u[1], v[2] - vn * u[2])
                slip = math.sqrt(vt[0] ** 2 + vt[1] ** 2 + vt[2] ** 2)
                drag = law.viscous_friction_n_s_m + law.friction * fn / max(slip, V_SLIP_M_S)
                ft = (-drag * vt[0], -drag * vt[1], -drag * vt[2])
                f[0], f[1], f[2] = f[0] + ft[0], f[1] + ft[1], f[2] + ft[2]
                if r:  # the friction acts at the contact point p − r·u: (−r·u) × F_t about p
                    out[3] -= r * (u[1] * ft[2] - u[2] * ft[1])
                    out[4] -= r * (u[2] * ft[0] - u[0] * ft[2])
                    out[5] -= r * (u[0] * ft[1] - u[1] * ft[0])
            out[0] += f[0]
            out[1] += f[1]
            out[2] += f[2]
        return touched

    def describe(self) -> dict[str, Any]:
        """For a control channel's status and for `describe`."""
        return {"tool_radius_m": self.tool_radius_m, "shapes": [s.describe() for s in self.shapes]}
