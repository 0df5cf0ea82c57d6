"""The commissioning service (pipeline/commissioning/steps.py): every judgement the engine and ``calibrate`` present.

Pure functions on made-up windows and poses -- no rig, no loop, no clock -- so each limit is checked at its edge
and each refusal's words where both front ends show them.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.commissioning.frame_check import AXES, AxisCheck, check_axis
from pipeline.commissioning.payload_identification import CalibrationPose
from pipeline.commissioning.rig_calibration import ToolCalibration
from pipeline.commissioning.steps import (
    CALIBRATION_MAX_CONDITION,
    PAYLOAD_POSE_SETS,
    PIVOT_STILL_M,
    POSE_STILL_DEG,
    POSE_STILL_M,
    REST_MAX_FORCE_N,
    calibration_verdict,
    chain_refusal,
    frame_check_of,
    frames_step,
    payload_step,
    pose_set,
    record_pivot,
    record_pose,
    rest_check_note,
    rest_force_n,
    rest_verdict,
    robot_pose_refusal,
    rotation_angle_deg,
    sensor_stalled,
    tcp_step,
    tcp_target,
)
from pipeline.commissioning.tcp import PivotPose, pivot_orientations
from pipeline.devices.interfaces import PoseSample
from pipeline.force.frames import IDENTITY, Mat3, axis_angle, mat_mul
from pipeline.force.framework import DEFAULT_ROT_HAPTIC_BASE
from pipeline.sim.robot import TOOL_DOWN

G = 9.80665
MASS, COM, BIAS = 0.4, np.array([0.0, 0.01, 0.05]), np.array([0.2, -0.1, 0.3])
TIP = np.array([0.0012, -0.0009, 0.2513])
PIVOT = np.array([0.30, -0.10, 0.12])
MOUNT = axis_angle((0.0, 0.0, 1.0), math.radians(30.0))  # a sensor mounted 30° about the tool axis


def pose(rot: Mat3 = IDENTITY, p: tuple[float, float, float] = (0.3, -0.1, 0.2), t_ns: int = 0) -> PoseSample:
    return PoseSample(t_ns, p, rot)


def wrench_at(rot_base_sensor: Mat3) -> np.ndarray:
    g_s = np.asarray(rot_base_sensor).reshape(3, 3).T @ np.array([0.0, 0.0, -G])
    return np.concatenate([MASS * g_s + BIAS, np.cross(COM, MASS * g_s)])


# -- payload poses ---------------------------------------------------------------------------------------------
def test_a_still_pose_is_averaged_at_the_sensor_orientation_and_measured_against_its_target() -> None:
    tcp = axis_angle((1.0, 0.0, 0.0), 0.7)
    w = np.tile(wrench_at(mat_mul(tcp, MOUNT)), (200, 1))
    w[::2, 0] += 0.01  # noise on fx: a spread, the same mean
    target = axis_angle((1.0, 0.0, 0.0), 0.7 + math.radians(2.0))
    rp = record_pose("P01", w, pose(tcp), pose(tcp, (0.3, -0.1, 0.2 + 0.9 * POSE_STILL_M)), MOUNT,
                     mat_mul(target, MOUNT))
    assert rp.accepted and rp.reason == "" and rp.samples == 200
    assert np.allclose(rp.rot_base_sensor, mat_mul(tcp, MOUNT))
    assert np.allclose(rp.wrench, w.mean(axis=0)) and 0 < rp.force_std_n < 0.01
    assert rp.off_target_deg == pytest.approx(2.0, abs=1e-6)
    assert rp.pose() == CalibrationPose(rp.rot_base_sensor, rp.wrench, "P01")


@pytest.mark.parametrize(("after", "words"), [
    (pose(IDENTITY, (0.3, -0.1, 0.2 + 1.1 * POSE_STILL_M)), "the robot moved while recording (2.20 mm, 0.00°; "
                                                             "allowed 2 mm and 0.5°) — hold it still and record again"),
    (pose(axis_angle((0.0, 1.0, 0.0), math.radians(1.1 * POSE_STILL_DEG))), "the robot moved while recording (0.00 "
                                                                            "mm, 0.55°; allowed 2 mm and 0.5°)"),
    (pose(IDENTITY, (math.nan, 0.0, 0.0)), "no TCP pose received from the robot yet; check the RTDE connection"),
])
def test_a_pose_the_robot_moved_in_or_lost_is_refused_in_words(after: PoseSample, words: str) -> None:
    rp = record_pose("P01", np.zeros((10, 6)), pose(), after, IDENTITY)
    assert not rp.accepted and rp.reason.startswith(words) and "\n" not in rp.reason
    assert all(math.isnan(v) for v in rp.wrench)


def test_non_finite_or_missing_force_readings_are_refused() -> None:
    w = np.zeros((10, 6))
    w[3, 2] = math.inf
    assert record_pose("P01", w, pose(), pose(), IDENTITY).reason == "the force sensor gave non-finite readings"
    assert record_pose("P01", np.zeros((0, 6)), pose(), pose(), IDENTITY).reason == "the force sensor gave no readings"


def test_a_robot_pose_too_old_to_start_from_is_named_with_its_age() -> None:
    assert robot_pose_refusal(pose(t_ns=0), now_ns=400_000_000) == ""
    assert robot_pose_refusal(pose(t_ns=0), now_ns=1_200_000_000) == (
        "the robot's newest TCP pose is 1.2 s old; check the RTDE connection")
    assert robot_pose_refusal(pose(t_ns=0)) == ""  # no clock given: only a missing pose is refused


def test_the_sensor_stalls_above_fifty_milliseconds() -> None:
    assert not sensor_stalled(np.array([], dtype=np.int64))
    assert not sensor_stalled(np.array([1_000_000, 50_000_000]))
    assert sensor_stalled(np.array([1_000_000, 50_000_001]))


# -- the payload step -------------------------------------------------------------------------------------------
def test_the_payload_step_identifies_judges_and_says_what_goes_on_record() -> None:
    poses = [CalibrationPose(r, tuple(wrench_at(r)), f"P{k + 1:02d}") for k, r in enumerate(pose_set("quick"))]
    r = payload_step(poses, "quick")
    assert r.accepted and r.reason == "" and r.n_poses == 6 and r.step == "payload"
    assert r.calibration is not None and r.record is r.calibration
    assert r.calibration.mass_kg == pytest.approx(MASS, abs=1e-9)
    assert r.condition_number == r.calibration.condition_number < CALIBRATION_MAX_CONDITION


def test_a_degenerate_pose_set_is_refused_with_its_condition_and_nothing_goes_on_record() -> None:
    poses = [CalibrationPose(r, tuple(wrench_at(r)), f"P{k + 1:02d}") for k, r in enumerate(pose_set("tool-down only"))]
    r = payload_step(poses, "tool-down only")
    assert not r.accepted and "rank" in r.reason and r.n_poses == 6
    assert r.calibration is None and r.record is None and r.condition_number > CALIBRATION_MAX_CONDITION
    empty = payload_step([], "quick")
    assert not empty.accepted and empty.reason.startswith("no calibration poses given")
    assert empty.condition_number == math.inf


def test_a_fit_is_refused_above_either_limit_with_the_limit_in_the_words() -> None:
    poses = [CalibrationPose(r, tuple(wrench_at(r)), f"P{k + 1:02d}") for k, r in enumerate(pose_set("quick"))]
    cal = payload_step(poses, "quick").calibration
    assert cal is not None and calibration_verdict(cal) == ""
    assert calibration_verdict(replace(cal, condition_number=1000.5)).startswith(
        "condition number 1e+03 is above 1000: the poses do not vary the tool's orientation enough")
    assert calibration_verdict(replace(cal, rms_force_residual_n=0.06)) == (
        "RMS force residual 0.06 N is above 0.05 N: a pose was in contact or the tool moved; check the tool hangs "
        "free and repeat")
    # a bad fit keeps its numbers for the display, but is not recorded
    contact = [replace(p, wrench=(p.wrench[0] + (0.5 if k == 2 else 0.0), *p.wrench[1:])) for k, p in enumerate(poses)]
    r = payload_step(contact, "quick")
    assert not r.accepted and r.reason.startswith("RMS force residual") and r.calibration is not None
    assert r.record is None


def test_pose_sets_and_the_pendant_s_target() -> None:
    assert [len(pose_set(n)) for n in PAYLOAD_POSE_SETS] == [24, 6, 6]
    with pytest.raises(ValueError, match=r"pose set = 'sideways': allowed values are recommended, quick, tool-down "
                                         r"only"):
        pose_set("sideways")
    target = pose_set("quick")[3]
    assert np.allclose(mat_mul(tcp_target(target, MOUNT), MOUNT), target)


# -- TCP ---------------------------------------------------------------------------------------------------------
def test_a_pivot_orientation_becomes_the_flange_pose_behind_the_reported_tcp() -> None:
    rot = pivot_orientations("minimal", TOOL_DOWN)[1]
    r = np.asarray(rot).reshape(3, 3)
    tcp = PIVOT + np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]]) * PIVOT_STILL_M
    rp = record_pivot("O2", tcp, rot, rot, TIP)
    assert rp.accepted and rp.moved_mm == pytest.approx(0.5 * PIVOT_STILL_M * 1e3) and rp.turned_deg < 1e-5
    assert np.allclose(rp.flange_position_m, PIVOT - r @ TIP)
    assert rp.pose() == PivotPose(rot, rp.flange_position_m, "O2")
    moved = record_pivot("O2", tcp * [1.0, 1.0, 1.0] + [[0, 0, 0], [0, 0, 0], [0, 0, 3 * PIVOT_STILL_M]], rot, rot, TIP)
    assert not moved.accepted and moved.reason.startswith("the robot moved while recording (0.4")
    assert moved.reason.endswith("allowed 0.2 mm and 0.2°) — hold it still and record again")
    turned = record_pivot("O2", tcp, rot, mat_mul(axis_angle((1.0, 0.0, 0.0), math.radians(0.3)), rot), TIP)
    assert not turned.accepted and "0.30°" in turned.reason
    lost = record_pivot("O2", [[math.nan, 0.0, 0.0]], rot, rot, TIP)
    assert lost.reason == "no TCP pose received from the robot yet; check the RTDE connection"


def test_the_tcp_step_fits_the_tip_or_refuses_and_nothing_goes_on_record() -> None:
    poses = []
    for k, rot in enumerate(pivot_orientations("recommended", TOOL_DOWN)):
        r = np.asarray(rot).reshape(3, 3)
        poses.append(PivotPose(rot, tuple(PIVOT - r @ TIP), f"O{k + 1}"))
    ok = tcp_step(poses, "recommended", TIP)
    assert ok.accepted and ok.step == "tcp" and ok.n_poses == 8 and ok.record is ok.calibration
    assert ok.error_mm < 1e-9 and math.isnan(tcp_step(poses, "recommended").error_mm)
    bad = tcp_step(poses[:3], "minimal", TIP)
    assert not bad.accepted and bad.reason.startswith("3 orientations recorded: a pivot calibration needs at least 4")
    assert bad.calibration is None and bad.record is None and bad.n_poses == 3


# -- frames ----------------------------------------------------------------------------------------------------
def axis_checks(rot_sensor_error: Mat3 = IDENTITY) -> dict[str, AxisCheck]:
    out = {}
    for axis in AXES:
        e = np.zeros(3)
        e["xyz".index(axis[1])] = 1.0
        base = np.tile(np.asarray(rot_sensor_error).reshape(3, 3) @ e, (50, 1))
        scaled = base @ np.asarray(DEFAULT_ROT_HAPTIC_BASE).reshape(3, 3).T
        out[axis] = check_axis(axis, base, scaled, DEFAULT_ROT_HAPTIC_BASE)
    return out


def test_frame_checks_come_together_once_every_axis_is_in_and_a_failure_names_the_mount() -> None:
    axes = axis_checks()
    assert frame_check_of({a: axes[a] for a in AXES[:2]}, IDENTITY, DEFAULT_ROT_HAPTIC_BASE) is None
    check = frame_check_of(axes, IDENTITY, DEFAULT_ROT_HAPTIC_BASE)
    assert check is not None
    r = frames_step(check, 0.4)
    assert r.passed and r.step == "frames" and r.record is check and r.summary == "Frames and signs: PASS (3 of 3 axes)"
    wrong = frame_check_of(axis_checks(axis_angle((0.0, 0.0, 1.0), math.pi / 2)), IDENTITY,
                           DEFAULT_ROT_HAPTIC_BASE)
    assert wrong is not None
    failed = frames_step(wrong, 90.0)
    assert not failed.passed and failed.record is wrong  # a failed check goes on record too: the gate says why
    assert failed.summary.startswith("Frames and signs: FAIL on +x (90.0° off), +y (90.0° off)")
    assert failed.summary.endswith(" (the payload calibration finds the sensor 90.0° from its configured mount)")
    assert frames_step(wrong, 5.0).summary == wrong.summary() == frames_step(wrong).summary


# -- the chain and the session gate -----------------------------------------------------------------------------
def test_the_chain_runs_in_order() -> None:
    empty = ToolCalibration("grasper")
    assert chain_refusal(empty, "tcp") == ""
    assert chain_refusal(empty, "payload") == (
        "no TCP calibration on record for tool 'grasper'; the chain runs in order: calibrate tcp first")
    assert chain_refusal(empty, "frames") == (
        "no payload calibration on record for tool 'grasper'; the chain runs in order: calibrate payload first")


def test_the_force_at_rest_passes_only_below_its_limit_and_an_override_never_waives_it() -> None:
    assert rest_force_n(np.tile([0.03, -0.04, 0.0], (100, 1))) == pytest.approx(0.05)
    assert rest_verdict(REST_MAX_FORCE_N * 0.999, "grasper") == ""
    assert rest_verdict(REST_MAX_FORCE_N, "grasper") == (
        "the compensated force at rest is 0.100 N over 2 s (limit 0.1 N): the tool touches something, or its payload "
        "calibration does not match the mounted tool 'grasper'; keep it clear and still, or calibrate the payload "
        "again")
    assert rest_verdict(math.nan, "grasper").startswith("the compensated force at rest is nan N")
    assert rest_verdict(0.3, "grasper", overridden=True).endswith("; an override does not waive this check")
    # nothing to "calibrate again" and no contact to look for: the tool has no payload on record, its weight is measured
    assert rest_verdict(4.228, "scalpel", overridden=True, payload_on_record=False) == (
        "the compensated force at rest is 4.228 N over 2 s (limit 0.1 N): no payload calibration is on record for tool "
        "'scalpel', so the tool's own weight counts as force; calibrate the payload first (the calibration wizard's "
        "step 2, or haptic-study calibrate payload); an override does not waive this check")
    # while it is measured: an override's start does not claim a calibration on record
    assert rest_check_note("grasper").startswith("calibration on record for tool 'grasper'; measuring")
    assert rest_check_note("scalpel", overridden=True) == (
        "starting without the calibration chain of tool 'scalpel' (your reason is stored); measuring the compensated "
        "force at rest for 2 s — keep the instrument still and clear of everything")


# -- numerics ----------------------------------------------------------------------------------------------------
_angles = st.floats(-math.pi, math.pi, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(_angles, _angles, _angles)
def test_the_turn_between_orientations_is_a_symmetric_angle_in_range(a: float, b: float, c: float) -> None:
    ra = axis_angle((1.0, 0.0, 0.0), a)
    rb = mat_mul(axis_angle((0.0, 1.0, 0.0), b), axis_angle((0.0, 0.0, 1.0), c))
    d = rotation_angle_deg(ra, rb)
    assert 0.0 <= d <= 180.0 and d == pytest.approx(rotation_angle_deg(rb, ra), abs=1e-6)
    assert rotation_angle_deg(ra, ra) < 1e-5  # acos near 1: the clamp keeps it finite
