"""The real rig: the devices a :class:`~pipeline.settings.hardware.HardwareConfig` names, opened.

:func:`build_real_rig` opens every arm's devices (Net F/T, UR over RTDE, Touch,
optional jaw) into a :class:`RealRig`, which satisfies :class:`pipeline.devices.rig.Rig`
and lists its arms (:class:`RealArm`).  With two or more arms, every arm's Touch
is opened by its OpenHaptics device name into one servo scheduler
(:class:`pipeline.backends.touch.TouchScheduler`), started once every arm's Touch
is open.  If one device fails, the ones already opened are closed again and the
error names the device (and, with more than one arm, the arm).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, ForceSensor, HapticDevice, JawActuator, Robot
from pipeline.devices.rig import RigArm
from pipeline.force.frames import Vec3
from pipeline.settings.hardware import (
    ArmSettings,
    HapticSettings,
    HardwareConfig,
    HardwareError,
    JawSettings,
    RobotSettings,
    SensorSettings,
    TeleopSettings,
)

__all__ = ["RealArm", "RealRig", "build_real_rig", "open_haptic", "open_jaw", "open_robot", "open_sensor",
           "open_servo", "open_touch_scheduler", "teleop_config"]


class RealArm:
    """One arm's opened devices: its sensor, robot, Touch, optional jaw and teleoperation driver."""

    def __init__(
        self, name: str, sensor: ForceSensor, robot: Robot, haptic: HapticDevice, jaw: JawActuator | None = None,
        teleop: Any = None
    ) -> None:
        self.name = name
        self.sensor = sensor
        self.robot = robot
        self.haptic = haptic
        self.jaw = jaw
        #: A :class:`pipeline.devices.teleop.TeleopDriver` when the app owns the robot (``robot.mode = "teleop"``).
        self.teleop = teleop
        #: Called with (now_ns, the stylus buttons) every tick:
        #: :meth:`pipeline.devices.jaw_control.JawController.buttons`.
        self.on_buttons: Callable[[int, int], None] | None = None

    def advance(self, now_ns: int) -> None:
        """With teleoperation, one call of the controller (no I/O: the adapter's thread sends); the stylus buttons
        go to the jaw's controller (no I/O either: it queues)."""
        if self.teleop is not None:
            self.teleop.update(now_ns)
        hook = self.on_buttons
        if hook is not None:
            hook(now_ns, self.haptic.read_state().buttons)

    def on_faults(self, faults: int) -> None:
        """The arm's latched faults changed: with teleoperation, any fault stops its robot
        (``pipeline.devices.rig.Rig``).  In ``"observe"`` mode the robot runs its own program and is not ours to stop.
        """
        if self.teleop is not None:
            self.teleop.on_faults(faults)

    def stop_motion(self, reason: str) -> None:
        """The loop is stopping: with teleoperation, stop the robot."""
        if self.teleop is not None:
            self.teleop.stop_motion(reason)

    def rig_arm(self) -> RigArm:
        """This arm as the loop sees it."""
        return RigArm(self.name, self.sensor, self.robot, self.haptic, self.jaw, on_faults=self.on_faults,
                      stop_motion=self.stop_motion)


