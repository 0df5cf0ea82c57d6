"""The real rig's settings: ``hardware.toml`` loaded and validated.

:func:`load_hardware` checks every field and raises one :class:`HardwareError`
naming the field, the offending value and what is allowed (the style of
``protocol/study/config.py``); nothing is opened with a bad file.  The documented
example is ``hardware.example.toml`` at the repository root.

The settings only describe the rig; :mod:`pipeline.assembly.real_rig` opens the
devices they name.  The haptic device and the robot are models of the device
registry (:mod:`pipeline.devices.registry`; ``[haptic] model``, ``[robot] model``,
by default the paper's Touch and UR3), whose limits the file is checked against:
``framework.f_max_n`` at most the haptic device's peak force,
``haptic.command_timeout_s`` at least two of its servo periods, and the robot's
automatic rate (``frequency_hz = -1``) its controller's own.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from pipeline.devices.registry import (
    DEFAULT_HAPTIC_MODEL,
    DEFAULT_ROBOT_MODEL,
    HapticModel,
    haptic_model,
    haptic_models,
    robot_model,
    robot_models,
)

# SINGLE_ARM_NAME: the one arm of a file without [[arm]] tables
from pipeline.devices.rig import ARM_NAME, ARM_NAME_WHAT, SINGLE_ARM_NAME
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S
from pipeline.force.config import FrameworkConfig
from pipeline.force.frames import Vec3
from pipeline.runtime.watchdog import WatchdogConfig
from pipeline.settings.tomlfields import Fields, read_toml

__all__ = [
    "FAULT_POLICIES",
    "SINGLE_ARM_NAME",
    "ArmSettings",
    "HapticSettings",
    "HardwareConfig",
    "HardwareError",
    "JawSettings",
    "RobotSettings",
    "SensorSettings",
    "TeleopSettings",
    "hardware_from_dict",
    "load_hardware",
]

ROBOT_MODES = ("observe", "teleop")
#: The calibration file when ``[calibration] file`` is not given (next to the hardware file).
DEFAULT_CALIBRATION_FILE = "calibration.json"
#: What a fault on one arm does to the others (``[rig] fault_policy``): ``both`` -- every arm ramps to zero (a
#: person's two hands are on the rig; the default); ``independent`` -- the other arms keep rendering.
FAULT_POLICIES = ("both", "independent")
#: The tables of one arm: a one-arm file has them at the top level, an ``[[arm]]`` table holds them.
_ARM_TABLES = ("sensor", "robot", "haptic", "jaw", "frames", "framework", "calibration", "teleop")


class HardwareError(ValueError):
    """A hardware file or value is invalid; the message names field, value and what is allowed."""


@dataclass(frozen=True, slots=True)
class SensorSettings:
    """ATI Net F/T box."""

    host: str
    port: int = 49152
    http_port: int = 80
    counts_per_force: float | None = None
    counts_per_torque: float | None = None
    force_unit: str = "N"
    torque_unit: str = "Nm"
    buffered: bool = False
    connect_timeout_s: float = 2.0


@dataclass(frozen=True, slots=True)
class RobotSettings:
    """The robot's controller (a UR over RTDE); ``model`` is its key in :mod:`pipeline.devices.registry`."""

    host: str
    frequency_hz: float = 125.0
    mode: str = "observe"
    tcp_offset_m: Vec3 = (0.0, 0.0, 0.0)
    connect_timeout_s: float = 2.0
    model: str = DEFAULT_ROBOT_MODEL


@dataclass(frozen=True, slots=True)
class TeleopSettings:
    """App-side teleoperation (``robot.mode = "teleop"``); see :class:`pipeline.devices.teleop.TeleopConfig`."""

    workspace_min_m: Vec3
    workspace_max_m: Vec3
    max_speed_m_s: float = 0.1
    motion_scale: float = 1.0
    deadman_button: int = 1
    clutch_button: int = 2
    stylus_max_age_s: float = 0.02
    pose_max_age_s: float = 0.05
    max_tracking_error_m: float = 0.05
    #: servoL's look-ahead: its lag is about its own length (UR client library #86: ~34 ms at 0.03 s), the robot's
    #: share of the hand → tip latency (docs/hardware-setup.md, "End-to-end latency"): the smallest allowed.
    lookahead_s: float = 0.03
    gain: float = 300.0
    control_timeout_s: float = 5.0


