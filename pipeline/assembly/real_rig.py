"""The real rig: the devices a :class:`~pipeline.settings.hardware.HardwareConfig` names, opened.

:func:`build_real_rig` opens every arm's devices (Net F/T, the robot, the haptic
device, optional jaw) into a :class:`RealRig`, which satisfies
:class:`pipeline.devices.rig.Rig` and lists its arms (:class:`RealArm`).  The
robot and the haptic device are opened through their models' backends
(:mod:`pipeline.devices.registry`), imported only now: a UR over RTDE, a Touch
through OpenHaptics -- two or more arms' Touch devices by their OpenHaptics names
into one servo scheduler (:class:`pipeline.backends.touch.TouchBackend`), started
once every arm's Touch is open.  If one device fails, the ones already opened
are closed again and the error names the device (and, with more than one arm,
the arm).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, ForceSensor, HapticDevice, JawActuator, Robot, TcpServo
from pipeline.devices.registry import HapticBackend, HapticConnection, haptic_model, robot_model
from pipeline.devices.rig import FirstArmMembers, RigArm, arm_named
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

__all__ = ["HapticOpener", "RealArm", "RealRig", "build_real_rig", "haptic_backends", "open_haptic", "open_jaw",
           "open_robot", "open_sensor", "open_servo", "teleop_config"]


class RealArm:
    """One arm's opened devices: its sensor, robot, haptic device, optional jaw and teleoperation driver."""

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


class RealRig(FirstArmMembers):
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
        self.first: RealArm = self.real_arms[0]
        self.arms: tuple[RigArm, ...] = tuple(a.rig_arm() for a in self.real_arms)

    def arm(self, name: str) -> RealArm:
        """The arm called ``name`` (KeyError naming the arms there are)."""
        return arm_named({a.name: a for a in self.real_arms}, name)

    @property
    def teleop(self) -> Any:
        """The first arm's teleoperation driver."""
        return self.first.teleop

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
        before anything else goes away), then the haptic devices, robots, sensors and jaws; a failing close does
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
    """Connect to the robot ``cfg`` describes, through its model's backend (read only).

    With ``tip_in_flange_m`` (a TCP calibration on record) the poses are moved from the pendant's TCP
    (``robot.tcp_offset_m``) to the calibrated tip.
    """
    corr = (0.0, 0.0, 0.0) if tip_in_flange_m is None else tuple(
        t - o for t, o in zip(tip_in_flange_m, cfg.tcp_offset_m, strict=True))
    return robot_model(cfg.model).backend_for().open_robot(
        cfg, clock, corr)  # type: ignore[arg-type]  # three items: mypy cannot count a generator


def open_servo(
    robot: RobotSettings, teleop: TeleopSettings, clock: Clock,
    control_factory: Callable[[str, float], Any] | None = None
) -> TcpServo:
    """Take control of the robot for teleoperation, through its model's backend (a UR: uploads ur_rtde's script).

    ``control_factory`` replaces the vendor's control interface (a UR's ``RTDEControlInterface``, see
    :class:`pipeline.backends.ur_control.UrRtdeServo`); None uses the vendor's.
    """
    return robot_model(robot.model).backend_for().open_servo(robot, teleop, clock, control_factory)