class RealRig:
    """The devices of the real rig, satisfying :class:`pipeline.devices.rig.Rig`: its ``sensor``, ``robot``,
    ``haptic``, ``jaw``, ``teleop`` and ``on_buttons`` are the first arm's; ``arms`` lists every arm for the loop.

    Parameters
    ----------
    real_arms
        Every arm's devices, the first arm first.
    """

    def __init__(self, real_arms: Sequence[RealArm]) -> None:
        if not real_arms:
            raise ValueError("a rig needs at least one arm")
        self.real_arms: tuple[RealArm, ...] = tuple(real_arms)
        self.first = self.real_arms[0]
        self.arms: tuple[RigArm, ...] = tuple(a.rig_arm() for a in self.real_arms)

    def arm(self, name: str) -> RealArm:
        """The arm called ``name`` (KeyError naming the arms there are)."""
        for a in self.real_arms:
            if a.name == name:
                return a
        raise KeyError(f"no arm {name!r}; the rig's arms: {', '.join(a.name for a in self.real_arms)}")

    @property
    def sensor(self) -> ForceSensor:
        """The first arm's F/T sensor."""
        return self.first.sensor

    @property
    def robot(self) -> Robot:
        """The first arm's robot."""
        return self.first.robot

    @property
    def haptic(self) -> HapticDevice:
        """The first arm's Touch."""
        return self.first.haptic

    @property
    def jaw(self) -> JawActuator | None:
        """The first arm's jaw actuator."""
        return self.first.jaw

    @property
    def teleop(self) -> Any:
        """The first arm's teleoperation driver."""
        return self.first.teleop

    @property
    def on_buttons(self) -> Callable[[int, int], None] | None:
        """The first arm's stylus-button hook (each arm's is its :attr:`RealArm.on_buttons`)."""
        return self.first.on_buttons

    @on_buttons.setter
    def on_buttons(self, hook: Callable[[int, int], None] | None) -> None:
        self.first.on_buttons = hook

    def advance(self, now_ns: int) -> None:
        """Every arm's :meth:`RealArm.advance`."""
        for a in self.real_arms:
            a.advance(now_ns)

    def true_contact_force(self) -> None:
        """No ground truth on hardware."""
        return None

    def on_faults(self, faults: int) -> None:
        """The first arm's hook (the loop calls each arm's own, :attr:`arms`)."""
        self.first.on_faults(faults)

    def stop_motion(self, reason: str) -> None:
        """The loop is stopping: every teleoperated robot stops."""
        for a in self.real_arms:
            a.stop_motion(reason)

    def close(self) -> None:
        """Zero and release every device of every arm, a kind at a time: teleoperation first (every robot stops
        before anything else goes away), then the Touch devices, robots, sensors and jaws; a failing close does
        not skip the others."""
        errors = []
        for kind in ("teleop", "haptic", "robot", "sensor", "jaw"):
            for a in self.real_arms:
                dev = getattr(a, kind)
                if dev is None:
                    continue
                try:
                    dev.close()
                except Exception as exc:  # close everything, report after
                    who = type(dev).__name__ if len(self.real_arms) == 1 else f"arm {a.name!r}: {type(dev).__name__}"
                    errors.append(f"{who}: {exc}")
        if errors:
            raise DeviceError("closing the rig: " + "; ".join(errors))


def open_sensor(cfg: SensorSettings, clock: Clock) -> ForceSensor:
    """Open the Net F/T box described by ``cfg``."""
    from pipeline.backends.netft import NetFTCalibration, NetFTForceSensor

    cal = None
    if cfg.counts_per_force is not None and cfg.counts_per_torque is not None:
        cal = NetFTCalibration(cfg.counts_per_force, cfg.counts_per_torque, cfg.force_unit, cfg.torque_unit)
    return NetFTForceSensor(
        cfg.host, port=cfg.port, http_port=cfg.http_port, calibration=cal, clock=clock,
        connect_timeout_s=cfg.connect_timeout_s, buffered=cfg.buffered,
    )


def open_robot(cfg: RobotSettings, clock: Clock, tip_in_flange_m: Vec3 | None = None) -> Robot:
    """Connect to the UR controller described by ``cfg`` (read only).

    With ``tip_in_flange_m`` (a TCP calibration on record) the poses are moved from the pendant's TCP
    (``robot.tcp_offset_m``) to the calibrated tip.
    """
    from pipeline.backends.ur import UrRtdeRobot

    corr = (0.0, 0.0, 0.0) if tip_in_flange_m is None else tuple(
        t - o for t, o in zip(tip_in_flange_m, cfg.tcp_offset_m, strict=True))
    return UrRtdeRobot(cfg.host, frequency_hz=cfg.frequency_hz, clock=clock, connect_timeout_s=cfg.connect_timeout_s,
                       tcp_correction_m=corr)  # type: ignore[arg-type]  # three items: mypy cannot count a generator


def open_servo(
    robot: RobotSettings, teleop: TeleopSettings, clock: Clock,
    control_factory: Callable[[str, float], Any] | None = None
) -> Any:
    """Take control of the UR for teleoperation (uploads ur_rtde's control script).

    ``control_factory`` replaces ur_rtde's ``RTDEControlInterface`` (see
    :class:`pipeline.backends.ur_control.UrRtdeServo`); None uses ur_rtde.
    """
    from pipeline.backends.ur_control import UrRtdeServo

    return UrRtdeServo(
        robot.host, frequency_hz=robot.frequency_hz, clock=clock, connect_timeout_s=robot.connect_timeout_s,
        control_timeout_s=teleop.control_timeout_s, lookahead_s=teleop.lookahead_s, gain=teleop.gain,
        control_factory=control_factory,
    )