@dataclass(frozen=True, slots=True)
class HapticSettings:
    """The haptic device (the 3D Systems Touch by default); ``model`` is its key in :mod:`pipeline.devices.registry`."""

    #: The device's name in its vendor's set-up (OpenHaptics' Touch Setup).
    device_name: str = "Default Device"
    #: A command this old renders as zero, in the device's own servo thread (the device-side watchdog).
    command_timeout_s: float = DEFAULT_COMMAND_TIMEOUT_S
    #: The folder holding the vendor's library (``HD.dll``; Windows looks there before pyOpenHaptics loads it); None:
    #: the system's folders.
    dll_dir: str | None = None
    model: str = DEFAULT_HAPTIC_MODEL


@dataclass(frozen=True, slots=True)
class JawSettings:
    """Jaw actuator Arduino, and the Touch's stylus buttons that drive it (when teleoperation does not claim them)."""

    port: str
    baud: int = 115200
    ready_timeout_s: float = 3.0
    close_button: int = 1
    open_button: int = 2


@dataclass(frozen=True, slots=True)
class ArmFields:
    """What a one-arm file's top level and each ``[[arm]]`` table say: the arm's devices, frames and calibration."""

    sensor: SensorSettings
    robot: RobotSettings
    haptic: HapticSettings
    jaw: JawSettings | None
    framework: FrameworkConfig = field(default_factory=FrameworkConfig)
    #: The arm's calibration file (:mod:`pipeline.commissioning.rig_calibration`); ``calibration.json`` next to the
    #: hardware file by default.
    calibration_file: str | None = None
    #: The file the settings came from (for messages; the same for every arm of a file).
    source: str = "hardware"
    teleop: TeleopSettings | None = None
    #: The instrument mounted on the arm now: its record in the calibration file is the one in use.
    calibration_tool: str = "instrument"


@dataclass(frozen=True, slots=True)
class ArmSettings(ArmFields):
    """One arm of the rig: its devices, frames and calibration (the fields of a one-arm file), and its name."""

    name: str = field(kw_only=True)


@dataclass(frozen=True, slots=True)
class HardwareConfig(ArmFields):
    """A validated hardware file.

    ``arms`` lists every arm, the first (the task arm until the protocol names one) first; the other fields are the
    first arm's, so code that knows one arm reads a two-arm file's first arm unchanged.  Built from the one-arm
    fields alone (``arms`` empty), the rig is that one arm, named :data:`SINGLE_ARM_NAME`.
    """

    #: Every arm, the first first (see the class's docstring).
    arms: tuple[ArmSettings, ...] = ()
    #: What a fault on one arm does to the others: one of :data:`FAULT_POLICIES`.
    fault_policy: str = "both"

    def __post_init__(self) -> None:
        name = self.arms[0].name if self.arms else SINGLE_ARM_NAME
        first = ArmSettings(**_arm_fields(self), name=name)
        if not self.arms or self.arms[0] != first:  # built from the one-arm fields, or they were replaced
            object.__setattr__(self, "arms", (first, *self.arms[1:]))

    @classmethod
    def of_arms(cls, arms: tuple[ArmSettings, ...], fault_policy: str = "both") -> HardwareConfig:
        """The configuration of these arms; its one-arm fields are the first arm's."""
        return cls(**_arm_fields(arms[0]), arms=arms, fault_policy=fault_policy)

    def arm(self, name: str) -> ArmSettings:
        """The arm called ``name`` (KeyError naming the arms there are)."""
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f"no arm {name!r} in {self.source}; its arms: {', '.join(a.name for a in self.arms)}")


def _arm_fields(a: ArmFields) -> dict[str, Any]:
    """An arm's (or a configuration's first arm's) :class:`ArmFields`, by name."""
    return {f.name: getattr(a, f.name) for f in fields(ArmFields)}


# -- validation ------------------------------------------------------------------------------
_PORT = "a whole port number"
_DEVICE_PATH = "a non-empty string without spaces (a serial device path such as /dev/ttyACM0 or COM3)"


