"""``haptic-study calibrate tcp|payload|frames``: the commissioning chain, headless, on the simulated or the real rig.

Each step does what the calibration wizard's step does, from a terminal:

* ``tcp`` -- pivot calibration of the tool-centre point (:mod:`pipeline.commissioning.tcp`);
* ``payload`` -- gravity/bias identification (:mod:`pipeline.commissioning.payload_identification`);
* ``frames`` -- the frame and sign check (:mod:`pipeline.commissioning.frame_check`).

On the simulated rig each step runs by itself (the simulated robot turns,
the simulated experimenter pushes) and nothing is saved.  On the real rig the
experimenter moves the robot and presses Enter at each prompt; an accepted
result is saved under the mounted tool in the calibration file the hardware
file names (:mod:`pipeline.commissioning.rig_calibration`), which the engine reads and the
session gate checks.  The steps run in order: ``payload`` needs a TCP on
record, ``frames`` a payload.

Exit status: 0 accepted / passed, 1 refused / failed (the reason on stdout),
2 bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from study_app.cli.argtypes import SEED, add_command, real_number
from study_app.cli.error import CliError

if TYPE_CHECKING:  # numpy is imported where it is used: ``haptic-study --help`` must not load it
    pass

__all__ = ["add_calibrate_command", "ask_on_stderr", "cmd_calibrate"]

STEPS = ("tcp", "payload", "frames")
_PAYLOAD_SETS = ("recommended", "quick", "tool-down only")
#: Real rig, TCP step: a recorded orientation is refused if the TCP moved more than this while averaging.
_STILL_M, _STILL_DEG = 0.0002, 0.2


def add_calibrate_command(sub: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` to the ``haptic-study`` subcommands."""
    c = add_command(
        sub, "calibrate", "commission the rig: TCP pivot calibration, payload/bias, frame and sign check",
        "haptic-study calibrate tcp --rig sim --json\n"
        "haptic-study calibrate frames --rig sim --sim-mount-error-deg 90   # a sensor mounted 90° off: FAIL\n"
        "haptic-study calibrate tcp --rig real --hardware hardware.toml     # then payload, then frames",
        "Run one step of the commissioning chain, in order: tcp (the tip rests in a divot while the instrument is "
        "turned; least squares gives the tip in the flange frame), payload (the tool's weight and the sensor bias "
        "from static poses), frames (push the free tip along each base axis; the force must come out the right way "
        "in the base and haptic frames). On the real rig each accepted result is saved for the mounted tool in the "
        "calibration file of the hardware file; a session starts only when all three are on record",
    )
    c.add_argument("step", choices=STEPS, help="tcp, payload or frames")
    c.add_argument("--rig", choices=("sim", "real"), default="sim", help="simulated rig (default) or the real hardware")
    c.add_argument("--hardware", default=None, metavar="FILE", help="hardware.toml for --rig real")
    c.add_argument("--poses", default=None, metavar="SET",
                   help="tcp: recommended (8, default), minimal (4), 'roll only' (refused: shows why); "
                        "payload: recommended (24, default), quick (6), 'tool-down only' (refused)")
    c.add_argument("--seed", type=SEED, default=0, help="simulated rig: seed (default 0)")
    c.add_argument("--sim-mount-error-deg", type=real_number("--sim-mount-error-deg", -180.0, 180.0), default=0.0,
                   metavar="DEG", help="simulated rig: mount the sensor turned about its own z axis by DEG without "
                                       "telling the pipeline (a lab's mounting mistake the frame check must catch)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(handler=cmd_calibrate)


def ask_on_stderr(prompt: str) -> str:
    """The experimenter's answer to ``prompt``: the prompt on stderr, the answer one line of stdin.

    ``input()`` writes its prompt to stdout when stdin is not a terminal, mixing it into the result (and
    breaking ``--json``); stdout carries only the result.

    Raises
    ------
    EOFError
        stdin ended (the step stops; nothing is saved).
    """
    print(prompt, end="", file=sys.stderr, flush=True)
    line = sys.stdin.readline()
    if not line:
        raise EOFError
    return line.rstrip("\r\n")


def cmd_calibrate(args: argparse.Namespace, ask: Callable[[str], str] = ask_on_stderr) -> int:
    """Run the step; ``ask`` reads the experimenter's answers (real rig); a refusal raises :class:`CliError`."""
    from pipeline.commissioning.tcp import PIVOT_POSE_SETS

    allowed = PIVOT_POSE_SETS if args.step == "tcp" else _PAYLOAD_SETS
    if args.poses is not None and (args.step == "frames" or args.poses not in allowed):
        if args.step == "frames":
            raise CliError(f"--poses = {args.poses!r}: the frames step takes no pose set (it checks +x, +y and +z)")
        raise CliError(f"--poses = {args.poses!r}: allowed for {args.step}: {', '.join(repr(a) for a in allowed)}")
    if args.rig == "real":
        if args.sim_mount_error_deg:
            raise CliError("--sim-mount-error-deg applies to the simulated rig only (omit it with --rig real)")
        if args.hardware is None:
            raise CliError("--rig real needs --hardware FILE (the hardware.toml of the lab; see hardware.example.toml)")
        result = _real(args, ask)
    else:
        if args.hardware is not None:
            raise CliError("--hardware applies to --rig real only")
        result = _sim(args)
    text = result.pop("text")
    print(json.dumps(result) if args.json else text)
    return 0 if result["accepted"] else 1


# -- the simulated rig ---------------------------------------------------------------------------------
def _sim(args: argparse.Namespace) -> dict[str, Any]:
    import numpy as np

    from pipeline.runtime.engine import EngineConfig, build_sim_engine
    from pipeline.sim.rig import SimRigConfig

    sim = SimRigConfig(seed=args.seed, sensor_z_mount_deg=args.sim_mount_error_deg)
    note = f"simulated rig, seed {args.seed}" + (
        f", sensor mounted {args.sim_mount_error_deg:g}° about its z axis (not told to the pipeline)"
        if args.sim_mount_error_deg else "")
    if args.step == "tcp":
        from pipeline.commissioning.tcp import pivot_orientations
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.rig import SimRig
        from pipeline.sim.robot import TOOL_DOWN

        rig = SimRig(sim)
        name = args.poses or "recommended"
        out = _tcp_result(pivot_poses(rig, pivot_orientations(name, TOOL_DOWN)), name, note)
        if out["accepted"]:
            truth = np.asarray(sim.tip_in_flange_m)
            err = float(np.linalg.norm(np.asarray(out["tip_in_flange_m"]) - truth))
            out["true_tip_in_flange_m"] = truth.tolist()
            out["error_mm"] = err * 1e3
            out["text"] += (f"\n  simulated truth ({_mm(truth)}) mm: error {err * 1e3:.3f} mm"
                            "\nAccepted (simulated rig: not saved).")
        return out
    if args.step == "payload":
        from pipeline.runtime.clock import VirtualClock
        from pipeline.sim.calibration import auto_calibrate
        from pipeline.sim.rig import SimRig
        from study_app.engine.commissioning import pose_set

        name = args.poses or "recommended"
        rig = SimRig(sim)
        rots = pose_set(name)
        try:
            cal, _ = auto_calibrate(rig, VirtualClock(), rots)
        except ValueError as exc:
            return _refused("payload", name, len(rots), str(exc), note)
        out = _payload_result(cal, name, note)
        if out["accepted"]:
            out["text"] += "\nAccepted (simulated rig: not saved)."
        return out
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", haptics_on=False, refine_bias=False, sim=sim))
    from pipeline.sim.commissioning import push_axes

    assert eng.ring is not None
    check = push_axes(eng.rig, eng.loop, eng.ring)
    head = (f"Frame and sign check ({note}; payload calibrated automatically first, mount "
            f"{eng.calibration.mount_angle_deg:.1f}° from [frames]; the simulated experimenter pushes the free tip "
            "1 N along each base axis):")
    return _frames_result(check, head, eng.calibration.mount_angle_deg)


def _mm(v: Any) -> str:
    return ", ".join(f"{1e3 * float(x):+.2f}" for x in v)


def _refused(step: str, name: str, n: int, reason: str, note: str) -> dict[str, Any]:
    what = "orientations" if step == "tcp" else "poses"
    return {"step": step, "accepted": False, "pose_set": name, "poses": n, "reason": reason,
            "text": f"{_TITLES[step]} ({note}, {n} {what} '{name}'):\nRefused: {reason}"}


_TITLES = {"tcp": "TCP pivot calibration", "payload": "Payload/bias calibration", "frames": "Frame and sign check"}


def _tcp_result(poses: list[Any], name: str, note: str) -> dict[str, Any]:
    from pipeline.commissioning.tcp import identify_tip

    try:
        tc = identify_tip(poses)
    except ValueError as exc:
        return _refused("tcp", name, len(poses), str(exc), note)
    worst = max(tc.residuals, key=lambda r: r[1])
    text = "\n".join([
        f"TCP pivot calibration ({note}, {tc.n_poses} orientations" + (f" '{name}'" if name else "") + "):",
        f"  tip in the flange frame ({_mm(tc.tip_in_flange_m)}) mm",
        f"  pivot (the divot) in the base frame ({_mm(tc.pivot_base_m)}) mm",
        f"  RMS residual {tc.rms_residual_m * 1e3:.3f} mm (worst {worst[0]} {worst[1] * 1e3:.3f} mm); "
        f"the orientations span {tc.spread_deg:.0f}° about every axis across the tip",
    ])
    return {"step": "tcp", "accepted": True, "pose_set": name, "poses": tc.n_poses, "result": tc.to_dict(),
            "tip_in_flange_m": list(tc.tip_in_flange_m), "pivot_base_m": list(tc.pivot_base_m),
            "rms_residual_mm": tc.rms_residual_m * 1e3, "spread_deg": tc.spread_deg,
            "residuals_mm": {lab: r * 1e3 for lab, r in tc.residuals}, "text": text}


def _payload_result(cal: Any, name: str, note: str) -> dict[str, Any]:
    from study_app.engine.commissioning import calibration_verdict

    reason = calibration_verdict(cal)
    text = "\n".join([
        f"Payload/bias calibration ({note}, {len(cal.residuals)} poses '{name}', {cal.model} model):",
        f"  mass {cal.mass_kg:.4f} kg, centre of mass ({_mm(cal.com_m)}) mm in the sensor frame",
        f"  force bias ({', '.join(f'{v:+.3f}' for v in cal.force_bias_n)}) N, sensor mount {cal.mount_angle_deg:.2f}° "
        "from [frames] rot_tip_sensor",
        f"  condition number {cal.condition_number:.1f}, RMS residual {cal.rms_force_residual_n * 1e3:.1f} mN "
        f"(force), {cal.rms_torque_residual_nm * 1e3:.2f} mN·m (torque)",
    ])
    if reason:
        text += f"\nRefused: {reason}"
    return {"step": "payload", "accepted": not reason, "pose_set": name, "poses": len(cal.residuals),
            "reason": reason, "result": cal.to_dict(), "mass_kg": cal.mass_kg, "condition_number": cal.condition_number,
            "rms_force_residual_n": cal.rms_force_residual_n, "mount_angle_deg": cal.mount_angle_deg, "text": text}


def _frames_result(check: Any, head: str, mount_deg: float | None) -> dict[str, Any]:
    lines = [head] + [f"  {a.describe()}" for a in check.axes] + [check.summary()]
    if not check.passed and mount_deg is not None and mount_deg > 5.0:
        lines[-1] += f" (the payload calibration finds the sensor {mount_deg:.1f}° from its configured mount)"
    return {"step": "frames", "accepted": check.passed, "passed": check.passed, "result": check.to_dict(),
            "axes": [a.to_dict() for a in check.axes], "summary": check.summary(), "text": "\n".join(lines)}


# -- the real rig --------------------------------------------------------------------------------------
def _real(args: argparse.Namespace, ask: Callable[[str], str]) -> dict[str, Any]:
    from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile
    from pipeline.devices.interfaces import DeviceError
    from pipeline.runtime.clock import MonotonicClock
    from pipeline.settings.hardware import HardwareError, load_hardware

    try:
        hw = load_hardware(args.hardware)
        cal_file = RigCalibrationFile.load(hw.calibration_file or "calibration.json")
    except (HardwareError, CalibrationFileError) as exc:
        raise CliError(str(exc)) from None
    tool = hw.calibration_tool
    record = cal_file.tool(tool)
    if args.step == "payload" and record.tcp is None:
        raise CliError(f"calibrate payload: no TCP calibration on record for tool {tool!r}; the chain runs in order: "
                    "calibrate tcp first")
    if args.step == "frames" and record.payload is None:
        raise CliError(f"calibrate frames: no payload calibration on record for tool {tool!r}; the chain runs in "
                       "order: calibrate payload first")
    note = f"tool {tool!r}"
    clock = MonotonicClock()
    try:
        if args.step == "tcp":
            out = _real_tcp(hw, clock, ask, args.poses or "recommended", note)
        elif args.step == "payload":
            out = _real_payload(hw, clock, ask, args.poses or "recommended", note)
        else:
            out = _real_frames(hw, clock, ask, record.payload, note)
    except DeviceError as exc:
        raise CliError(str(exc)) from None
    except (EOFError, KeyboardInterrupt):
        raise CliError(f"calibrate {args.step}: stopped before the end; nothing was saved") from None
    if out.pop("save", False):
        try:
            cal_file.record(tool, args.step, out.pop("object"))
        except CalibrationFileError as exc:
            raise CliError(str(exc)) from None
        out["saved_to"] = cal_file.path
        out["text"] += f"\nSaved for tool {tool!r} in {cal_file.path}."
    out.pop("object", None)
    return out


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)  # prompts and progress on stderr: stdout is the result (--json)