def teleop_config(config: HardwareConfig | ArmSettings) -> Any:
    """The :class:`pipeline.devices.teleop.TeleopConfig` of a teleop-mode hardware file (its first arm's) or arm.

    Targets go out once per controller cycle: the rate the file asks of the robot, ``-1`` being the robot model's
    own (:meth:`pipeline.devices.registry.RobotModel.rate_hz`).
    """
    from pipeline.devices.teleop import TeleopConfig

    t = config.teleop
    if t is None:
        where = f"arm {config.name!r}: " if isinstance(config, ArmSettings) else ""
        raise HardwareError(f"{config.source}: {where}teleop = None: robot.mode = 'teleop' needs a [teleop] table")
    rate_hz = robot_model(config.robot.model).rate_hz(config.robot.frequency_hz)
    return TeleopConfig(
        workspace_min_m=t.workspace_min_m, workspace_max_m=t.workspace_max_m, max_speed_m_s=t.max_speed_m_s,
        motion_scale=t.motion_scale, period_s=1.0 / rate_hz,
        rot_haptic_base=config.framework.rot_haptic_base, deadman_button=t.deadman_button,
        clutch_button=t.clutch_button,
        stylus_max_age_s=t.stylus_max_age_s, pose_max_age_s=t.pose_max_age_s,
        max_tracking_error_m=t.max_tracking_error_m,
    )


def open_haptic(cfg: HapticSettings, clock: Clock) -> HapticDevice:
    """Open one haptic device alone, through its model's backend (a Touch needs OpenHaptics and the ``touch``
    extra)."""
    backend = haptic_model(cfg.model).backend_for([cfg])
    dev = backend.open(cfg, clock)
    try:
        backend.start()
    except DeviceError:
        dev.close()
        raise
    return dev


def open_jaw(cfg: JawSettings) -> JawActuator:
    """Open the jaw actuator's serial port and wait for READY."""
    from pipeline.backends.jaw import SerialJawActuator

    return SerialJawActuator(cfg.port, baud=cfg.baud, ready_timeout_s=cfg.ready_timeout_s)


#: Opens one arm's haptic device: ``opener(settings, clock)`` (:func:`open_haptic`'s signature).
HapticOpener = Callable[[HapticSettings, Clock], HapticDevice]


class _OpenEach:
    """A haptic backend that opens each arm's device alone with one opener (what :func:`build_real_rig` is given in
    place of the models' backends: the app's stand-in for the Touch on machines without one)."""

    start_step: str | None = None

    def __init__(self, opener: HapticOpener) -> None:
        self.opener = opener

    def open(self, settings: HapticConnection, clock: Clock) -> HapticDevice:
        assert isinstance(settings, HapticSettings)
        return self.opener(settings, clock)

    def start(self) -> None:
        """Nothing to start: each device runs from its opening."""


def haptic_backends(arms: Sequence[ArmSettings], open_haptic: HapticOpener | None = None) -> dict[str, HapticBackend]:
    """The backend of each haptic model the arms name, opening every arm's device of that model; with
    ``open_haptic``, that one opener for every arm instead."""
    if open_haptic is not None:
        each = _OpenEach(open_haptic)
        return {a.haptic.model: each for a in arms}
    by_model: dict[str, list[HapticSettings]] = {}
    for a in arms:
        by_model.setdefault(a.haptic.model, []).append(a.haptic)
    return {key: haptic_model(key).backend_for(settings) for key, settings in by_model.items()}


Step = tuple[str, str, Callable[[], Any]]


def _arm_steps(arm: ArmSettings, clk: Clock, with_jaw: bool, tip: Vec3 | None,
               haptic: HapticBackend) -> list[Step]:
    """What to open for one arm, in order: ``(arm, what, opener)``; the jaw only if configured and wanted."""
    steps: list[Step] = [
        (arm.name, "force sensor", lambda: open_sensor(arm.sensor, clk)),
        (arm.name, "robot", lambda: open_robot(arm.robot, clk, tip)),
        (arm.name, "haptic device", lambda: haptic.open(arm.haptic, clk)),
    ]
    jaw_cfg = arm.jaw
    if with_jaw and jaw_cfg is not None:
        steps.append((arm.name, "jaw actuator", lambda: open_jaw(jaw_cfg)))
    return steps


def _start_steps(arms: Sequence[ArmSettings], backends: Mapping[str, HapticBackend]) -> list[Step]:
    """Each haptic backend that starts its devices together once all are open: ``("", what (arms …), start)``."""
    steps: list[Step] = []
    for key, backend in backends.items():
        if backend.start_step is not None:
            names = ", ".join(a.name for a in arms if a.haptic.model == key)
            steps.append(("", f"{backend.start_step} (arms {names})", backend.start))
    return steps