def hardware_from_dict(d: Any, source: str = "hardware") -> HardwareConfig:
    """Validate plain data (a parsed TOML file) into a :class:`HardwareConfig`.

    A file describes one arm with top-level tables (``[sensor]``, ``[robot]``, …), or one or more arms with
    ``[[arm]]`` tables, each holding the same tables and a ``name``; never both.  A field of an arm's table is
    named in an error after the arm (``<file>: arm 'left': sensor.host = …``).

    Raises
    ------
    HardwareError
        One line naming ``source``, the arm (with ``[[arm]]`` tables), the field, the value and what is allowed.
    """
    f = Fields(source, HardwareError)
    top = f.table("", d, {"version", "arm", "rig", *_ARM_TABLES})
    f.version(top, "hardware file")
    rig = f.section(top, "rig", {"fault_policy"})
    policy = f.choice("rig.fault_policy", rig.get("fault_policy", "both"), FAULT_POLICIES,
                      "allowed values: 'both' (a fault on one arm ramps every arm to zero) and 'independent' (the "
                      "other arms keep rendering)")
    if "arm" not in top:
        return HardwareConfig.of_arms((_arm(f, top, SINGLE_ARM_NAME, source),), policy)
    stray = [k for k in _ARM_TABLES if k in top]
    if stray:
        raise f.fail(stray[0], top[stray[0]], "with [[arm]] tables every device table belongs to an arm: move "
                     f"[{stray[0]}] into an [[arm]] table as [arm.{stray[0]}] (see hardware.example.toml)")
    tables = top["arm"]
    if not isinstance(tables, list) or not tables or not all(isinstance(t, dict) for t in tables):
        raise f.fail("arm", tables, "must be one or more [[arm]] tables, each with a name and its devices")
    if len(tables) > 4:
        raise f.fail("arm", f"{len(tables)} [[arm]] tables", "at most 4 arms")
    arms: list[ArmSettings] = []
    for i, t in enumerate(tables):
        f.required(t, f"arm[{i}]", "name", "required: the arm's name, e.g. 'left' or 'right'")
        name = f.string(f"arm[{i}].name", t["name"], pattern=ARM_NAME, what=ARM_NAME_WHAT)
        if any(a.name == name for a in arms):
            raise f.fail(f"arm[{i}].name", name, "each arm needs its own name; this one is taken by an earlier arm")
        fa = Fields(f"{source}: arm {name!r}", HardwareError)
        arm_top = fa.table("", {k: v for k, v in t.items() if k != "name"}, set(_ARM_TABLES))
        arms.append(_arm(fa, arm_top, name, source, default_calibration=f"calibration-{name}.json"))
    _distinct(f, arms)
    return HardwareConfig.of_arms(tuple(arms), policy)


def _arm(f: Fields, top: dict[str, Any], name: str, source: str,
         default_calibration: str | None = None) -> ArmSettings:
    """One arm's tables (the top level of a one-arm file, or an ``[[arm]]`` table), validated."""
    for required in ("sensor", "robot", "haptic"):
        f.required(top, "", required, f"the [{required}] table is required")
    sensor = _sensor(f, top["sensor"])
    robot = _robot(f, top["robot"], has_teleop="teleop" in top)
    haptic = _haptic(f, top["haptic"])
    jaw = _jaw(f, top["jaw"]) if "jaw" in top else None
    framework = _framework(f, top, haptic_model(haptic.model))
    cal = f.section(top, "calibration", {"file", "tool"})
    cal_file = cal.get("file", default_calibration)
    if cal_file is not None:
        cal_file = f.string("calibration.file", cal_file, what="the path of the calibration JSON file")
    tool = f.string("calibration.tool", cal.get("tool", "instrument"),
                    what="a non-empty name of the mounted instrument (its calibration is kept under it)")
    teleop = _teleop(f, top["teleop"]) if "teleop" in top else None
    rate_hz = robot_model(robot.model).rate_hz(robot.frequency_hz)
    if teleop is not None and teleop.pose_max_age_s <= 1.0 / rate_hz:
        raise f.fail("teleop.pose_max_age_s", teleop.pose_max_age_s,
                     f"must be longer than the robot's pose period, 1 / robot.frequency_hz = "
                     f"{1e3 / rate_hz:g} ms (teleoperation would stop the robot at every pose)")
    return ArmSettings(sensor, robot, haptic, jaw, framework, cal_file, source, teleop, tool, name=name)