def _still_pose(robot: Any, seconds: float) -> tuple[Any, str]:
    """Average the TCP position over ``seconds``; (pose, "") or (None, why it is refused)."""
    import numpy as np

    from study_app.engine.commissioning import rotation_angle_deg

    first = robot.read_pose()
    pts = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pts.append(robot.read_pose().position_m)
        time.sleep(0.004)  # the controller updates every 8 ms: read each state about twice
    last = robot.read_pose()
    if not all(math.isfinite(v) for v in last.position_m):
        return None, "no TCP pose from the robot; check the RTDE connection"
    p = np.asarray(pts)
    moved = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
    turned = rotation_angle_deg(first.rot_base_tip, last.rot_base_tip)
    if moved > _STILL_M or turned > _STILL_DEG:
        return None, (f"the robot moved while recording ({moved * 1e3:.2f} mm, {turned:.2f}°; allowed "
                      f"{_STILL_M * 1e3:g} mm and {_STILL_DEG:g}°): hold it still and record again")
    return last._replace(position_m=tuple(float(v) for v in p.mean(axis=0))), ""


def _sensor_and_robot(hw: Any, clock: Any) -> tuple[Any, Any]:
    """Open the Net F/T and the robot (read only); the sensor is closed again if the robot cannot be opened."""
    from pipeline.devices.real_rig import open_robot, open_sensor

    sensor = open_sensor(hw.sensor, clock)
    try:
        return sensor, open_robot(hw.robot, clock)
    except BaseException:
        sensor.close()
        raise


