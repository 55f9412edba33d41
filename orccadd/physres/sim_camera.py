"""The simulated arm's camera: a pinhole camera on the tool that sees a target of four points.

Eye in hand, as `orccadd.modules.visual` (`image_servo`) expects: the camera's frame is the tool's
(`[tool]`, `RobotModel.tool_frame_id`; z the optical axis, x and y the image's u and v), or that
frame moved by `offset_m` and `offset_rpy_rad`. With (p, R) the camera's pose in the base frame at
the arm's state and P_i the target's points (base frame, `target_points_m`), each read measures

    (X_i, Y_i, Z_i) = Rᵀ·(P_i − p)                  (the point in the camera's frame)
    (x_i, y_i) = (X_i / Z_i, Y_i / Z_i)              (normalised image coordinates)
    u_i = f·x_i + w/2,  v_i = f·y_i + h/2            (pixels: `focal_px` f, `image_size_px` (w, h))

and the target is seen when every point is in front of the camera (Z_i > 1 mm), in the image
(0 <= u_i <= w and 0 <= v_i <= h: |x_i| <= w/2f, |y_i| <= h/2f) and not occluded. Seen: the
signal `features` = (x1, y1, ..., x4, y4) plus white Gaussian noise of `noise_px` / f (the
detector's pixel noise in normalised units; seeded by the resource's `seed`, a stream of its
own), `target_visible` = 1. Not seen: `target_visible` = 0, `features` keep their last values.

Declared in the sim backends' `[resource.settings.camera]` (no table, or `enabled = false`: no
camera, and the resource has no `features` / `target_visible` signals); changed at run time by
`change_camera` (the plant process's control channel: `occlude`, `unocclude`, `target`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.schema import field
from orccadd.errors import ConfigError
from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.physres.contact import only
from orccadd.physres.description import Signal
from orccadd.state import FloatArray

TARGET_POINTS = 4  # the corners of a target, as `image_servo`'s FEATURES
NEAR_M = 0.001  # "in front of the camera": at least this far along its axis
FEATURES = Signal(
    "features",
    2 * TARGET_POINTS,
    "1",
    "the target's points in the image, (x1, y1, ..., x4, y4) = (X/Z, Y/Z) in the camera's frame "
    "(the tool's): measured by the simulated camera; their last seen values while it is not seen",
)
TARGET_VISIBLE = Signal(
    "target_visible",
    1,
    "1",
    "1 while the simulated camera sees the target's four points (in front, in the image, not "
    "occluded), else 0",
)
CAMERA_SIGNALS = (FEATURES, TARGET_VISIBLE)
CAMERA_SIZE = FEATURES.size + TARGET_VISIBLE.size  # what the plant's shared memory carries
# what the control channel changes: an occluder put before the camera, taken away; the target moved
CAMERA_CHANGES = ("occlude", "unocclude", "target")


@dataclass(frozen=True)
class CameraSettings:
    """`[resource.settings.camera]` of the sim backends: the camera and the target it looks for."""

    enabled: bool = field(default=True)
    # the target's four points (base frame), in the order of the features (x1, y1 is the first);
    # none: nothing to see until one is set (`target` on the control channel)
    target_points_m: tuple[tuple[float, ...], ...] = field(default=(), bounds=(-20.0, 20.0))
    focal_px: float = field(default=600.0, bounds=(1.0, 1e5))  # square pixels
    image_size_px: tuple[int, ...] = field(default=(640, 480), bounds=(1, 100000))  # width, height
    noise_px: float = field(default=0.0, bounds=(0.0, 100.0))  # the features' noise (std)
    # the camera's frame in the tool's (image_servo takes them equal: the default)
    offset_m: tuple[float, ...] = field(default=(0.0, 0.0, 0.0), bounds=(-2.0, 2.0))
    offset_rpy_rad: tuple[float, ...] = field(default=(0.0, 0.0, 0.0), bounds=(-math.pi, math.pi))


def camera_of(settings: Any) -> CameraSettings | None:
    """The enabled camera of a sim backend's settings (None: no camera)."""
    camera = getattr(settings, "camera", None)
    return camera if isinstance(camera, CameraSettings) and camera.enabled else None


def camera_signals(config: Any) -> tuple[Signal, ...]:
    """The camera's signals if the robot config's settings enable one (for the description)."""
    return CAMERA_SIGNALS if camera_of(config.backend_settings) is not None else ()


def target_points(raw: Any) -> FloatArray:
    """`TARGET_POINTS` distinct points of 3 finite numbers (m) as a 4×3 array; `ValueError`
    saying what is wrong otherwise (the key is the caller's to name)."""
    shown = [list(p) if isinstance(p, tuple) else p for p in raw] if isinstance(raw, list | tuple) else raw
    what = f"(={shown!r}) must be {TARGET_POINTS} points [x, y, z] (m, base frame)"
    if not isinstance(raw, list | tuple) or len(raw) != TARGET_POINTS:
        raise ValueError(what)
    try:
        points = np.array([[float(v) for v in p] for p in raw])
    except (TypeError, ValueError):
        raise ValueError(what) from None
    if points.shape != (TARGET_POINTS, 3):
        raise ValueError(what)
    if not np.isfinite(points).all():
        raise ValueError(f"(={shown!r}) must be finite")
    for i in range(TARGET_POINTS):
        for j in range(i):
            if np.linalg.norm(points[i] - points[j]) < 1e-6:
                raise ValueError(f"(={shown!r}) must be distinct points: [{j}] and [{i}] are the same")
    return points