def _distinct(f: Fields, arms: list[ArmSettings]) -> None:
    """Refuse two arms on one device: one sensor address, robot address, Touch, jaw port or calibration record."""
    keys: list[tuple[str, str, Any]] = [
        ("sensor.host", "a Net F/T box has one address: two arms cannot read one sensor",
         lambda a: a.sensor.host.lower()),
        ("robot.host", "a UR controller drives one arm: two arms cannot share one robot",
         lambda a: a.robot.host.lower()),
        ("haptic.device_name", "one Touch (its OpenHaptics device name), as any haptic device by its name, serves "
         "one arm", lambda a: (a.haptic.model, a.haptic.device_name)),
        ("jaw.port", "one jaw actuator's serial port serves one arm", lambda a: None if a.jaw is None else a.jaw.port),
        ("calibration.tool", "the two arms' calibrations would overwrite each other in one calibration file: name "
         "another calibration.file or tool",
         lambda a: (os.path.normcase(os.path.normpath(a.calibration_file or DEFAULT_CALIBRATION_FILE)),
                    a.calibration_tool)),
    ]
    for fld, why, key in keys:
        seen: dict[Any, str] = {}
        for a in arms:
            k = key(a)
            if k is None:
                continue
            if k in seen:
                value = k[1] if isinstance(k, tuple) else k
                raise HardwareError(f"{f.source}: arm {a.name!r}: {fld} = {value!r}: arm {seen[k]!r} has it already; "
                                    f"{why}")
            seen[k] = a.name


def _sensor(f: Fields, v: Any) -> SensorSettings:
    """``[sensor]``: the Net F/T box."""
    s = f.table("sensor", v, {
        "host", "port", "http_port", "counts_per_force", "counts_per_torque", "force_unit", "torque_unit",
        "buffered", "connect_timeout_s",
    })
    f.required(s, "sensor", "host", "required: the Net F/T box's IP address")
    cpf, cpt = s.get("counts_per_force"), s.get("counts_per_torque")
    if (cpf is None) != (cpt is None):
        missing = "sensor.counts_per_torque" if cpt is None else "sensor.counts_per_force"
        raise f.fail(missing, None,
                     "give counts_per_force and counts_per_torque together (or neither, to read the box's XML)")
    from pipeline.backends.netft import NetFTError, force_unit_to_n, torque_unit_to_nm

    if cpf is not None:  # counts per *unit*: a unit taken by default would scale every force by a guess
        for unit, counts in (("force_unit", "counts_per_force"), ("torque_unit", "counts_per_torque")):
            f.required(s, "sensor", unit, f"required with sensor.{counts}: the unit the box's counts are per (as its "
                                          "web page shows it, e.g. N or lbf); a wrong one scales every force")
    fu, tu = s.get("force_unit", "N"), s.get("torque_unit", "Nm")
    for fld, unit, check in (("sensor.force_unit", fu, force_unit_to_n), ("sensor.torque_unit", tu, torque_unit_to_nm)):
        try:
            if not isinstance(unit, str):
                raise NetFTError("must be a string")
            check(unit)
        except NetFTError as exc:
            raise f.fail(fld, unit, str(exc).split("; ")[-1]) from None
    return SensorSettings(
        # the Net F/T backend opens an AF_INET socket and builds an http:// URL from the host: IPv4 only
        host=f.host("sensor.host", s["host"], ipv6=False),
        port=f.integer("sensor.port", s.get("port", 49152), lo=1, hi=65535, what=_PORT),
        http_port=f.integer("sensor.http_port", s.get("http_port", 80), lo=1, hi=65535, what=_PORT),
        counts_per_force=None if cpf is None else f.number("sensor.counts_per_force", cpf, lo=0.0, hi=1e12),
        counts_per_torque=None if cpt is None else f.number("sensor.counts_per_torque", cpt, lo=0.0, hi=1e12),
        force_unit=fu, torque_unit=tu, buffered=f.boolean("sensor.buffered", s.get("buffered", False)),
        connect_timeout_s=f.number("sensor.connect_timeout_s", s.get("connect_timeout_s", 2.0), lo=0.0, hi=60.0),
    )