def _real_tcp(hw: Any, clock: Any, ask: Callable[[str], str], name: str, note: str) -> dict[str, Any]:
    from pipeline.commissioning.tcp import MIN_PIVOT_POSES, MIN_SPREAD_DEG, PivotPose
    from pipeline.devices.real_rig import open_robot
    from pipeline.force.frames import mat_vec, matrix_to_rotvec

    robot = open_robot(hw.robot, clock)  # the pendant's TCP: poses are turned back into flange poses below
    off = hw.robot.tcp_offset_m
    poses: list[PivotPose] = []
    _say(f"TCP pivot calibration of {note}: rest the instrument tip in the divot and keep it there. Turn the "
         f"instrument through at least {MIN_PIVOT_POSES} orientations, tilted at least {MIN_SPREAD_DEG:g}° apart in "
         "two directions (e.g. toward the front, back, left and right), and record each one standing still.")
    try:
        while True:
            k = len(poses) + 1
            line = ask(f"orientation O{k}: Enter = record, c = compute ({len(poses)} recorded), q = quit: ").strip()
            if line.lower() == "q":
                raise EOFError
            if line.lower() == "c":
                if len(poses) >= MIN_PIVOT_POSES:
                    break
                _say(f"record at least {MIN_PIVOT_POSES} orientations first ({len(poses)} so far)")
                continue
            pose, why = _still_pose(robot, 0.3)
            if pose is None:
                _say(f"O{k} not recorded: {why}")
                continue
            rot = pose.rot_base_tip
            d = mat_vec(rot, off)
            flange = tuple(p - q for p, q in zip(pose.position_m, d, strict=True))
            poses.append(PivotPose(rot, flange, f"O{k}"))
            rv = matrix_to_rotvec(rot)
            _say(f"O{k} recorded: flange at ({_mm(flange)}) mm, rotation vector ({rv[0]:+.3f}, {rv[1]:+.3f}, "
                 f"{rv[2]:+.3f}) rad")
    finally:
        robot.close()
    out = _tcp_result(poses, "", note)
    if out["accepted"]:
        t = out["tip_in_flange_m"]
        out["text"] += (f"\n  set the TCP on the pendant to ({_mm(t)}) mm and robot.tcp_offset_m to "
                        f"[{', '.join(f'{v:.5f}' for v in t)}] (until then the app corrects the poses itself)")
        from pipeline.commissioning.tcp import TipCalibration

        out["save"], out["object"] = True, TipCalibration.from_dict(out["result"])
    return out


