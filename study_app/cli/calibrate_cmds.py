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
session gate checks.  A rig of several arms is commissioned an arm at a time:
``--arm NAME`` runs the step on that arm's devices and saves to that arm's
calibration file (``--sim-arms`` names the simulated rig's arms).  The steps run in order: ``payload`` needs a TCP on
record, ``frames`` a payload.

Exit status: 0 accepted / passed, 1 refused / failed (the reason on stdout),
2 bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from study_app.cli.argtypes import SEED, add_command, arm_name, arm_names, real_number
from study_app.cli.error import CliError
from study_app.guide_paths import hardware_template

# numpy, and the service that uses it, are imported where they are used: ``haptic-study --help`` must not load them
if TYPE_CHECKING:
    from pipeline.commissioning.steps import FramesResult, PayloadResult, TcpResult

__all__ = ["add_calibrate_command", "ask_on_stderr", "chosen_arm", "cmd_calibrate"]

STEPS = ("tcp", "payload", "frames")
#: Real rig: how long the TCP is watched for each pivot orientation, s (the robot reports a pose every 8 ms).
_PIVOT_WATCH_S = 0.3
#: Real rig, payload step: force samples averaged per pose, the least that must arrive, and how long to wait, s.
_POSE_SAMPLES, _POSE_MIN_SAMPLES, _POSE_WAIT_S = 1000, 500, 3.0
#: Real rig, frame check: force samples recorded per push (the Net F/T streams at 1 kHz or more), and the wait, s.
_PUSH_SAMPLES, _PUSH_WAIT_S = 3000, 4.0


def add_calibrate_command(sub: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` to the ``haptic-study`` subcommands."""
    c = add_command(
        sub, "calibrate", "commission the rig: TCP pivot calibration, payload/bias, frame and sign check",
        "haptic-study calibrate tcp --rig sim --json\n"
        "haptic-study calibrate frames --rig sim --sim-mount-error-deg 90   # a sensor mounted 90° off: FAIL\n"
        "haptic-study calibrate tcp --rig real --hardware hardware.toml     # then payload, then frames\n"
        "haptic-study calibrate tcp --rig real --hardware hardware.toml --arm left   # a rig of two arms",
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
    c.add_argument("--arm", type=arm_name("--arm"), default=None, metavar="NAME",
                   help="a rig of several arms: the arm to commission (its devices, its calibration file); "
                        "required when the rig has more than one arm")
    c.add_argument("--sim-arms", dest="sim_arms", type=arm_names("--sim-arms"), default=None, metavar="NAMES",
                   help="simulated rig: its arms, comma-separated (default: one arm, right), e.g. left,right")
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


def chosen_arm(names: tuple[str, ...], arm: str | None, where: str, *, required: bool = True) -> str | None:
    """The arm ``--arm`` names among ``names`` (the rig's, from ``where``); with no ``--arm``, the only arm, or
    None when ``required`` is False (every arm).

    Raises
    ------
    CliError
        ``--arm`` names no arm of the rig, or the rig has several and none is named while one is ``required``.
    """
    listed = ", ".join(names)
    if arm is None:
        if len(names) == 1:
            return names[0]
        if required:
            raise CliError(f"{where} has {len(names)} arms ({listed}): name the one to commission with --arm "
                           f"(e.g. --arm {names[0]}), one arm at a time")
        return None
    if arm not in names:
        raise CliError(f"--arm = {arm!r}: {where} has no such arm; its arms: {listed}")
    return arm


def cmd_calibrate(args: argparse.Namespace, ask: Callable[[str], str] = ask_on_stderr) -> int:
    """Run the step; ``ask`` reads the experimenter's answers (real rig); a refusal raises :class:`CliError`."""
    from pipeline.commissioning.steps import PAYLOAD_POSE_SETS
    from pipeline.commissioning.tcp import PIVOT_POSE_SETS

    allowed = PIVOT_POSE_SETS if args.step == "tcp" else PAYLOAD_POSE_SETS
    if args.poses is not None and (args.step == "frames" or args.poses not in allowed):
        if args.step == "frames":
            raise CliError(f"--poses = {args.poses!r}: the frames step takes no pose set (it checks +x, +y and +z)")
        raise CliError(f"--poses = {args.poses!r}: allowed for {args.step}: {', '.join(repr(a) for a in allowed)}")
    if args.rig == "real":
        if args.sim_mount_error_deg:
            raise CliError("--sim-mount-error-deg applies to the simulated rig only (omit it with --rig real)")
        if args.sim_arms is not None:
            raise CliError("--sim-arms applies to the simulated rig only (with --rig real the hardware file names "
                           "the arms)")
        if args.hardware is None:
            raise CliError("--rig real needs --hardware FILE (the hardware.toml of the lab; "
                           f"see {hardware_template()})")
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
    from pipeline.assembly.sim_config import sim_rig_config
    from pipeline.devices.rig import SINGLE_ARM_NAME
    from pipeline.sim.arms import arm_configs

    names = args.sim_arms or (SINGLE_ARM_NAME,)
    where = f"the simulated rig (--sim-arms {','.join(names)})" if args.sim_arms else (
        f"the simulated rig (one arm, {SINGLE_ARM_NAME}; --sim-arms names more)")
    arm = chosen_arm(names, args.arm, where)
    assert arm is not None  # required: one arm or a refusal
    # the arm's own configuration (its own seed) as the simulated rig of several arms builds it
    sim = dict(arm_configs(names, sim_rig_config(args.seed, sensor_z_mount_deg=args.sim_mount_error_deg)))[arm]
    note = f"simulated rig, seed {args.seed}" + (f", arm {arm!r}" if len(names) > 1 else "") + (
        f", sensor mounted {args.sim_mount_error_deg:g}° about its z axis (not told to the pipeline)"
        if args.sim_mount_error_deg else "")
    out = _sim_step(args, sim, note)
    out["arm"] = arm
    return out


def _sim_step(args: argparse.Namespace, sim: Any, note: str) -> dict[str, Any]:
    """Run the step on the simulated arm of configuration ``sim``."""
    from pipeline.commissioning.steps import frames_step, payload_step, pose_set, tcp_step
    from pipeline.sim.rig import SimRig

    if args.step == "tcp":
        from pipeline.commissioning.tcp import pivot_orientations
        from pipeline.sim.commissioning import pivot_poses
        from pipeline.sim.robot import TOOL_DOWN

        name = args.poses or "recommended"
        tcp = tcp_step(pivot_poses(SimRig(sim), pivot_orientations(name, TOOL_DOWN)), name, sim.tip_in_flange_m)
        out = _tcp_out(tcp, note)
        if tcp.accepted:
            out["true_tip_in_flange_m"] = [float(v) for v in sim.tip_in_flange_m]
            out["error_mm"] = tcp.error_mm
            out["text"] += (f"\n  simulated truth ({_mm(sim.tip_in_flange_m)}) mm: error {tcp.error_mm:.3f} mm"
                            "\nAccepted (simulated rig: not saved).")
        return out
    if args.step == "payload":
        from pipeline.core.clock import VirtualClock
        from pipeline.sim.calibration import measure_poses

        name = args.poses or "recommended"
        payload = payload_step(measure_poses(SimRig(sim), VirtualClock(), pose_set(name)), name)
        out = _payload_out(payload, note)
        if payload.accepted:
            out["text"] += "\nAccepted (simulated rig: not saved)."
        return out
    from pipeline.assembly.engine import EngineConfig, build_sim_engine
    from pipeline.sim.commissioning import push_axes

    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", haptics_on=False, refine_bias=False, sim=sim))
    assert eng.ring is not None
    mount = eng.calibration.mount_angle_deg
    head = (f"Frame and sign check ({note}; payload calibrated automatically first, mount {mount:.1f}° from "
            "[frames]; the simulated experimenter pushes the free tip 1 N along each base axis):")
    return _frames_out(frames_step(push_axes(eng.rig, eng.loop, eng.ring), mount), head)


# -- the results, presented ------------------------------------------------------------------------------
_TITLES = {"tcp": "TCP pivot calibration", "payload": "Payload/bias calibration", "frames": "Frame and sign check"}


def _mm(v: Any) -> str:
    return ", ".join(f"{1e3 * float(x):+.2f}" for x in v)


def _refused(step: str, name: str, n: int, reason: str, note: str) -> dict[str, Any]:
    what = "orientations" if step == "tcp" else "poses"
    return {"step": step, "accepted": False, "pose_set": name, "poses": n, "reason": reason,
            "text": f"{_TITLES[step]} ({note}, {n} {what} '{name}'):\nRefused: {reason}"}


def _tcp_out(r: TcpResult, note: str) -> dict[str, Any]:
    tc = r.calibration
    if tc is None:
        return _refused("tcp", r.pose_set, r.n_poses, r.reason, note)
    worst = max(tc.residuals, key=lambda x: x[1])
    text = "\n".join([
        f"TCP pivot calibration ({note}, {tc.n_poses} orientations" + (f" '{r.pose_set}'" if r.pose_set else "") + "):",
        f"  tip in the flange frame ({_mm(tc.tip_in_flange_m)}) mm",
        f"  pivot (the divot) in the base frame ({_mm(tc.pivot_base_m)}) mm",
        f"  RMS residual {tc.rms_residual_m * 1e3:.3f} mm (worst {worst[0]} {worst[1] * 1e3:.3f} mm); "
        f"the orientations span {tc.spread_deg:.0f}° about every axis across the tip",
    ])
    return {"step": "tcp", "accepted": True, "pose_set": r.pose_set, "poses": tc.n_poses, "result": tc.to_dict(),
            "tip_in_flange_m": list(tc.tip_in_flange_m), "pivot_base_m": list(tc.pivot_base_m),
            "rms_residual_mm": tc.rms_residual_m * 1e3, "spread_deg": tc.spread_deg,
            "residuals_mm": {lab: x * 1e3 for lab, x in tc.residuals}, "text": text}


def _payload_out(r: PayloadResult, note: str) -> dict[str, Any]:
    cal = r.calibration
    if cal is None:
        return _refused("payload", r.pose_set, r.n_poses, r.reason, note)
    text = "\n".join([
        f"Payload/bias calibration ({note}, {len(cal.residuals)} poses '{r.pose_set}', {cal.model} model):",
        f"  mass {cal.mass_kg:.4f} kg, centre of mass ({_mm(cal.com_m)}) mm in the sensor frame",
        f"  force bias ({', '.join(f'{v:+.3f}' for v in cal.force_bias_n)}) N, sensor mount {cal.mount_angle_deg:.2f}° "
        "from [frames] rot_tip_sensor",
        f"  condition number {cal.condition_number:.1f}, RMS residual {cal.rms_force_residual_n * 1e3:.1f} mN "
        f"(force), {cal.rms_torque_residual_nm * 1e3:.2f} mN·m (torque)",
    ])
    if r.reason:
        text += f"\nRefused: {r.reason}"
    return {"step": "payload", "accepted": r.accepted, "pose_set": r.pose_set, "poses": len(cal.residuals),
            "reason": r.reason, "result": cal.to_dict(), "mass_kg": cal.mass_kg,
            "condition_number": cal.condition_number, "rms_force_residual_n": cal.rms_force_residual_n,
            "mount_angle_deg": cal.mount_angle_deg, "text": text}


def _frames_out(r: FramesResult, head: str) -> dict[str, Any]:
    check = r.check
    lines = [head] + [f"  {a.describe()}" for a in check.axes] + [r.summary]
    return {"step": "frames", "accepted": r.passed, "passed": r.passed, "result": check.to_dict(),
            "axes": [a.to_dict() for a in check.axes], "summary": check.summary(), "text": "\n".join(lines)}


# -- the real rig --------------------------------------------------------------------------------------
def _real(args: argparse.Namespace, ask: Callable[[str], str]) -> dict[str, Any]:
    from pipeline.commissioning.rig_calibration import CalibrationFileError, RigCalibrationFile
    from pipeline.commissioning.steps import chain_refusal
    from pipeline.core.clock import MonotonicClock
    from pipeline.devices.interfaces import DeviceError
    from pipeline.settings.hardware import HardwareError, load_hardware

    try:
        rig = load_hardware(args.hardware)
    except HardwareError as exc:
        raise CliError(str(exc)) from None
    names = tuple(a.name for a in rig.arms)
    arm = chosen_arm(names, args.arm, args.hardware)
    assert arm is not None
    hw = rig.arm(arm)  # this arm's devices, frames, calibration file and tool
    try:
        cal_file = RigCalibrationFile.load(hw.calibration_file or "calibration.json")
    except CalibrationFileError as exc:
        raise CliError(str(exc)) from None
    tool = hw.calibration_tool
    record = cal_file.tool(tool)
    refusal = chain_refusal(record, args.step)
    which = f" --arm {arm}" if len(names) > 1 else ""
    if refusal:
        raise CliError(f"calibrate {args.step}{which}: {refusal}")
    note = (f"arm {arm!r}, " if len(names) > 1 else "") + f"tool {tool!r}"
    clock = MonotonicClock()
    try:
        if args.step == "tcp":
            result: Any = _real_tcp(hw, clock, ask, note)
            out = _tcp_out(result, note)
            if result.accepted:
                t = out["tip_in_flange_m"]
                out["text"] += (f"\n  set the TCP on the pendant to ({_mm(t)}) mm and robot.tcp_offset_m to "
                                f"[{', '.join(f'{v:.5f}' for v in t)}] (until then the app corrects the poses itself)")
        elif args.step == "payload":
            result = _real_payload(hw, clock, ask, args.poses or "recommended", note)
            out = _payload_out(result, note)
        else:
            result = _real_frames(hw, clock, ask, record.payload, note)
            out = _frames_out(result, f"Frame and sign check ({note}):")
    except DeviceError as exc:
        raise CliError(str(exc)) from None
    except (EOFError, KeyboardInterrupt):
        raise CliError(f"calibrate {args.step}{which}: stopped before the end; nothing was saved") from None
    out["arm"] = arm
    if result.record is not None:  # the service says what goes on record (a failed frame check does too)
        try:
            cal_file.record(tool, result.step, result.record)
        except CalibrationFileError as exc:
            raise CliError(str(exc)) from None
        out["saved_to"] = cal_file.path
        out["text"] += f"\nSaved for tool {tool!r} in {cal_file.path}."
    return out


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)  # prompts and progress on stderr: stdout is the result (--json)


def _sensor_and_robot(hw: Any, clock: Any) -> tuple[Any, Any]:
    """Open the Net F/T and the robot (read only); the sensor is closed again if the robot cannot be opened."""
    from pipeline.assembly.real_rig import open_robot, open_sensor

    sensor = open_sensor(hw.sensor, clock)
    try:
        return sensor, open_robot(hw.robot, clock)
    except BaseException:
        sensor.close()
        raise


def _watch_tcp(robot: Any, seconds: float) -> tuple[Any, list[Any], Any]:
    """The robot's pose before, its TCP positions during ``seconds``, and its pose after (wall clock)."""
    first = robot.read_pose()
    pts = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pts.append(robot.read_pose().position_m)
        time.sleep(0.004)  # the controller updates every 8 ms: read each state about twice
    return first, pts, robot.read_pose()


def _real_tcp(hw: Any, clock: Any, ask: Callable[[str], str], note: str) -> TcpResult:
    from pipeline.assembly.real_rig import open_robot
    from pipeline.commissioning.steps import record_pivot, tcp_step
    from pipeline.commissioning.tcp import MIN_PIVOT_POSES, MIN_SPREAD_DEG, PivotPose
    from pipeline.force.frames import matrix_to_rotvec

    robot = open_robot(hw.robot, clock)  # the pendant's TCP: poses are turned back into flange poses
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
            first, pts, last = _watch_tcp(robot, _PIVOT_WATCH_S)
            rp = record_pivot(f"O{k}", pts, first.rot_base_tip, last.rot_base_tip, hw.robot.tcp_offset_m)
            if not rp.accepted:
                _say(f"O{k} not recorded: {rp.reason}")
                continue
            poses.append(rp.pose())
            rv = matrix_to_rotvec(rp.rot_base_flange)
            _say(f"O{k} recorded: flange at ({_mm(rp.flange_position_m)}) mm, rotation vector ({rv[0]:+.3f}, "
                 f"{rv[1]:+.3f}, {rv[2]:+.3f}) rad")
    finally:
        robot.close()
    return tcp_step(poses, "")


def _real_payload(hw: Any, clock: Any, ask: Callable[[str], str], name: str, note: str) -> PayloadResult:
    import numpy as np

    from pipeline.commissioning.payload_identification import CalibrationPose
    from pipeline.commissioning.steps import payload_step, pose_set, record_pose, tcp_target
    from pipeline.force.frames import matrix_to_rotvec

    rots = pose_set(name)
    rts = hw.framework.rot_tip_sensor
    sensor, robot = _sensor_and_robot(hw, clock)
    poses: list[CalibrationPose] = []
    _say(f"Payload/bias calibration of {note}: move the robot to each pose with the tool hanging free, then press "
         "Enter; 's' skips a pose the robot cannot reach, 'c' identifies from the poses so far.")
    try:
        k = 0
        while k < len(rots):
            label = f"pose {k + 1}"  # never "P01", a participant's code
            rv = matrix_to_rotvec(tcp_target(rots[k], rts))
            line = ask(f"{label} of {len(rots)}: TCP rotation vector ({rv[0]:+.3f}, {rv[1]:+.3f}, "
                       f"{rv[2]:+.3f}) rad -- Enter = record, s = skip, c = identify now, q = quit: ").strip().lower()
            if line == "q":
                raise EOFError
            if line == "c":
                break
            if line == "s":
                k += 1
                continue
            before = robot.read_pose()
            samples = sensor.collect(_POSE_SAMPLES, _POSE_WAIT_S)
            if len(samples) < _POSE_MIN_SAMPLES:
                _say(f"{label} not recorded: the force sensor sent too few samples")
                continue
            rp = record_pose(label, [s[1:7] for s in samples], before, robot.read_pose(), rts, rots[k])
            if not rp.accepted:
                _say(f"{label} not recorded: {rp.reason}")
                continue
            poses.append(rp.pose())
            _say(f"{label} recorded: |F| = {float(np.linalg.norm(rp.wrench[:3])):.3f} N")
            k += 1
    finally:
        robot.close()
        sensor.close()
    return payload_step(poses, name)


def _real_frames(hw: Any, clock: Any, ask: Callable[[str], str], payload: Any, note: str) -> FramesResult:
    import numpy as np

    from pipeline.commissioning.frame_check import AXES, AxisCheck, check_axis
    from pipeline.commissioning.steps import frame_check_of, frames_step
    from pipeline.devices.registry import haptic_model
    from pipeline.force.framework import STEP_FIELDS, HapticFramework

    base_at, scaled_at = STEP_FIELDS.index("base_fx"), STEP_FIELDS.index("scaled_fx")
    fw = HapticFramework(hw.framework, payload, device_peak_n=haptic_model(hw.haptic.model).peak_force_n)
    sensor, robot = _sensor_and_robot(hw, clock)
    words = {"+x": "+x", "+y": "+y", "+z": "+z (up)"}
    results: dict[str, AxisCheck] = {}
    _say(f"Frame and sign check of {note}: the tip hangs free. At each prompt press Enter, then within 3 s push the "
         "tip gently (about 1 N) along the base axis shown and let go. Feedback stays off.")
    try:
        for axis in AXES:
            line = ask(f"push along base {words[axis]}: Enter = start the 3 s recording, q = quit: ").strip().lower()
            if line == "q":
                raise EOFError
            base, scaled = [], []
            for s in sensor.collect(_PUSH_SAMPLES, _PUSH_WAIT_S):
                fw.set_pose(robot.read_pose().rot_base_tip)
                step = fw.step(s[1], s[2], s[3], False, 0.001)
                base.append(step[base_at:base_at + 3])
                scaled.append(step[scaled_at:scaled_at + 3])
            res = check_axis(axis, np.asarray(base).reshape(-1, 3), np.asarray(scaled).reshape(-1, 3),
                             hw.framework.rot_haptic_base)
            _say(res.describe())
            results[axis] = res
    finally:
        robot.close()
        sensor.close()
    check = frame_check_of(results, hw.framework.rot_tip_sensor, hw.framework.rot_haptic_base)
    assert check is not None  # every axis was pushed (quitting raised)
    return frames_step(check, payload.mount_angle_deg)