def _servo_steps(arms: Sequence[ArmSettings], clk: Clock,
                 factory: Callable[[str, float], Any] | None) -> list[Step]:
    """Every teleoperated arm's robot control, last: once everything else answered."""
    steps: list[Step] = []
    for a in arms:
        if a.robot.mode == "teleop":
            robot, t_settings = a.robot, a.teleop
            assert t_settings is not None
            steps.append((a.name, "robot control (teleoperation)", _servo_opener(robot, t_settings, clk, factory)))
    return steps


def _servo_opener(robot: RobotSettings, teleop: TeleopSettings, clk: Clock,
                  factory: Callable[[str, float], Any] | None) -> Callable[[], Any]:
    return lambda: open_servo(robot, teleop, clk, factory)


def _open_all(steps: list[Step], on_open: Callable[[str], None] | None, multi: bool) -> dict[tuple[str, str], Any]:
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


def _real_arm(a: ArmSettings, opened: Mapping[tuple[str, str], Any], teleop: Any) -> RealArm:
    """Arm ``a``'s opened devices as a :class:`RealArm`, with a teleoperation driver when its servo was opened."""
    sensor, robot, haptic = (opened[(a.name, w)] for w in ("force sensor", "robot", "haptic device"))
    servo = opened.get((a.name, "robot control (teleoperation)"))
    driver = None
    if servo is not None:
        from pipeline.devices.teleop import TeleopController, TeleopDriver

        driver = TeleopDriver(TeleopController(teleop), haptic, robot, servo)
    return RealArm(a.name, sensor, robot, haptic, opened.get((a.name, "jaw actuator")), driver)


def build_real_rig(
    config: HardwareConfig,
    clock: Clock | None = None,
    *,
    with_jaw: bool = True,
    on_open: Callable[[str], None] | None = None,
    control_factory: Callable[[str, float], Any] | None = None,
    tip_in_flange_m: Vec3 | None = None,
    arm_tips_m: Mapping[str, Vec3 | None] | None = None,
    open_haptic: HapticOpener | None = None,
) -> RealRig:
    """Open every arm's devices into a :class:`RealRig`.

    Arm by arm (the first first): the force sensor, the robot, the haptic device, the jaw -- the robot and the haptic
    device through their models' backends (:mod:`pipeline.devices.registry`).  A haptic backend that serves several
    arms' devices from one servo scheduler (the Touch's) starts it once all are open ("haptic servo scheduler").
    Last, for every arm with ``robot.mode = "teleop"``, the robot's control interface (once everything else
    answered), and a :class:`pipeline.devices.teleop.TeleopDriver` attached to that arm.

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
    open_haptic
        Opens every arm's haptic device alone, in place of the models' backends (``opener(settings, clock)``;
        the app's ``HostConfig.haptic_factory``); None: the backends.

    Raises
    ------
    DeviceError
        One line naming the device that failed (and the arm, with more than one); the devices opened before it
        are closed again.
    """
    clk = clock or MonotonicClock()
    arms = config.arms
    tips = {arms[0].name: tip_in_flange_m, **(arm_tips_m or {})}
    # refused before anything opens
    tcfgs = {a.name: teleop_config(a if len(arms) > 1 else config) for a in arms if a.robot.mode == "teleop"}
    backends = haptic_backends(arms, open_haptic)
    steps = [step for a in arms for step in _arm_steps(a, clk, with_jaw, tips.get(a.name), backends[a.haptic.model])]
    steps += _start_steps(arms, backends) + _servo_steps(arms, clk, control_factory)
    opened = _open_all(steps, on_open, len(arms) > 1)
    return RealRig([_real_arm(a, opened, tcfgs.get(a.name)) for a in arms])
