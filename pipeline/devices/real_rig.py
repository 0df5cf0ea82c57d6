"""The real rig: the devices a :class:`~pipeline.settings.hardware.HardwareConfig` names, opened.

:func:`build_real_rig` opens the devices (Net F/T, UR over RTDE, Touch,
optional jaw) into a :class:`RealRig`, which satisfies :class:`pipeline.devices.rig.Rig`.
If one device fails, the ones already opened are closed again and the error
names the device.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.devices.interfaces import DeviceError, ForceSensor, HapticDevice, JawActuator, Robot
from pipeline.force.frames import Vec3
from pipeline.runtime.clock import Clock, MonotonicClock
from pipeline.settings.hardware import (
    HapticSettings,
    HardwareConfig,
    HardwareError,
    JawSettings,
    RobotSettings,
    SensorSettings,
    TeleopSettings,
)

__all__ = ["RealRig", "build_real_rig", "open_haptic", "open_jaw", "open_robot", "open_sensor", "open_servo",
           "teleop_config"]


class RealRig:
    """The devices of the real rig, satisfying :class:`pipeline.devices.rig.Rig`."""

    def __init__(
        self, sensor: ForceSensor, robot: Robot, haptic: HapticDevice, jaw: JawActuator | None = None,
        teleop: Any = None
    ) -> None:
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
        """The devices run on their own; with teleoperation, one call of the controller (no I/O: the adapter's thread
        sends).

        The stylus buttons go to the jaw's controller (no I/O either: it queues).
        """
        if self.teleop is not None:
            self.teleop.update(now_ns)
        hook = self.on_buttons
        if hook is not None:
            hook(now_ns, self.haptic.read_state().buttons)

    def true_contact_force(self) -> None:
        """No ground truth on hardware."""
        return None

    def on_faults(self, faults: int) -> None:
        """The loop's latched faults changed: with teleoperation, any fault stops the robot
        (``pipeline.devices.rig.Rig``).

        In ``"observe"`` mode the robot runs its own program and is not ours to stop.
        """
        if self.teleop is not None:
            self.teleop.on_faults(faults)

    def stop_motion(self, reason: str) -> None:
        """The loop is stopping: with teleoperation, stop the robot."""
        if self.teleop is not None:
            self.teleop.stop_motion(reason)

    def close(self) -> None:
        """Zero and release every device (the Touch first); a failing close does not skip the others."""
        errors = []
        # teleoperation first: the robot stops before anything else goes away
        for dev in (self.teleop, self.haptic, self.robot, self.sensor, self.jaw):
            if dev is None:
                continue
            try:
                dev.close()
            except Exception as exc:  # close everything, report after
                errors.append(f"{type(dev).__name__}: {exc}")
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


def teleop_config(config: HardwareConfig) -> Any:
    """The :class:`pipeline.devices.teleop.TeleopConfig` of a teleop-mode hardware file."""
    from pipeline.devices.teleop import TeleopConfig

    t = config.teleop
    if t is None:
        raise HardwareError(f"{config.source}: teleop = None: robot.mode = 'teleop' needs a [teleop] table")
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


def open_jaw(cfg: JawSettings) -> JawActuator:
    """Open the jaw actuator's serial port and wait for READY."""
    from pipeline.backends.jaw import SerialJawActuator

    return SerialJawActuator(cfg.port, baud=cfg.baud, ready_timeout_s=cfg.ready_timeout_s)


def _one_arm(config: HardwareConfig) -> None:
    """Refuse a file with more than one arm: this version does not open a second arm's real devices (two Touch
    devices in one OpenHaptics servo scheduler), and a rig that silently ran one of two configured arms would not be
    the rig on record."""
    if len(config.arms) > 1:
        names = ", ".join(a.name for a in config.arms)
        raise DeviceError(f"{config.source}: {len(config.arms)} arms ({names}): this version opens the real devices "
                          "of one arm only (two Touch devices in one servo scheduler are not built yet); give one "
                          "[[arm]] table, or run the two-arm simulated rig")


def build_real_rig(
    config: HardwareConfig,
    clock: Clock | None = None,
    *,
    with_jaw: bool = True,
    on_open: Callable[[str], None] | None = None,
    control_factory: Callable[[str, float], Any] | None = None,
    tip_in_flange_m: Vec3 | None = None,
) -> RealRig:
    """Open every configured device into a :class:`RealRig`.

    With ``robot.mode = "teleop"`` the UR's control interface is opened too
    (last, once everything else answered) and a
    :class:`pipeline.devices.teleop.TeleopDriver` is attached to the rig.

    Parameters
    ----------
    config
        The validated hardware file.
    clock
        The loop's clock.
    with_jaw
        Open the jaw actuator if one is configured.
    on_open
        Called with the device's name ("force sensor", "robot", ...) before each is opened
        (the engine process reports it, so a hang names the device).
    control_factory
        Teleop mode only: replaces ur_rtde's ``RTDEControlInterface``
        constructor (``factory(host, frequency_hz)``); None uses ur_rtde.
    tip_in_flange_m
        The calibrated tip (a TCP calibration on record): the robot's poses are reported there.

    Raises
    ------
    DeviceError
        Naming the device that failed; the devices opened before it are closed again.  A file with more than
        one arm is refused before any device is opened (:func:`_one_arm`).
    """
    _one_arm(config)
    clk = clock or MonotonicClock()
    opened: list[Any] = []
    steps: list[tuple[str, Any]] = [
        ("force sensor", lambda: open_sensor(config.sensor, clk)),
        ("robot", lambda: open_robot(config.robot, clk, tip_in_flange_m)),
        ("haptic device", lambda: open_haptic(config.haptic, clk)),
    ]
    if with_jaw and config.jaw is not None:
        jaw_cfg = config.jaw
        steps.append(("jaw actuator", lambda: open_jaw(jaw_cfg)))
    teleop = config.robot.mode == "teleop"
    if teleop:
        tcfg = teleop_config(config)
        t_settings = config.teleop
        assert t_settings is not None
        steps.append(("robot control (teleoperation)",
                      lambda: open_servo(config.robot, t_settings, clk, control_factory)))
    for what, opener in steps:
        if on_open is not None:
            on_open(what)
        try:
            opened.append(opener())
        except DeviceError as exc:
            for dev in reversed(opened):
                try:
                    dev.close()
                except Exception:  # already failing; the first error is the one to show
                    pass
            raise DeviceError(f"{what}: {exc}") from None
    servo = opened.pop() if teleop else None
    jaw = opened[3] if len(opened) > 3 else None
    driver = None
    if servo is not None:
        from pipeline.devices.teleop import TeleopController, TeleopDriver

        driver = TeleopDriver(TeleopController(tcfg), opened[2], opened[1], servo)
    return RealRig(opened[0], opened[1], opened[2], jaw, driver)