def _robot(f: Fields, v: Any, *, has_teleop: bool) -> RobotSettings:
    """``[robot]``: the UR controller (``has_teleop``: the file has a ``[teleop]`` table)."""
    r = f.table("robot", v, {"host", "frequency_hz", "mode", "tcp_offset_m", "connect_timeout_s", "model"})
    f.required(r, "robot", "host", "required: the UR controller's IP address")
    model = robot_model(f.choice("robot.model", r.get("model", DEFAULT_ROBOT_MODEL), robot_models(),
                                 _models_allowed(robot_models(), lambda k: robot_model(k).name)))
    freq = r.get("frequency_hz", 125.0)
    if not (type(freq) is int and freq == -1):
        freq = f.number("robot.frequency_hz", freq, lo=0.0, hi=500.0, note="(Hz), or -1 to let ur_rtde choose")
    pose_limit_s = WatchdogConfig().pose_max_age_s
    if 1.0 / model.rate_hz(freq) >= pose_limit_s:
        raise f.fail("robot.frequency_hz", r.get("frequency_hz"),
                     f"must be above {1.0 / pose_limit_s:g} Hz: the watchdog faults when the robot pose is older "
                     f"than {pose_limit_s * 1e3:g} ms (watchdog.pose_max_age_s), and at {freq:g} Hz each pose "
                     f"is {1e3 / freq:g} ms old when the next arrives")
    mode = f.choice("robot.mode", r.get("mode", "observe"), ROBOT_MODES)
    if mode == "teleop" and not has_teleop:
        raise f.fail("teleop", None, "robot.mode = 'teleop' needs a [teleop] table with at least workspace_min_m "
                     "and workspace_max_m (see hardware.example.toml)")
    return RobotSettings(
        host=f.host("robot.host", r["host"]), frequency_hz=float(freq), mode=mode,
        tcp_offset_m=f.vec3("robot.tcp_offset_m", r.get("tcp_offset_m", [0.0, 0.0, 0.0]), limit=1.0,
                            what="must be 3 numbers in metres, each within ±1 m"),
        connect_timeout_s=f.number("robot.connect_timeout_s", r.get("connect_timeout_s", 2.0), lo=0.0, hi=60.0),
        model=model.key,
    )


def _models_allowed(keys: tuple[str, ...], name: Any) -> str:
    """The refusal's "what is allowed" of a model key: every registered model, by key and name."""
    return "allowed values: " + ", ".join(f"{k!r} ({name(k)})" for k in keys)


def _haptic(f: Fields, v: Any) -> HapticSettings:
    """``[haptic]``: the haptic device (a Touch by default)."""
    h = f.table("haptic", v, {"device_name", "command_timeout_s", "dll_dir", "model"})
    model = haptic_model(f.choice("haptic.model", h.get("model", DEFAULT_HAPTIC_MODEL), haptic_models(),
                                  _models_allowed(haptic_models(), lambda k: haptic_model(k).name)))
    dll_dir = h.get("dll_dir")
    if dll_dir is not None:
        dll_dir = f.string("haptic.dll_dir", dll_dir, what="the path of the folder holding OpenHaptics' HD.dll "
                           "(e.g. 'C:/OpenHaptics/Developer/3.4.0/lib/x64/Release'), absolute or relative to "
                           "this file")
        if "\0" in dll_dir:
            raise f.fail("haptic.dll_dir", dll_dir, "a path without NUL characters")
    return HapticSettings(
        f.string("haptic.device_name", h.get("device_name", "Default Device"),
                 what="a non-empty string (the OpenHaptics device name)"),
        # at most 50 ms: every fault must reach zero force within 50 ms, a dead loop included; at least two of the
        # device's servo periods (one late servo tick must not drop a fresh command)
        f.number("haptic.command_timeout_s", h.get("command_timeout_s", DEFAULT_COMMAND_TIMEOUT_S),
                 lo=model.min_command_timeout_s, hi=0.05, lo_open=False,
                 note="s (a force command this old renders as zero)"),
        dll_dir,
        model.key,
    )


