"""The contact world's geometry and law (no arm): planes push out along their normal, a hole lets
the tool through its opening, its wall and rim push toward its axis, friction opposes the slip."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orccadd.physres.contact import (
    V_SLIP_M_S,
    ContactWorld,
    ShapeError,
    hole_from_params,
    plane_from_params,
)

FLOOR = {
    "point_m": [0.0, 0.0, 0.1],
    "normal": [0.0, 0.0, 2.0],
    "stiffness_n_m": 1000.0,
    "damping_n_s_m": 10.0,
}
HOLE = {"center_m": [0.5, 0.0, 0.1], "normal": [0, 0, 1], "radius_m": 0.01, "stiffness_n_m": 1000.0}


def wrench(world: ContactWorld, p: list[float], v: list[float] | None = None) -> tuple[bool, np.ndarray]:
    out = np.full(6, np.nan)
    touched = world.wrench_at(p, v or [0.0, 0.0, 0.0], out)
    return touched, out


def test_a_plane_pushes_out_along_its_normal_as_a_spring_damper_that_never_pulls() -> None:
    w = ContactWorld([plane_from_params(FLOOR)])
    assert wrench(w, [0.3, 0.2, 0.101]) == (False, pytest.approx(np.zeros(6)))  # above it
    touched, out = wrench(w, [0.3, 0.2, 0.098])  # 2 mm in: k·d
    assert touched and out == pytest.approx([0, 0, 2.0, 0, 0, 0])
    assert wrench(w, [0, 0, 0.098], [0, 0, -0.1])[1][2] == pytest.approx(2.0 + 1.0)  # going in: + c·v
    assert wrench(w, [0, 0, 0.098], [0, 0, 0.5]) == (
        False,
        pytest.approx(np.zeros(6)),
    )  # leaving fast: no pull


def test_a_tool_sphere_touches_a_radius_earlier() -> None:
    w = ContactWorld([plane_from_params(FLOOR)], tool_radius_m=0.005)
    assert wrench(w, [0, 0, 0.103])[1][2] == pytest.approx(1000.0 * 0.002)


def test_friction_opposes_the_slip_and_its_moment_acts_at_the_contact_point() -> None:
    params = {**FLOOR, "damping_n_s_m": 0.0, "friction": 0.5, "viscous_friction_n_s_m": 20.0}
    w = ContactWorld([plane_from_params(params)], tool_radius_m=0.01)
    touched, out = wrench(w, [0, 0, 0.1], [0.2, 0, 0])  # 1 cm in (the radius), sliding along +x
    fn = 10.0
    assert touched and out[2] == pytest.approx(fn)
    assert out[0] == pytest.approx(-(20.0 * 0.2 + 0.5 * fn))
    # the friction at the sphere's bottom (−r·z) about its centre: (−r ẑ) × (Fx x̂) = −r·Fx ŷ
    assert out[3:] == pytest.approx([0.0, -0.01 * out[0], 0.0])
    slow = wrench(w, [0, 0, 0.1], [V_SLIP_M_S / 2, 0, 0])[1][0]  # regularised below V_SLIP
    assert slow == pytest.approx(-(20.0 * V_SLIP_M_S / 2 + 0.5 * fn / 2))


def test_a_hole_lets_the_tool_through_its_opening_and_not_beside_it() -> None:
    w = ContactWorld([hole_from_params(HOLE)], tool_radius_m=0.002)
    assert wrench(w, [0.5, 0.0, 0.05])[0] is False  # on the axis, 5 cm below the surface
    assert wrench(w, [0.505, 0.003, 0.0])[0] is False  # through: no bottom
    touched, out = wrench(w, [0.53, 0.0, 0.099])  # beside: the surface, 1 mm + r in
    assert touched and out == pytest.approx([0, 0, 1000.0 * 0.003, 0, 0, 0])


def test_inside_the_hole_its_wall_pushes_toward_the_axis_and_its_bottom_up() -> None:
    w = ContactWorld([hole_from_params({**HOLE, "depth_m": 0.02})], tool_radius_m=0.002)
    touched, out = wrench(w, [0.5, 0.009, 0.09])  # 1 cm down, 9 mm off the axis: 1 mm in the wall
    assert touched and out == pytest.approx([0, -1000.0 * 0.001, 0, 0, 0, 0])
    touched, out = wrench(w, [0.5, 0.0, 0.081])  # 1 mm above the bottom, the sphere 1 mm into it
    assert touched and out == pytest.approx([0, 0, 1000.0 * 0.001, 0, 0, 0])
    touched, out = wrench(w, [0.5, 0.0, 0.075])  # below the bottom: pushed back up
    assert touched and out[2] == pytest.approx(1000.0 * (0.005 + 0.002))


def test_the_hole_rim_is_a_rounded_edge_pushing_up_and_toward_the_axis() -> None:
    w = ContactWorld([hole_from_params(HOLE)], tool_radius_m=0.003)
    # the sphere's centre 1 mm above the surface, 1 mm inside the rim: the rim 1.414 mm away
    touched, out = wrench(w, [0.5 + 0.009, 0.0, 0.101])
    depth = 0.003 - math.sqrt(2) * 0.001
    assert touched and out[:3] == pytest.approx(
        [-1000 * depth / math.sqrt(2), 0, 1000 * depth / math.sqrt(2)]
    )


def test_several_shapes_add_and_clear_removes_them() -> None:
    w = ContactWorld([plane_from_params(FLOOR)])
    w.add(plane_from_params({**FLOOR, "point_m": [0.2, 0, 0], "normal": [-1, 0, 0]}))
    assert wrench(w, [0.201, 0, 0.099])[1][:3] == pytest.approx([-1.0, 0, 1.0])
    assert [s["shape"] for s in w.describe()["shapes"]] == ["plane", "plane"]
    w.clear()
    assert wrench(w, [0.201, 0, 0.099])[0] is False and w.describe()["shapes"] == []


@pytest.mark.parametrize(
    ("make", "params", "key", "message"),
    [
        (plane_from_params, {**FLOOR, "normal": [0, 0, 0]}, "normal", "must not be zero"),
        (plane_from_params, {**FLOOR, "stiffness_n_m": -5}, "stiffness_n_m", "must be > 0"),
        (plane_from_params, {**FLOOR, "damping_n_s_m": -1}, "damping_n_s_m", "must be >= 0"),
        (plane_from_params, {**FLOOR, "point_m": [0, 0]}, "point_m", "must be 3 numbers"),
        (plane_from_params, {**FLOOR, "friction": "much"}, "friction", "must be a number"),
        (hole_from_params, {**HOLE, "radius_m": 0}, "radius_m", "must be > 0"),
        (hole_from_params, {**HOLE, "depth_m": -0.1}, "depth_m", "must be > 0"),
    ],
)
def test_a_bad_shape_is_refused_naming_the_parameter_and_its_value(make, params, key, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ShapeError, match=message) as e:
        make(params)
    assert e.value.key == key


def test_an_unknown_parameter_is_refused_listing_the_allowed_ones() -> None:
    with pytest.raises(
        ValueError, match=r"plane: unknown parameter\(s\) stifness .*allowed: point_m, normal"
    ):
        plane_from_params({**FLOOR, "stifness": 1})