def _real_payload(hw: Any, clock: Any, ask: Callable[[str], str], name: str, note: str) -> dict[str, Any]:
    import numpy as np

    from pipeline.commissioning.payload_identification import CalibrationPose, identify_payload
    from pipeline.force.frames import mat_mul, matrix_to_rotvec, transpose
    from pipeline.force.payload_compensator import PayloadCalibration
    from study_app.engine.commissioning import pose_set

    rots = pose_set(name)
    rts = hw.framework.rot_tip_sensor
    sensor, robot = _sensor_and_robot(hw, clock)
    poses: list[CalibrationPose] = []
    _say(f"Payload/bias calibration of {note}: move the robot to each pose with the tool hanging free, then press "
         "Enter; 's' skips a pose the robot cannot reach, 'c' identifies from the poses so far.")
    try:
        k = 0
        while k < len(rots):
            target = mat_mul(rots[k], transpose(rts))
            rv = matrix_to_rotvec(target)
            line = ask(f"pose P{k + 1:02d} of {len(rots)}: TCP rotation vector ({rv[0]:+.3f}, {rv[1]:+.3f}, "
                       f"{rv[2]:+.3f}) rad -- Enter = record, s = skip, c = identify now, q = quit: ").strip().lower()
            if line == "q":
                raise EOFError
            if line == "c":
                break
            if line == "s":
                k += 1
                continue
            pose, why = _still_pose(robot, 0.2)
            samples = sensor.collect(1000, 3.0) if pose is not None else []
            if pose is None or len(samples) < 500:
                _say(f"P{k + 1:02d} not recorded: {why or 'the force sensor sent too few samples'}")
                continue
            w = np.asarray([s[1:7] for s in samples], dtype=float).mean(axis=0)
            poses.append(CalibrationPose(mat_mul(pose.rot_base_tip, rts), tuple(float(v) for v in w),  # type: ignore[arg-type]  # six items: mypy cannot count a generator
                                         f"P{k + 1:02d}"))
            _say(f"P{k + 1:02d} recorded: |F| = {float(np.linalg.norm(w[:3])):.3f} N")
            k += 1
    finally:
        robot.close()
        sensor.close()
    try:
        cal = identify_payload(poses)
    except ValueError as exc:
        return _refused("payload", name, len(poses), str(exc), note)
    out = _payload_result(cal, name, note)
    if out["accepted"]:
        out["save"], out["object"] = True, PayloadCalibration.from_dict(out["result"])
    return out