def _jaw(f: Fields, v: Any) -> JawSettings:
    """``[jaw]``: the jaw actuator's Arduino and its buttons."""
    j = f.table("jaw", v, {"port", "baud", "ready_timeout_s", "close_button", "open_button"})
    f.required(j, "jaw", "port", "required: the Arduino's serial port, e.g. /dev/ttyACM0 or COM3")
    close_button, open_button = _two_buttons(f, "jaw", j, "close_button", "open_button")
    return JawSettings(
        f.string("jaw.port", j["port"], what=_DEVICE_PATH, spaces=False),
        f.choice("jaw.baud", j.get("baud", 115200), (9600, 19200, 38400, 57600, 115200),
                 "allowed values: 9600, 19200, 38400, 57600, 115200 (the sketch uses 115200)"),
        f.number("jaw.ready_timeout_s", j.get("ready_timeout_s", 3.0), lo=0.0, hi=60.0),
        close_button, open_button,
    )


#: What the two rotations of ``[frames]`` are, for the message when one is missing (no default: a guess sets a
#: force's direction).
_ROTATIONS = {
    "rot_tip_sensor": "the sensor's mounting on the instrument (e.g. [[1, 0, 0], [0, 1, 0], [0, 0, 1]] for a sensor "
                      "coaxial with it)",
    "rot_haptic_base": "how the experimenter faces the robot (e.g. [[1, 0, 0], [0, 0, 1], [0, -1, 0]] facing it along "
                       "base +y)",
}


def _framework(f: Fields, top: dict[str, Any], haptic: HapticModel) -> FrameworkConfig:
    """``[frames]`` and ``[framework]``: Algorithm 1's rotations and scaling.

    What sets a rendered force's direction (both rotations) or size (f_max,
    f_scale) has no default on a real rig: a file without it is refused, so no
    identity or textbook value is ever taken silently.
    """
    fr = f.section(top, "frames", {"rot_tip_sensor", "rot_haptic_base"})
    fw = f.section(top, "framework", {"f_max_n", "f_scale_n", "filter_window"})
    # the safety clamp is min(f_max, the device's reported peak): an f_max above the device's peak would be a
    # setting the device silently ignores (and the paper's scaling law would no longer hold)
    # what the file gives is checked first, then what it lacks
    # (f_max from 1 µN: the safety stage's own lower bound (SafetyConfig), so no value passes here and fails there)
    f_max = (f.number("framework.f_max_n", fw["f_max_n"], lo=1e-6, hi=haptic.peak_force_n, lo_open=False,
                      note=f"(N; the {haptic.name}'s peak force)") if "f_max_n" in fw else None)
    f_scale = f.number("framework.f_scale_n", fw["f_scale_n"], lo=0.0, hi=1000.0) if "f_scale_n" in fw else None
    rot_ts = f.rotation("frames.rot_tip_sensor", fr["rot_tip_sensor"]) if "rot_tip_sensor" in fr else None
    rot_hb = f.rotation("frames.rot_haptic_base", fr["rot_haptic_base"]) if "rot_haptic_base" in fr else None
    window = f.integer("framework.filter_window", fw.get("filter_window", 10), lo=1, hi=1000,
                       what="a whole number of samples")
    for key, what in (("f_max_n", "the largest force rendered (the paper's 3.0 N)"),
                      ("f_scale_n", "the tanh scaling's force scale (the paper's 7.0 N)")):
        f.required(fw, "framework", key, f"required on a real rig: {what}; it sets the size of every rendered force")
    for key, what in _ROTATIONS.items():
        f.required(fr, "frames", key, f"required on a real rig: {what}; it sets the direction of every rendered "
                                      "force (see hardware.example.toml)")
    assert f_max is not None and f_scale is not None and rot_ts is not None and rot_hb is not None
    return FrameworkConfig(
        f_max_n=f_max, f_scale_n=f_scale, filter_window=window, rot_tip_sensor=rot_ts, rot_haptic_base=rot_hb,
    )


def _two_buttons(f: Fields, table: str, t: dict[str, Any], first: str, second: str) -> tuple[int, int]:
    """Two of the Touch's stylus buttons, ``first`` (default 1) and ``second`` (default 2), which must differ."""
    a, b = (f.choice(f"{table}.{fld}", t.get(fld, default), (1, 2),
                     "allowed values: 1 (the Touch's front, dark-grey button), 2 (rear, light-grey)")
            for fld, default in ((first, 1), (second, 2)))
    if a == b:
        raise f.fail(f"{table}.{second}", b, f"must differ from {table}.{first}")
    return a, b