def teleop_config(config: HardwareConfig | ArmSettings) -> Any:
    """The :class:`pipeline.devices.teleop.TeleopConfig` of a teleop-mode hardware file (its first arm's) or arm."""
    from pipeline.devices.teleop import TeleopConfig

    t = config.teleop
    if t is None:
        where = f"arm {config.name!r}: " if isinstance(config, ArmSettings) else ""
        raise HardwareError(f"{config.source}: {where}teleop = None: robot.mode = 'teleop' needs a [teleop] table")
    freq = config.robot.frequency_hz
    return TeleopConfig(
        workspace_min_m=t.workspace_min_m, workspace_max_m=t.workspace_max_m, max_speed_m_s=t.max_speed_m_s,
        motion_scale=t.motion_scale, period_s=1.0 / freq if freq > 0 else 0.008,
        rot_haptic_base=config.framework.rot_haptic_base, deadman_button=t.deadman_button,
        clutch_button=t.clutch_button,
        stylus_max_age_s=t.stylus_max_age_s, pose_max_age_s=t.pose_max_age_s,
        max_tracking_error_m=t.max_tracking_error_m,
    )


def open_haptic(cfg: HapticSettings, clock: Clock) -> HapticDevice:
    """Open the Touch (needs OpenHaptics and the ``touch`` extra)."""
    from pipeline.backends.touch import TouchHapticDevice

    return TouchHapticDevice(cfg.device_name, clock=clock, command_timeout_s=cfg.command_timeout_s,
                             dll_dir=cfg.dll_dir)


_OPEN_HAPTIC = open_haptic  # the module's own: see _Touches


def open_touch_scheduler(dll_dir: str | None) -> Any:
    """One OpenHaptics servo scheduler for every arm's Touch (:class:`pipeline.backends.touch.TouchScheduler`;
    needs OpenHaptics and the ``touch`` extra)."""
    from pipeline.backends.touch import TouchScheduler

    return TouchScheduler(dll_dir=dll_dir)


def open_jaw(cfg: JawSettings) -> JawActuator:
    """Open the jaw actuator's serial port and wait for READY."""
    from pipeline.backends.jaw import SerialJawActuator

    return SerialJawActuator(cfg.port, baud=cfg.baud, ready_timeout_s=cfg.ready_timeout_s)


class _Touches:
    """Every arm's Touch: one arm's opened alone (:func:`open_haptic`, the seam the app's tests replace); two or
    more into one servo scheduler (:func:`open_touch_scheduler`), made when the first is opened and started once
    every one is -- unless :func:`open_haptic` was replaced, which then opens each."""

    def __init__(self, arms: Sequence[ArmSettings], clock: Clock) -> None:
        # a replaced open_haptic (the app's HostConfig.haptic_factory, a test's stand-in) opens every arm's Touch
        self.shared = len(arms) > 1 and open_haptic is _OPEN_HAPTIC
        self.clock = clock
        self.dll_dir = next((a.haptic.dll_dir for a in arms if a.haptic.dll_dir is not None), None)
        self.scheduler: Any = None

    def open(self, cfg: HapticSettings) -> HapticDevice:
        if not self.shared:
            return open_haptic(cfg, self.clock)
        if self.scheduler is None:
            self.scheduler = open_touch_scheduler(self.dll_dir)
        dev: HapticDevice = self.scheduler.open(cfg.device_name, self.clock, cfg.command_timeout_s)
        return dev

    def start(self) -> None:
        if self.scheduler is not None:
            self.scheduler.start()


def _arm_steps(arm: ArmSettings, clk: Clock, with_jaw: bool, tip: Vec3 | None,
               touches: _Touches) -> list[tuple[str, Callable[[], Any]]]:
    """What to open for one arm, in order: ``(what, opener)``; the jaw only if configured and wanted."""
    steps: list[tuple[str, Callable[[], Any]]] = [
        ("force sensor", lambda: open_sensor(arm.sensor, clk)),
        ("robot", lambda: open_robot(arm.robot, clk, tip)),
        ("haptic device", lambda: touches.open(arm.haptic)),
    ]
    jaw_cfg = arm.jaw
    if with_jaw and jaw_cfg is not None:
        steps.append(("jaw actuator", lambda: open_jaw(jaw_cfg)))
    return steps


