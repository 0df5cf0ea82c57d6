"""The commissioning chain's pieces: pivot calibration, frame and sign check, the calibration file and its gate.

The simulated rig carries each step out (pipeline/sim/commissioning.py); the
truths it hides (the tip offset, a sensor mounted 90° off) must come back out
of the same code the real rig runs.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.commissioning.frame_check import AXES, FrameCheck, check_axis
from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile, ToolCalibration
from pipeline.commissioning.tcp import DegeneratePivotError, PivotPose, identify_tip, pivot_orientations
from pipeline.force.frames import IDENTITY, axis_angle, mat_mul
from pipeline.force.framework import DEFAULT_ROT_HAPTIC_BASE
from pipeline.force.payload_compensator import NO_PAYLOAD
from pipeline.sim.commissioning import pivot_poses, push_axes
from pipeline.sim.rig import SimRig, SimRigConfig
from pipeline.sim.robot import TOOL_DOWN


# -- TCP pivot calibration -------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("name", ["recommended", "minimal"])
def test_pivot_calibration_recovers_the_simulated_tip_within_half_a_millimetre(seed: int, name: str) -> None:
    rig = SimRig(SimRigConfig(seed=seed))
    tc = identify_tip(pivot_poses(rig, pivot_orientations(name, TOOL_DOWN)))
    err = np.linalg.norm(np.subtract(tc.tip_in_flange_m, rig.config.tip_in_flange_m))
    assert err < 0.5e-3
    assert np.linalg.norm(np.subtract(tc.pivot_base_m, rig.config.pivot_m)) < 0.5e-3
    assert 1e-6 < tc.rms_residual_m < 2e-4 and tc.n_poses == (8 if name == "recommended" else 4)


def test_pivot_calibration_is_exact_on_noise_free_poses() -> None:
    t, q = np.array([0.002, -0.001, 0.25]), np.array([0.3, 0.1, 0.05])
    poses = [PivotPose(r, tuple(q - np.asarray(r).reshape(3, 3) @ t), f"O{k}")
             for k, r in enumerate(pivot_orientations("minimal", TOOL_DOWN))]
    tc = identify_tip(poses)
    assert tc.tip_in_flange_m == pytest.approx(tuple(t), abs=1e-12)
    assert tc.pivot_base_m == pytest.approx(tuple(q), abs=1e-12) and tc.rms_residual_m < 1e-12


def test_a_roll_only_set_is_refused_naming_the_undetermined_axis_and_what_to_add() -> None:
    rig = SimRig()
    with pytest.raises(DegeneratePivotError) as info:
        identify_tip(pivot_poses(rig, pivot_orientations("roll only", TOOL_DOWN)))
    assert str(info.value) == (
        "the orientations are too alike: the tip's offset along the flange z axis is not determined (the instrument "
        "turned 0.0° about axes across it, need at least 20°); add orientations tilted at least 20° about the flange x "
        "or y axis, with the tip kept in the divot")


def test_tilting_about_one_axis_only_leaves_that_axis_undetermined() -> None:
    rots = [mat_mul(axis_angle((1.0, 0.0, 0.0), math.radians(a)), TOOL_DOWN) for a in (-30, -10, 10, 30)]
    with pytest.raises(DegeneratePivotError,
                       match=r"along the flange x axis is not determined .* about the flange y or z"):
        identify_tip(pivot_poses(SimRig(), rots))


def test_orientations_too_close_together_are_refused() -> None:
    with pytest.raises(DegeneratePivotError, match=r"turned 10\.0° about axes across it, need at least 20°"):
        identify_tip(pivot_poses(SimRig(), pivot_orientations("recommended", TOOL_DOWN, tilt_deg=5.0)))


def test_too_few_orientations_and_a_tip_that_slipped_are_refused() -> None:
    rig = SimRig()
    poses = pivot_poses(rig, pivot_orientations("recommended", TOOL_DOWN))
    with pytest.raises(DegeneratePivotError, match=r"^3 orientations recorded: a pivot calibration needs at least 4"):
        identify_tip(poses[:3])
    slipped = list(poses)
    p = slipped[2]
    slipped[2] = PivotPose(p.rot_base_flange, (p.position_m[0] + 0.004, *p.position_m[1:]), p.label)
    with pytest.raises(ValueError, match=r"RMS residual 1\.\d\d mm is above 1 mm \(worst O3: "):
        identify_tip(slipped)


@given(st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_pivot_calibration_recovers_any_tip_and_pivot(t: list[float], q: list[float]) -> None:
    tt, qq = np.asarray(t) * 1e-3, np.asarray(q)
    rots = pivot_orientations("recommended", TOOL_DOWN)
    poses = [PivotPose(r, tuple(qq - np.asarray(r).reshape(3, 3) @ tt)) for r in rots]
    tc = identify_tip(poses)
    assert np.allclose(tc.tip_in_flange_m, tt, atol=1e-9) and np.allclose(tc.pivot_base_m, qq, atol=1e-9)


# -- frame and sign check ----------------------------------------------------------------------------------
def test_the_frame_check_passes_on_a_correct_rig_and_fails_a_sensor_mounted_90_degrees_off() -> None:
    good = build_sim_engine(EngineConfig(clock="virtual", driver="hold", haptics_on=False))
    assert good.ring is not None
    fc = push_axes(good.rig, good.loop, good.ring)
    assert fc.passed and [a.axis for a in fc.axes] == list(AXES)
    assert all(a.base_angle_deg < 3.0 and a.haptic_angle_deg < 3.0 for a in fc.axes)
    assert fc.summary() == "Frames and signs: PASS (3 of 3 axes)"

    bad = build_sim_engine(EngineConfig(clock="virtual", driver="hold", haptics_on=False,
                                        sim=SimRigConfig(sensor_z_mount_deg=90.0)))
    assert bad.ring is not None
    fc = push_axes(bad.rig, bad.loop, bad.ring)
    assert not fc.passed and [a.axis for a in fc.failed] == ["+x", "+y"]
    for a in fc.failed:
        assert a.base_angle_deg == pytest.approx(90.0, abs=3.0) and a.haptic_angle_deg == pytest.approx(90.0, abs=3.0)
    assert fc.summary().startswith("Frames and signs: FAIL on +x (8") and "+y (9" in fc.summary()
    # the payload calibration absorbed the mount for the weight -- which is why nothing else noticed
    assert bad.calibration.mount_angle_deg == pytest.approx(90.0, abs=1.0)


def test_a_sign_error_in_the_haptic_rotation_fails_only_the_haptic_side() -> None:
    # what the pipeline would render with a base→haptic rotation that has two signs wrong (still a rotation)
    flipped_rot = (-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0)
    base = np.tile([1.0, 0.0, 0.0], (200, 1))
    scaled = base @ np.asarray(flipped_rot).reshape(3, 3).T
    a = check_axis("+x", base, scaled, DEFAULT_ROT_HAPTIC_BASE)
    assert a.base_angle_deg == pytest.approx(0.0, abs=1e-9) and a.haptic_angle_deg == pytest.approx(180.0)
    assert not a.passed and "along -x (left)" in a.describe()


def test_one_axis_felt_opposite_while_the_others_pass_is_a_push_the_wrong_way_not_a_mounting_error() -> None:
    """A first-day experimenter pushes down when asked for +z (up): the check must not send them to change [frames]
    (which is right), since no rotation reverses one axis alone."""
    rhb = DEFAULT_ROT_HAPTIC_BASE

    def pushed(axis: str, along: tuple[float, float, float]):
        base = np.tile(along, (200, 1))
        return check_axis(axis, base, base @ np.asarray(rhb).reshape(3, 3).T, rhb)

    fc = FrameCheck((pushed("+x", (1.0, 0, 0)), pushed("+y", (0, 1.0, 0)), pushed("+z", (0, 0, -1.0))), IDENTITY, rhb)
    assert not fc.passed
    assert fc.summary() == (
        "Frames and signs: FAIL on +z (180.0° off): the push was felt along -z, opposite to +z, while +x and +y pass; "
        "no sensor mounting or [frames] rotation turns one axis around alone, so the tip was pushed the wrong way: "
        "push along +z (up) again (leave [frames] as it is)")
    # two axes off (a real mounting error), or one axis 90° off: the frames are suspect, as before
    fc = FrameCheck((pushed("+x", (0, 1.0, 0)), pushed("+y", (-1.0, 0, 0)), pushed("+z", (0, 0, 1.0))), IDENTITY, rhb)
    assert "check the sensor mounting and [frames]" in fc.summary()
    fc = FrameCheck((pushed("+x", (1.0, 0, 0)), pushed("+y", (0, 0, 1.0)), pushed("+z", (0, 0, 1.0))), IDENTITY, rhb)
    assert "check the sensor mounting and [frames]" in fc.summary()


def test_no_push_is_a_failure_that_says_so() -> None:
    a = check_axis("+z", np.full((100, 3), 0.05), np.full((100, 3), 0.02), DEFAULT_ROT_HAPTIC_BASE)
    assert not a.passed and a.samples == 0
    assert a.describe().startswith("+z  no push felt: the largest force was 0.09 N (need 0.3 N)")


# -- the calibration file and the gate -------------------------------------------------------------------
def _chain(tool: str = "grasper") -> ToolCalibration:
    rig = SimRig()
    tcp = identify_tip(pivot_poses(rig, pivot_orientations("minimal", TOOL_DOWN)))
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", haptics_on=False))
    assert eng.ring is not None
    frames = push_axes(eng.rig, eng.loop, eng.ring)
    return (ToolCalibration(tool).with_step("tcp", tcp).with_step("payload", eng.calibration)
            .with_step("frames", frames))


def test_the_gate_names_the_first_missing_step_in_order() -> None:
    full = _chain()
    rts, rhb = full.frames.rot_tip_sensor, full.frames.rot_haptic_base
    assert full.missing(rts, rhb) == ""
    assert ToolCalibration("grasper").missing(rts, rhb) == (
        "no TCP calibration on record for tool 'grasper': run haptic-study calibrate tcp --rig real --hardware FILE "
        "(or the calibration wizard's TCP step)")
    assert ToolCalibration("grasper", tcp=full.tcp).missing(rts, rhb).startswith(
        "no payload calibration on record for tool 'grasper': run haptic-study calibrate payload")
    no_frames = ToolCalibration("grasper", tcp=full.tcp, payload=full.payload)
    assert no_frames.missing(rts, rhb).startswith("no frame and sign check on record for tool 'grasper'")
    other = axis_angle((0.0, 0.0, 1.0), math.pi / 2)
    assert full.missing(other, rhb).startswith("the frame check on record for tool 'grasper' was made with other "
                                               "[frames] rotations")
    axes = tuple(a if a.axis != "+y" else replace(a, base_angle_deg=92.0, haptic_angle_deg=92.0, passed=False)
                 for a in full.frames.axes)
    failed = FrameCheck(axes, rts, rhb)
    assert full.with_step("frames", failed).missing(rts, rhb).startswith(
        "the frame check on record for tool 'grasper' failed (FAIL on +y (92.0° off)")


def test_the_file_keeps_every_tool_round_trips_and_reads_the_old_bare_payload(tmp_path) -> None:
    path = tmp_path / "calibration.json"
    f = RigCalibrationFile.load(path)  # not there yet: nothing on record
    assert f.tool("grasper") == ToolCalibration("grasper")
    full = _chain()
    for step in ("tcp", "payload", "frames"):
        f.record("grasper", step, getattr(full, step))
    f.record("scissors", "tcp", full.tcp)
    back = RigCalibrationFile.load(path)
    g = back.tool("grasper")
    assert g.tcp == full.tcp and g.payload == full.payload and g.frames == full.frames
    assert g.tcp_date and g.payload_date.endswith("+00:00")
    assert back.tool("scissors").payload is None and back.tool("scissors").tcp == full.tcp
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data["format"] == "haptic-study calibration" and sorted(data["tools"]) == ["grasper", "scissors"]
    assert [name for name, ok, _ in g.status()] == ["TCP", "payload", "frames"] and all(ok for _, ok, _ in g.status())

    old = tmp_path / "payload.json"
    old.write_text(json.dumps(NO_PAYLOAD.to_dict()), encoding="utf-8")
    legacy = RigCalibrationFile.load(old)
    assert legacy.tool("anything").payload == NO_PAYLOAD and legacy.tool("anything").tcp is None


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("{not json", "cannot be read as JSON"),
        ("[1, 2]", "must hold a JSON object"),
        ('{"format": "haptic-study calibration", "version": 7}', "version = 7: this software reads version 1"),
        ('{"format": "haptic-study calibration", "version": 1, "tools": {"g": {"tcp": {"date": "x"}}}}',
         "tool 'g' tcp: tcp field 'tip_in_flange_m' is missing"),
        ('{"format": "haptic-study calibration", "version": 1, "tools": {"g": {"tcp": {"tip_in_flange_m": [0, 0, "a"], '
         '"pivot_base_m": [0, 0, 0], "rms_residual_m": 0, "residuals": [], "spread_deg": 30}}}}',
         "tcp.tip_in_flange_m = 'a': must be a finite number"),
    ],
)
def test_a_bad_calibration_file_is_one_line_naming_it(tmp_path, text: str, says: str) -> None:
    p = tmp_path / "calibration.json"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(CalibrationFileError) as info:
        RigCalibrationFile.load(p)
    assert str(info.value).startswith(f"calibration file {p}: ") and says in str(info.value)
    assert "\n" not in str(info.value)


def test_identity_frames_on_record_are_checked_against_the_frames_in_use() -> None:
    fc = FrameCheck((), IDENTITY, DEFAULT_ROT_HAPTIC_BASE)
    assert fc.matches(IDENTITY, DEFAULT_ROT_HAPTIC_BASE) and not fc.passed