def _teleop(f: Fields, v: Any) -> TeleopSettings:
    """``[teleop]``: app-side teleoperation."""
    t = f.table("teleop", v, {
        "workspace_min_m", "workspace_max_m", "max_speed_m_s", "motion_scale", "deadman_button", "clutch_button",
        "stylus_max_age_s", "pose_max_age_s", "max_tracking_error_m", "lookahead_s", "gain", "control_timeout_s",
    })
    for req in ("workspace_min_m", "workspace_max_m"):
        f.required(t, "teleop", req, "required: the corner of the box (m, robot base frame) the TCP must stay in")
    box = "must be 3 numbers in metres (x, y, z in the robot base frame), each within ±1 m"
    lo = f.vec3("teleop.workspace_min_m", t["workspace_min_m"], limit=1.0, what=box)
    hi = f.vec3("teleop.workspace_max_m", t["workspace_max_m"], limit=1.0, what=box)
    for i, axis in enumerate("xyz"):
        if not lo[i] < hi[i]:
            raise f.fail("teleop.workspace_max_m", t["workspace_max_m"],
                         f"each coordinate must be above workspace_min_m's ({axis}: {hi[i]:g} ≤ {lo[i]:g})")
    deadman, clutch = _two_buttons(f, "teleop", t, "deadman_button", "clutch_button")
    return TeleopSettings(
        workspace_min_m=lo, workspace_max_m=hi,
        max_speed_m_s=f.number("teleop.max_speed_m_s", t.get("max_speed_m_s", 0.1), lo=0.0, hi=0.25),
        motion_scale=f.number("teleop.motion_scale", t.get("motion_scale", 1.0), lo=0.0, hi=10.0),
        deadman_button=deadman, clutch_button=clutch,
        stylus_max_age_s=f.number("teleop.stylus_max_age_s", t.get("stylus_max_age_s", 0.02), lo=0.0, hi=1.0),
        pose_max_age_s=f.number("teleop.pose_max_age_s", t.get("pose_max_age_s", 0.05), lo=0.0, hi=1.0),
        max_tracking_error_m=f.number("teleop.max_tracking_error_m", t.get("max_tracking_error_m", 0.05), lo=0.0,
                                      hi=0.2),
        lookahead_s=f.number("teleop.lookahead_s", t.get("lookahead_s", 0.03), lo=0.03, hi=0.2, lo_open=False,
                             note="s (servoL's look-ahead time)"),
        gain=f.number("teleop.gain", t.get("gain", 300.0), lo=100.0, hi=2000.0, lo_open=False,
                      note="(servoL's proportional gain)"),
        control_timeout_s=f.number("teleop.control_timeout_s", t.get("control_timeout_s", 5.0), lo=0.0, hi=60.0),
    )


def load_hardware(path: str | Path) -> HardwareConfig:
    """Load and validate a hardware file (paths in it are relative to it)."""
    p = Path(path)
    src = str(p)
    data = read_toml(p, HardwareError, "hardware file", " (copy hardware.example.toml and edit it)")
    hw = hardware_from_dict(data, src)
    arms = tuple(_resolve_paths(a, p, multi="arm" in data) for a in hw.arms)
    return HardwareConfig.of_arms(arms, hw.fault_policy)


def _resolve_paths(arm: ArmSettings, p: Path, *, multi: bool) -> ArmSettings:
    """The arm's calibration file and DLL folder relative to the hardware file ``p``; the folder must exist."""
    # a relative calibration path is relative to the hardware file, not to the working directory
    cal = Path(arm.calibration_file if arm.calibration_file is not None else DEFAULT_CALIBRATION_FILE)
    arm = replace(arm, calibration_file=str(cal if cal.is_absolute() else p.parent / cal))
    if arm.haptic.dll_dir is not None:  # relative to the hardware file too; it must be a folder there now
        dll = Path(arm.haptic.dll_dir)
        dll = dll if dll.is_absolute() else p.parent / dll
        if not dll.is_dir():
            what = "is not a folder" if dll.exists() else "no such folder"
            where = f"arm {arm.name!r}: " if multi else ""
            raise HardwareError(f"{p}: {where}haptic.dll_dir = {arm.haptic.dll_dir!r}: {what} ({dll}); give the "
                                "folder that holds OpenHaptics' HD.dll, or remove the line to use the system's folders")
        arm = replace(arm, haptic=replace(arm.haptic, dll_dir=str(dll)))
    return arm
