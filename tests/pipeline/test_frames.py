"""Tests of rotations, the S→T→B→H force chain and the wrench transform (paper eqs. 1–4).

External references: scipy.spatial.transform.Rotation for rotation vectors and a
NumPy 6×6 block matrix for eq. (1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.force.frames import (
    IDENTITY,
    as_mat3,
    axis_angle,
    check_rotation,
    cross,
    det3,
    mat_mul,
    mat_vec,
    matrix_to_rotvec,
    orthonormality_error,
    rotvec_to_matrix,
    sensor_to_haptic_chain,
    skew,
    transpose,
    wrench_transform,
)
from pipeline.force.scaling import clamp_norm

PI = math.pi

# ---------------------------------------------------------------------------
# strategies

unit_axis = st.tuples(
    st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)
).filter(lambda v: math.hypot(*v) > 1e-3).map(lambda v: tuple(c / math.hypot(*v) for c in v))

SPECIAL_ANGLES = [
    0.0, 1e-300, 1e-12, 1e-9, 1e-8, 1e-6, 9.99e-5, 1e-4, 1.0001e-4, 1e-3, PI / 2,
    PI - 1e-2, PI - 1e-3 - 1e-12, PI - 1e-3, PI - 1e-3 + 1e-12, PI - 1e-6, PI - 1e-9,
    PI - 1e-12, PI,
]
angle_0_pi = st.one_of(st.sampled_from(SPECIAL_ANGLES), st.floats(0.0, PI))
angle_any = st.one_of(angle_0_pi, st.floats(PI, 4 * PI), st.sampled_from([2 * PI, 3 * PI, PI + 1e-9]))
forces = st.tuples(*[st.floats(-130.0, 130.0)] * 3)  # Gamma SI-130-10 range
torques = st.tuples(*[st.floats(-10.0, 10.0)] * 3)
positions = st.tuples(*[st.floats(-1.0, 1.0)] * 3)


@st.composite
def rotvecs(draw, angles=angle_0_pi):
    k = draw(unit_axis)
    th = draw(angles)
    return tuple(c * th for c in k), k, th


@st.composite
def rotations(draw):
    """A rotation matrix (Mat3) from a random unit quaternion via scipy."""
    q = draw(st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: math.sqrt(sum(c * c for c in q)) > 1e-3))
    return tuple(float(c) for c in Rotation.from_quat(q).as_matrix().ravel())


def max_abs_diff(a, b) -> float:
    return max(abs(x - y) for x, y in zip(a, b, strict=True))


def rotvec_distance_mod_2pi(r2, r, k, th) -> float:
    """Distance of r2 from r, or from r - 2π·k (the same rotation), whichever is closer."""
    alt = tuple(c - 2 * PI * kc for c, kc in zip(r, k, strict=True))
    return min(max_abs_diff(r2, r), max_abs_diff(r2, alt))


# ---------------------------------------------------------------------------
# rotation vectors


@given(rotvecs(angle_any))
@example(((PI / 2, 0.0, 0.0), (1.0, 0.0, 0.0), PI / 2))
@example(((0.0, 0.0, 1e-12), (0.0, 0.0, 1.0), 1e-12))
@example(((PI, 0.0, 0.0), (1.0, 0.0, 0.0), PI))
def test_rotvec_to_matrix_matches_scipy(rk):
    r, _, _ = rk
    m = rotvec_to_matrix(*r)
    expected = Rotation.from_rotvec(r).as_matrix().ravel()
    assert max_abs_diff(m, expected) <= 1e-14


@given(rotvecs(angle_any))
def test_rotvec_to_matrix_is_orthonormal_with_det_plus_one(rk):
    m = rotvec_to_matrix(*rk[0])
    assert len(m) == 9 and all(type(c) is float for c in m)
    assert orthonormality_error(m) < 1e-14
    assert abs(det3(m) - 1.0) < 1e-14


@given(rotvecs())
def test_rotvec_round_trip(rk):
    r, k, th = rk
    m = rotvec_to_matrix(*r)
    r2 = matrix_to_rotvec(m)
    m2 = rotvec_to_matrix(*r2)
    assert max_abs_diff(m2, m) <= 1e-12
    assert math.hypot(*r2) <= PI + 1e-15
    # r and r - 2πk are the same rotation; they only both lie in [0, π] at θ = π.
    assert rotvec_distance_mod_2pi(r2, r, k, th) <= 1e-12, (r, r2)
    if th < PI - 1e-12:
        assert max_abs_diff(r2, r) <= 1e-12, (r, r2)


@given(unit_axis, st.sampled_from([1e-12, 1e-9, 1e-6, 1e-4, PI - 1e-3, PI - 1e-6, PI - 1e-9]))
def test_round_trip_picks_the_right_sign_just_below_pi_and_keeps_tiny_angles(k, th):
    r = tuple(c * th for c in k)
    r2 = matrix_to_rotvec(rotvec_to_matrix(*r))
    assert max_abs_diff(r2, r) <= 1e-12
    # relative accuracy for tiny rotations (not just "close to zero")
    assert math.hypot(*r2) == pytest.approx(th, rel=1e-12)


@given(unit_axis, st.floats(PI + 1e-6, 2 * PI - 1e-6))
def test_angles_above_pi_come_back_as_the_short_way_round(k, th):
    r = tuple(c * th for c in k)
    r2 = matrix_to_rotvec(rotvec_to_matrix(*r))
    expected = tuple(-c * (2 * PI - th) for c in k)
    assert max_abs_diff(r2, expected) <= 1e-12


@pytest.mark.parametrize(
    "axis",
    [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 1, -1), (1, 1, 1), (-1, 2, 0.5), (1e-3, 0, 1)],
)
def test_exactly_pi_round_trips_modulo_sign(axis):
    n = math.sqrt(sum(c * c for c in axis))
    k = tuple(c / n for c in axis)
    r = tuple(c * PI for c in k)
    m = rotvec_to_matrix(*r)
    r2 = matrix_to_rotvec(m)
    assert math.hypot(*r2) == pytest.approx(PI, abs=1e-15)
    assert min(max_abs_diff(r2, r), max_abs_diff(r2, tuple(-c for c in r))) <= 1e-12
    assert max_abs_diff(rotvec_to_matrix(*r2), m) <= 1e-12


@given(rotations())
def test_matrix_to_rotvec_matches_scipy_and_round_trips(m):
    r2 = matrix_to_rotvec(m)
    ref = Rotation.from_matrix(np.array(m).reshape(3, 3)).as_rotvec()
    th = float(np.linalg.norm(ref))
    if th > 1e-300:
        k = tuple(float(c) / th for c in ref)
        assert rotvec_distance_mod_2pi(r2, tuple(ref), k, th) <= 1e-12
    else:
        assert max_abs_diff(r2, (0.0, 0.0, 0.0)) <= 1e-12
    assert max_abs_diff(rotvec_to_matrix(*r2), m) <= 1e-12


def test_identity_and_zero_rotvec():
    assert rotvec_to_matrix(0.0, 0.0, 0.0) == IDENTITY
    assert matrix_to_rotvec(IDENTITY) == (0.0, 0.0, 0.0)


def test_axis_angle():
    m = axis_angle((0.0, 0.0, 2.0), PI / 2)  # axis need not be unit length
    expected = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert max_abs_diff(m, expected) <= 1e-15
    for bad in [(0.0, 0.0, 0.0), (math.nan, 0.0, 1.0)]:
        with pytest.raises(ValueError):
            axis_angle(bad, 1.0)


# hardware.md §3c: UR3 FK unit-test vectors


def test_ur_rotvec_quarter_turn_about_x():
    m = rotvec_to_matrix(PI / 2, 0.0, 0.0)
    expected = Rotation.from_rotvec([PI / 2, 0.0, 0.0]).as_matrix().ravel()
    assert max_abs_diff(m, expected) <= 1e-14
    # by hand: Rx(90°)
    assert max_abs_diff(m, (1, 0, 0, 0, 0, -1, 0, 1, 0)) <= 1e-15
    assert max_abs_diff(matrix_to_rotvec(m), (PI / 2, 0.0, 0.0)) <= 1e-12


def test_ur_rotvec_half_turn_about_y_minus_z():
    r = (0.0, 2.22144, -2.22144)  # |r| = 3.14159..., 2.7e-6 short of π
    m = rotvec_to_matrix(*r)
    expected = Rotation.from_rotvec(r).as_matrix().ravel()
    assert max_abs_diff(m, expected) <= 1e-14
    # by hand: a half turn about (0, 1, -1)/√2 is 2kkᵀ - I (to the 6-digit rounding of r)
    assert max_abs_diff(m, (-1, 0, 0, 0, 0, -1, 0, -1, 0)) <= 1e-5
    assert orthonormality_error(m) < 1e-14
    assert max_abs_diff(matrix_to_rotvec(m), r) <= 1e-12


# ---------------------------------------------------------------------------
# check_rotation

GOOD = [
    IDENTITY,
    rotvec_to_matrix(PI / 2, 0.0, 0.0),
    rotvec_to_matrix(0.0, 2.22144, -2.22144),
    rotvec_to_matrix(0.3, -1.1, 0.7),
]


@pytest.mark.parametrize("m", GOOD)
@pytest.mark.parametrize("form", ["flat", "nested", "numpy", "numpy-flat"])
def test_check_rotation_accepts_rotations(m, form):
    arg = {
        "flat": list(m),
        "nested": [list(m[0:3]), list(m[3:6]), list(m[6:9])],
        "numpy": np.array(m).reshape(3, 3),
        "numpy-flat": np.array(m),
    }[form]
    out = check_rotation(arg, "rot_tip_sensor")
    assert out == tuple(m)
    assert all(type(c) is float for c in out)


def test_check_rotation_accepts_a_rotation_typed_with_limited_digits():
    m = [[0.866025, -0.5, 0.0], [0.5, 0.866025, 0.0], [0.0, 0.0, 1.0]]  # Rz(30°), 6 digits
    assert check_rotation(m, "rot_haptic_base") == tuple(v for row in m for v in row)


@given(rotations())
def test_check_rotation_accepts_random_rotations(m):
    assert check_rotation(m, "rot_base_tip") == m


BAD = {
    "scaled": ([[1.01, 0.0, 0.0], [0.0, 1.01, 0.0], [0.0, 0.0, 1.01]], "not a rotation"),
    "shear": ([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "not a rotation"),
    "reflection": ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]], "det = -1"),
    "minus-rotation": ([-c for c in rotvec_to_matrix(0.3, -1.1, 0.7)], "reflection"),
    "nan": ([[1.0, 0.0, 0.0], [0.0, math.nan, 0.0], [0.0, 0.0, 1.0]], "finite"),
    "inf": ([math.inf, 0, 0, 0, 1, 0, 0, 0, 1], "finite"),
    "2x2": ([[1.0, 0.0], [0.0, 1.0]], "3x3"),
    "row-of-2": ([[1.0, 0.0, 0.0], [0.0, 1.0], [0.0, 0.0, 1.0]], "row of length 2"),
    "8-numbers": ([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], "3x3"),
    "4x3": (np.eye(4, 3), "3x3"),
    "scalar": (1.0, "3x3"),
    "None": (None, "3x3"),
}


@pytest.mark.parametrize("case", list(BAD))
@pytest.mark.parametrize("name", ["rot_tip_sensor", "calibration.rot_haptic_base"])
def test_check_rotation_rejects_with_field_and_value(case, name):
    m, why = BAD[case]
    with pytest.raises(ValueError) as info:
        check_rotation(m, name)
    msg = str(info.value)
    assert name in msg
    assert repr(m) in msg  # the offending value, as the user wrote it
    assert why in msg


def test_check_rotation_tolerance():
    m = list(rotvec_to_matrix(0.3, -1.1, 0.7))
    m[4] += 1e-9
    check_rotation(m, "r")  # rounding of typed-in matrices is fine
    m[4] += 1e-4
    with pytest.raises(ValueError, match="r = "):
        check_rotation(m, "r")
    with pytest.raises(ValueError):
        check_rotation(m, "r", tol=1e-12)


# ---------------------------------------------------------------------------
# small helpers against NumPy


@given(rotations(), rotations(), forces)
def test_mat_helpers_match_numpy(a, b, v):
    na, nb = np.array(a).reshape(3, 3), np.array(b).reshape(3, 3)
    assert max_abs_diff(mat_vec(a, v), na @ np.array(v)) <= 1e-12
    assert max_abs_diff(mat_mul(a, b), (na @ nb).ravel()) <= 1e-15
    assert transpose(a) == tuple(na.T.ravel())
    assert det3(a) == pytest.approx(np.linalg.det(na), abs=1e-14)
    assert max_abs_diff(cross(v, a[0:3]), np.cross(v, a[0:3])) <= 1e-12
    assert max_abs_diff(mat_vec(skew(v), a[3:6]), np.cross(v, a[3:6])) <= 1e-12


def test_as_mat3_shapes():
    flat = tuple(float(i) for i in range(9))
    assert as_mat3(range(9)) == flat
    assert as_mat3(np.arange(9.0).reshape(3, 3)) == flat
    with pytest.raises(TypeError):
        as_mat3(3.0)
    with pytest.raises(ValueError):
        as_mat3([1.0, 2.0])


# ---------------------------------------------------------------------------
# the force chain S -> T -> B -> H (eqs. TCP, Base, Haptic)


@given(rotations(), rotations(), rotations(), forces)
@example(
    tuple(rotvec_to_matrix(0.0, 0.0, PI / 2)),
    rotvec_to_matrix(PI / 2, 0.0, 0.0),
    rotvec_to_matrix(0.0, 2.22144, -2.22144),
    (10.0, -5.0, 130.0),
)
def test_force_frame_round_trip(rot_tip_sensor, rot_base_tip, rot_haptic_base, f_s):
    f_t = mat_vec(rot_tip_sensor, f_s)
    f_b = mat_vec(rot_base_tip, f_t)
    f_h = mat_vec(rot_haptic_base, f_b)
    back = mat_vec(transpose(rot_tip_sensor),
                   mat_vec(transpose(rot_base_tip), mat_vec(transpose(rot_haptic_base), f_h)))
    assert max_abs_diff(back, f_s) <= 1e-12
    # rotations preserve the magnitude of the force
    assert math.hypot(*f_h) == pytest.approx(math.hypot(*f_s), abs=1e-12)


@given(rotations(), rotations(), rotations(), forces)
def test_sensor_to_haptic_chain_equals_chained_mat_vec(rot_tip_sensor, rot_base_tip, rot_haptic_base, f_s):
    chain = sensor_to_haptic_chain(rot_tip_sensor, rot_base_tip, rot_haptic_base)
    stepwise = mat_vec(rot_haptic_base, mat_vec(rot_base_tip, mat_vec(rot_tip_sensor, f_s)))
    assert max_abs_diff(mat_vec(chain, f_s), stepwise) <= 1e-12
    assert orthonormality_error(chain) < 1e-14
    assert abs(det3(chain) - 1.0) < 1e-14


def test_sensor_to_haptic_chain_order():
    # Three distinct quarter turns; the product does not commute, so this pins the order
    # H←B · B←T · T←S of eqs. (TCP), (Base), (Haptic).
    rts = rotvec_to_matrix(PI / 2, 0.0, 0.0)
    rbt = rotvec_to_matrix(0.0, PI / 2, 0.0)
    rhb = rotvec_to_matrix(0.0, 0.0, PI / 2)
    chain = sensor_to_haptic_chain(rts, rbt, rhb)
    expected = (np.array(rhb).reshape(3, 3) @ np.array(rbt).reshape(3, 3) @ np.array(rts).reshape(3, 3)).ravel()
    assert max_abs_diff(chain, expected) <= 1e-15
    wrong = (np.array(rts).reshape(3, 3) @ np.array(rbt).reshape(3, 3) @ np.array(rhb).reshape(3, 3)).ravel()
    assert max_abs_diff(chain, wrong) > 0.5


# ---------------------------------------------------------------------------
# the wrench transform, eq. (1)


def block_matrix(r, p) -> np.ndarray:
    rr = np.array(r).reshape(3, 3)
    sp = np.array(skew(p)).reshape(3, 3)
    assert np.allclose(sp @ np.array([1.0, 2.0, 3.0]), np.cross(p, [1.0, 2.0, 3.0]))
    return np.block([[rr, np.zeros((3, 3))], [sp @ rr, rr]])


@given(rotations(), positions, forces, torques)
def test_wrench_transform_matches_block_matrix_of_eq_1(r, p, f, tau):
    f_j, tau_j = wrench_transform(r, p, f, tau)
    expected = block_matrix(r, p) @ np.array(f + tau)
    assert max_abs_diff(f_j + tau_j, expected) <= 1e-12


def test_pure_force_at_an_offset_gives_the_lever_torque():
    # 10 N downward (-z) acting 0.1 m along +x, no rotation: τ = P × f = (0, 1, 0) N·m
    f_j, tau_j = wrench_transform(IDENTITY, (0.1, 0.0, 0.0), (0.0, 0.0, -10.0), (0.0, 0.0, 0.0))
    assert f_j == (0.0, 0.0, -10.0)
    assert tau_j == (0.0, 1.0, 0.0)


def test_force_and_torque_with_rotation_and_offset():
    # R = Rz(90°) (exact), f_i = 10 N along x_i -> f_j = 10 N along y_j; P = 0.2 m along z_j:
    # lever P × f_j = (0,0,0.2) × (0,10,0) = (-2, 0, 0); own torque τ_i = (0,0,1) -> R τ_i = (0,0,1).
    rz = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    f_j, tau_j = wrench_transform(rz, (0.0, 0.0, 0.2), (10.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert f_j == (0.0, 10.0, 0.0)
    assert tau_j == (-2.0, 0.0, 1.0)


@given(rotations(), positions, forces)
def test_force_part_of_wrench_uses_rotation_only(r, p, f):
    f_j, _ = wrench_transform(r, p, f, (0.0, 0.0, 0.0))
    assert f_j == mat_vec(r, f)


# ---------------------------------------------------------------------------
# clamp_norm (used by the scaling stage)


@given(st.tuples(*[st.floats(-1e299, 1e299)] * 3), st.floats(1e-3, 1e3))
@example((1e299, 1e299, 0.0), 3.0)
@example((3.0, 0.0, 0.0), 3.0)
@example((3.0000000000000004, 0.0, 0.0), 3.0)
@example((1.0, 1.0, 1.0), math.sqrt(3.0))
def test_clamp_norm_bounds_and_preserves_small_vectors(v, limit):
    out = clamp_norm(v, limit)
    assert math.hypot(*out) <= limit
    if math.hypot(*v) <= limit:
        assert out == v
    else:
        # shrunk by only a few ulps beyond what the limit requires
        assert math.hypot(*out) >= limit * (1 - 8 * 2.0**-52)