def _servo_opener(robot: RobotSettings, teleop: TeleopSettings, clk: Clock,
                  factory: Callable[[str, float], Any] | None) -> Callable[[], Any]:
    return lambda: open_servo(robot, teleop, clk, factory)


def _open_all(steps: list[tuple[str, str, Callable[[], Any]]], on_open: Callable[[str], None] | None,
              multi: bool) -> dict[tuple[str, str], Any]:
    """Run every ``(arm, what, opener)``; on a :class:`DeviceError` close what was opened (newest first) and raise
    one line naming the device, and with more than one arm the arm."""
    opened: dict[tuple[str, str], Any] = {}
    for arm, what, opener in steps:
        label = f"arm {arm!r}: {what}" if multi and arm else what
        if on_open is not None:
            on_open(label)
        try:
            dev = opener()
        except DeviceError as exc:
            for d in reversed(opened.values()):
                try:
                    d.close()
                except Exception:  # already failing; the first error is the one to show
                    pass
            raise DeviceError(f"{label}: {exc}") from None
        if dev is not None:
            opened[(arm, what)] = dev
    return opened


def build_real_rig(
    config: HardwareConfig,
    clock: Clock | None = None,
    *,
    with_jaw: bool = True,
    on_open: Callable[[str], None] | None = None,
    control_factory: Callable[[str, float], Any] | None = None,
    tip_in_flange_m: Vec3 | None = None,
    arm_tips_m: Mapping[str, Vec3 | None] | None = None,
) -> RealRig:
    """Open every arm's devices into a :class:`RealRig`.

    Arm by arm (the first first): the force sensor, the robot, the Touch, the jaw; with more than one arm the
    Touch devices share one servo scheduler, started once all are open ("haptic servo scheduler").  Last, for
    every arm with ``robot.mode = "teleop"``, the UR's control interface (once everything else answered), and a
    :class:`pipeline.devices.teleop.TeleopDriver` attached to that arm.

    Parameters
    ----------
    config
        The validated hardware file.
    clock
        The loop's clock.
    with_jaw
        Open each arm's jaw actuator if one is configured.
    on_open
        Called with the device's name ("force sensor", "robot", ...; with more than one arm prefixed
        ``arm 'left': ``) before each is opened (the engine process reports it, so a hang names the device).
    control_factory
        Teleop mode only: replaces ur_rtde's ``RTDEControlInterface``
        constructor (``factory(host, frequency_hz)``); None uses ur_rtde.
    tip_in_flange_m
        The first arm's calibrated tip (a TCP calibration on record): its robot's poses are reported there.
    arm_tips_m
        The calibrated tip per arm name (the first arm's here wins over ``tip_in_flange_m``).

    Raises
    ------
    DeviceError
        One line naming the device that failed (and the arm, with more than one); the devices opened before it
        are closed again.
    """
    clk = clock or MonotonicClock()
    arms = config.arms
    multi = len(arms) > 1
    tips = {arms[0].name: tip_in_flange_m, **(arm_tips_m or {})}
    # refused before anything opens
    tcfgs = {a.name: teleop_config(a if multi else config) for a in arms if a.robot.mode == "teleop"}
    touches = _Touches(arms, clk)
    steps = [(a.name, what, opener) for a in arms
             for what, opener in _arm_steps(a, clk, with_jaw, tips.get(a.name), touches)]
    if touches.shared:
        steps.append(("", f"haptic servo scheduler (arms {', '.join(a.name for a in arms)})", touches.start))
    for a in arms:
        if a.name in tcfgs:
            t_settings, robot = a.teleop, a.robot
            assert t_settings is not None
            steps.append((a.name, "robot control (teleoperation)",
                          _servo_opener(robot, t_settings, clk, control_factory)))
    opened = _open_all(steps, on_open, multi)
    real = []
    for a in arms:
        sensor, robot_dev, haptic = (opened[(a.name, w)] for w in ("force sensor", "robot", "haptic device"))
        servo = opened.get((a.name, "robot control (teleoperation)"))
        driver = None
        if servo is not None:
            from pipeline.devices.teleop import TeleopController, TeleopDriver

            driver = TeleopDriver(TeleopController(tcfgs[a.name]), haptic, robot_dev, servo)
        real.append(RealArm(a.name, sensor, robot_dev, haptic, opened.get((a.name, "jaw actuator")), driver))
    return RealRig(real)