def _real_frames(hw: Any, clock: Any, ask: Callable[[str], str], payload: Any, note: str) -> dict[str, Any]:
    import numpy as np

    from pipeline.commissioning.frame_check import AXES, FrameCheck, check_axis
    from pipeline.force.framework import HapticFramework

    fw = HapticFramework(hw.framework, payload)
    sensor, robot = _sensor_and_robot(hw, clock)
    words = {"+x": "+x", "+y": "+y", "+z": "+z (up)"}
    results = []
    _say(f"Frame and sign check of {note}: the tip hangs free. At each prompt press Enter, then within 3 s push the "
         "tip gently (about 1 N) along the base axis shown and let go. Feedback stays off.")
    try:
        for axis in AXES:
            line = ask(f"push along base {words[axis]}: Enter = start the 3 s recording, q = quit: ").strip().lower()
            if line == "q":
                raise EOFError
            base, scaled = [], []
            for s in sensor.collect(3000, 4.0):
                pose = robot.read_pose()
                fw.set_pose(pose.rot_base_tip)
                step = fw.step(s[1], s[2], s[3], False, 0.001)
                base.append(step[9:12])
                scaled.append(step[15:18])
            res = check_axis(axis, np.asarray(base).reshape(-1, 3), np.asarray(scaled).reshape(-1, 3),
                             hw.framework.rot_haptic_base)
            _say(res.describe())
            results.append(res)
    finally:
        robot.close()
        sensor.close()
    check = FrameCheck(tuple(results), hw.framework.rot_tip_sensor, hw.framework.rot_haptic_base)
    out = _frames_result(check, f"Frame and sign check ({note}):", payload.mount_angle_deg)
    out["save"], out["object"] = True, check  # a failed check is on record too (the gate refuses it, and says so)
    return out