def check_camera(camera: CameraSettings | None, file: str) -> None:
    """The checks the schema cannot make; `ConfigError` naming file, key, value and what is allowed."""
    if camera is None:
        return
    key = "resource.settings.camera"
    for name, n in (("image_size_px", 2), ("offset_m", 3), ("offset_rpy_rad", 3)):
        v = getattr(camera, name)
        if len(v) != n:
            raise ConfigError(file, f"{key}.{name}", f"(={list(v)!r}) must have {n} entries")
    if camera.target_points_m:
        try:
            target_points(camera.target_points_m)
        except ValueError as e:
            raise ConfigError(file, f"{key}.target_points_m", str(e)) from None


class SimCamera:
    """The camera on the arm's tool; `measure` at every read fills the resource's `features` and
    `target_visible` signals. `target` and `occluded` are replaced whole (never changed in place),
    so a control channel's thread may set them while a read measures."""

    def __init__(self, model: RobotModel, settings: CameraSettings, seed: int, signals: Mapping[str, Any]):
        self.settings = settings
        self._kin = ToolKinematics(model)
        self._offset = pin.SE3(pin.rpy.rpyToMatrix(*settings.offset_rpy_rad), np.array(settings.offset_m))
        w, h = settings.image_size_px
        self._half_x, self._half_y = w / 2 / settings.focal_px, h / 2 / settings.focal_px
        self._noise_std = settings.noise_px / settings.focal_px
        self._rng = np.random.default_rng([seed, 8])  # a stream of its own beside the others' noise
        self._noise = np.zeros(FEATURES.size)
        self._rel = np.zeros((TARGET_POINTS, 3))
        self._cam = np.zeros((TARGET_POINTS, 3))
        self.features: FloatArray = signals[FEATURES.name]
        self.visible: FloatArray = signals[TARGET_VISIBLE.name]
        self.target: FloatArray | None = (
            target_points(settings.target_points_m) if settings.target_points_m else None
        )
        self.occluded = False

    @staticmethod
    def of(model: RobotModel, settings: Any, seed: int, signals: Mapping[str, Any]) -> SimCamera | None:
        """The camera a sim backend's settings enable, writing into `signals`; None if none."""
        camera = camera_of(settings)
        return SimCamera(model, camera, seed, signals) if camera is not None else None

    def pose(self, q: FloatArray) -> pin.SE3:
        """The camera's placement in the base frame at `q` (a new SE3)."""
        return self._kin.pose(q) * self._offset

    def measure(self, q: FloatArray) -> bool:
        """The image at the arm's configuration `q` into the signals; True if the target is seen."""
        target = self.target  # read once: a control channel may replace it meanwhile
        if target is None or self.occluded:
            self.visible[0] = 0.0
            return False
        pose = self.pose(q)
        cam = self._cam
        np.subtract(target, pose.translation, out=self._rel)
        np.dot(self._rel, pose.rotation, out=cam)  # row i: Rᵀ·(P_i − p)
        z = cam[:, 2]
        if (z <= NEAR_M).any():
            self.visible[0] = 0.0
            return False
        x, y = cam[:, 0] / z, cam[:, 1] / z
        if (np.abs(x) > self._half_x).any() or (np.abs(y) > self._half_y).any():
            self.visible[0] = 0.0
            return False
        self.features[0::2] = x
        self.features[1::2] = y
        if self._noise_std:
            self._rng.standard_normal(out=self._noise)
            self._noise *= self._noise_std
            self.features += self._noise
        self.visible[0] = 1.0
        return True

    def describe(self) -> dict[str, Any]:
        """The camera for a status reply: its target, occluder, what it sees."""
        target = self.target
        return {
            "target_points_m": target.tolist() if target is not None else None,
            "occluded": self.occluded,
            "focal_px": self.settings.focal_px,
            "image_size_px": list(self.settings.image_size_px),
            "target_visible": bool(self.visible[0]),
            "features": self.features.tolist(),
        }


def change_camera(camera: SimCamera | None, what: str, params: dict[str, Any]) -> None:
    """One of `CAMERA_CHANGES` with its parameters (`ValueError` naming what is wrong)."""
    if camera is None:
        raise ValueError(f"{what}: the arm has no camera (none in [resource.settings.camera])")
    if what in ("occlude", "unocclude"):
        only(params, (), what)
        camera.occluded = what == "occlude"
    elif what == "target":
        only(params, ("points_m",), what)
        if "points_m" not in params:
            raise ValueError(f'{what}: "points_m" is required ({TARGET_POINTS} points [x, y, z])')
        try:
            camera.target = target_points(params["points_m"])
        except ValueError as e:
            raise ValueError(f'{what}: "points_m" {e}') from None
    else:
        raise ValueError(f"unknown fault {what!r} (faults: {', '.join(CAMERA_CHANGES)})")
