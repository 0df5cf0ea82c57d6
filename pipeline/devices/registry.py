"""The device models: every haptic device and robot a rig may use, each registered here once.

A model is one registration (:func:`register_haptic`, :func:`register_robot`): the key a hardware file names it by
(``[haptic] model``, ``[robot] model``), its limits -- each with its source -- and how to open it: its real backend
and its simulated twin.  A new device is its backend module (``pipeline/backends/``), its twin (``pipeline/sim/``,
or an existing twin given its limits) and one registration at the end of this module.

Who asks the registry what:

* the hardware settings (:mod:`pipeline.settings.hardware`) check a file against its models' limits:
  ``framework.f_max_n`` is capped by the haptic device's peak force, ``haptic.command_timeout_s`` must outlast two
  of its servo ticks, and a robot's automatic rate (``robot.frequency_hz = -1``) is its controller's own
  (:meth:`RobotModel.rate_hz`, the one meaning of ``-1``);
* the real rig (:mod:`pipeline.assembly.real_rig`) opens every arm's devices through their models' backends;
* the simulated rig (:mod:`pipeline.sim.rig`) builds its devices' twins from their models.

Backends and twins are named ``"module:attribute"`` and imported only when a rig opens one (:func:`load`):
importing the registry imports none of them, so a real rig's process imports the backends of the models its file
names and no other (each backend imports its vendor SDK only when a device is opened), and the simulated rig's
process imports no backend at all.  A model registered by a test or a lab's own module may give the object itself.
"""

from __future__ import annotations

import importlib
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pipeline.core.clock import Clock
from pipeline.devices.interfaces import HapticDevice, Robot, TcpServo
from pipeline.devices.touch_output import HapticLimits
from pipeline.force.frames import Mat3, Vec3

__all__ = [
    "DEFAULT_HAPTIC_MODEL",
    "DEFAULT_ROBOT_MODEL",
    "HapticBackend",
    "HapticConnection",
    "HapticModel",
    "Loadable",
    "RobotBackend",
    "RobotConnection",
    "RobotModel",
    "ServoConnection",
    "haptic_model",
    "haptic_models",
    "load",
    "register_haptic",
    "register_robot",
    "robot_model",
    "robot_models",
    "unregister_haptic",
    "unregister_robot",
]

#: A backend or twin: ``"module:attribute"`` (imported when first used) or the object itself.
Loadable = str | Callable[..., Any]
#: What a model's key may be (it is written in hardware files and stored with sessions).
_KEY = re.compile(r"[a-z][a-z0-9_-]{0,31}\Z")


def load(ref: Loadable) -> Any:
    """The object ``ref`` names: ``"module:attribute"`` imported now, or ``ref`` itself."""
    if not isinstance(ref, str):
        return ref
    module, _, attribute = ref.partition(":")
    return getattr(importlib.import_module(module), attribute)


# -- what a backend reads of the settings, and what it gives ---------------------------------------------------------
class HapticConnection(Protocol):
    """What a haptic backend reads of an arm's ``[haptic]`` table (``pipeline.settings.hardware.HapticSettings``)."""

    @property
    def device_name(self) -> str:
        """The device's name in its vendor's set-up (OpenHaptics' Touch Setup for a Touch)."""
        ...

    @property
    def command_timeout_s(self) -> float:
        """A command this old renders as zero, in the device's own servo thread."""
        ...

    @property
    def dll_dir(self) -> str | None:
        """The folder of the vendor's library on Windows (None: the system's folders)."""
        ...


class HapticBackend(Protocol):
    """Opens the devices of one haptic model, every arm's, and starts them once all are open.

    ``start_step`` names the opening step that starts them (a servo scheduler the devices share, reported as a
    device's opening is), or is None when each device runs from its :meth:`open`.
    """

    start_step: str | None

    def open(self, settings: HapticConnection, clock: Clock) -> HapticDevice:
        """Open one arm's device (:class:`pipeline.devices.interfaces.DeviceError` naming what to check)."""
        ...

    def start(self) -> None:
        """Every device is open: start serving them (nothing when ``start_step`` is None)."""
        ...


class RobotConnection(Protocol):
    """What a robot backend reads of an arm's ``[robot]`` table (:class:`pipeline.settings.hardware.RobotSettings`)."""

    @property
    def host(self) -> str:
        """The controller's address."""
        ...

    @property
    def frequency_hz(self) -> float:
        """The rate asked of the controller, Hz (-1: its own, :meth:`RobotModel.rate_hz`)."""
        ...

    @property
    def connect_timeout_s(self) -> float:
        """Bound of connecting, s."""
        ...

    @property
    def tcp_offset_m(self) -> Vec3:
        """The TCP set on the pendant, flange frame, m."""
        ...


class ServoConnection(Protocol):
    """What a robot backend reads of an arm's ``[teleop]`` table to take control of the robot."""

    @property
    def control_timeout_s(self) -> float:
        """Bound of taking control, s."""
        ...

    @property
    def lookahead_s(self) -> float:
        """The servo's look-ahead time, s."""
        ...

    @property
    def gain(self) -> float:
        """The servo's proportional gain."""
        ...


class RobotBackend(Protocol):
    """Opens a robot of one model: its pose stream, and (teleoperation only) its TCP servo."""

    def open_robot(self, settings: RobotConnection, clock: Clock, tcp_correction_m: Vec3) -> Robot:
        """Connect read-only; poses are moved by ``tcp_correction_m`` (TCP frame, m) to the calibrated tip."""
        ...

    def open_servo(self, settings: RobotConnection, servo: ServoConnection, clock: Clock,
                   control_factory: Callable[[str, float], Any] | None) -> TcpServo:
        """Take control of the robot for teleoperation (``control_factory`` replaces the vendor's interface)."""
        ...


# -- the models ------------------------------------------------------------------------------------------------------
def _check_key(kind: str, key: str, name: str, source: str) -> None:
    if not isinstance(key, str) or not _KEY.match(key):
        raise ValueError(f"{kind} model key {key!r}: a lower-case name of letters, digits, '_' and '-'")
    for what, text in (("name", name), ("source", source)):
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"{kind} model {key!r}: its {what} must be given (where its limits come from)")


@dataclass(frozen=True, slots=True)
class HapticModel:
    """A haptic device model: its limits, and how to open its backend and its twin.

    Attributes
    ----------
    key
        What ``[haptic] model`` names it by.
    name
        What people call it (in messages).
    limits
        Peak and continuous force and the motors' thermal budget (:class:`HapticLimits`).
    servo_rate_hz
        How often the device's own servo loop renders a force, Hz.
    backend
        ``backend(model, settings)`` -- the settings of every arm with this model -- makes the
        :class:`HapticBackend` that opens them.
    twin
        ``twin(limits, command_timeout_s)`` makes the simulated device (:class:`pipeline.sim.touch.SimTouch`'s
        interface: the simulated rig steps it, sets its stylus and reads what it renders).
    source
        Where the limits come from (a datasheet, a manual), for the reader and the refusals.
    """

    key: str
    name: str
    limits: HapticLimits
    servo_rate_hz: float
    backend: Loadable
    twin: Loadable
    source: str

    def __post_init__(self) -> None:
        _check_key("haptic", self.key, self.name, self.source)
        if not (math.isfinite(self.servo_rate_hz) and self.servo_rate_hz > 0):
            raise ValueError(f"haptic model {self.key!r}: servo_rate_hz = {self.servo_rate_hz!r}: must be > 0")

    @property
    def peak_force_n(self) -> float:
        """The largest force the device renders, N: what caps ``f_max``."""
        return self.limits.peak_force_n

    @property
    def min_command_timeout_s(self) -> float:
        """The shortest command timeout: two servo periods (one late servo tick must not drop a fresh command)."""
        return 2.0 / self.servo_rate_hz

    def backend_for(self, settings: Sequence[HapticConnection]) -> HapticBackend:
        """The backend that opens the devices of ``settings`` (every arm's of this model); imported now."""
        backend: HapticBackend = load(self.backend)(self, settings)
        return backend

    def open_twin(self, command_timeout_s: float, limits: HapticLimits | None = None) -> Any:
        """The simulated device, with the model's limits (or ``limits``, a rehearsal's hotter motors)."""
        return load(self.twin)(limits or self.limits, command_timeout_s)


@dataclass(frozen=True, slots=True)
class RobotModel:
    """A robot model: its control rate, and how to open its backend and its twin.

    Attributes
    ----------
    key
        What ``[robot] model`` names it by.
    name
        What people call it (in messages).
    control_rate_hz
        The controller's own cycle, Hz: the rate it publishes at when left to choose (``frequency_hz = -1``),
        and the cycle of its simulated twin.
    backend
        ``backend(model)`` makes the :class:`RobotBackend`.
    twin
        ``twin(home_m, rot_base_tip, params)`` makes the simulated arm (:class:`pipeline.sim.robot.SimRobot`),
        ``params`` holding the model's control rate.
    source
        Where the rate comes from.
    """

    key: str
    name: str
    control_rate_hz: float
    backend: Loadable
    twin: Loadable
    source: str

    def __post_init__(self) -> None:
        _check_key("robot", self.key, self.name, self.source)
        if not (math.isfinite(self.control_rate_hz) and self.control_rate_hz > 0):
            raise ValueError(f"robot model {self.key!r}: control_rate_hz = {self.control_rate_hz!r}: must be > 0")

    def rate_hz(self, frequency_hz: float) -> float:
        """The rate ``frequency_hz`` means on this robot: -1 (automatic) is the controller's own rate."""
        return self.control_rate_hz if frequency_hz == -1 else float(frequency_hz)

    def backend_for(self) -> RobotBackend:
        """The backend that opens robots of this model; imported now."""
        backend: RobotBackend = load(self.backend)(self)
        return backend

    def open_twin(self, home_m: Vec3, rot_base_tip: Mat3, params: Any) -> Any:
        """The simulated arm at ``home_m``, tool at ``rot_base_tip``, timed by ``params`` (its control rate)."""
        return load(self.twin)(home_m, rot_base_tip, params)


# -- the registry ----------------------------------------------------------------------------------------------------
_HAPTIC: dict[str, HapticModel] = {}
_ROBOT: dict[str, RobotModel] = {}


def register_haptic(model: HapticModel) -> HapticModel:
    """Make ``model`` one a hardware file (and the simulated rig) may name; a key is registered once."""
    if model.key in _HAPTIC:
        raise ValueError(f"haptic model {model.key!r} is registered already ({_HAPTIC[model.key].name})")
    _HAPTIC[model.key] = model
    return model


def register_robot(model: RobotModel) -> RobotModel:
    """Make ``model`` one a hardware file (and the simulated rig) may name; a key is registered once."""
    if model.key in _ROBOT:
        raise ValueError(f"robot model {model.key!r} is registered already ({_ROBOT[model.key].name})")
    _ROBOT[model.key] = model
    return model


def unregister_haptic(key: str) -> None:
    """Forget a haptic model (a test's own, once the test is done)."""
    del _HAPTIC[key]


def unregister_robot(key: str) -> None:
    """Forget a robot model (a test's own, once the test is done)."""
    del _ROBOT[key]


def haptic_models() -> tuple[str, ...]:
    """The keys of the haptic models, in the order they were registered."""
    return tuple(_HAPTIC)


def robot_models() -> tuple[str, ...]:
    """The keys of the robot models, in the order they were registered."""
    return tuple(_ROBOT)


def haptic_model(key: str) -> HapticModel:
    """The haptic model ``key`` (:class:`KeyError` naming the models there are)."""
    try:
        return _HAPTIC[key]
    except KeyError:
        raise KeyError(f"no haptic model {key!r}; the models: {', '.join(_HAPTIC)}") from None


def robot_model(key: str) -> RobotModel:
    """The robot model ``key`` (:class:`KeyError` naming the models there are)."""
    try:
        return _ROBOT[key]
    except KeyError:
        raise KeyError(f"no robot model {key!r}; the models: {', '.join(_ROBOT)}") from None


# -- the rig's devices -----------------------------------------------------------------------------------------------
#: The paper's haptic device, and the model of a hardware file that names none.
DEFAULT_HAPTIC_MODEL = register_haptic(HapticModel(
    key="touch",
    name="3D Systems Touch",
    limits=HapticLimits(
        # 3D Systems, Touch haptic device specifications: "maximum exertable force at nominal (orthogonal arms)
        # position 3.3 N", "continuous exertable force (24 hrs) > 0.88 N"; OpenHaptics reports the same as
        # HD_NOMINAL_MAX_FORCE and HD_NOMINAL_MAX_CONTINUOUS_FORCE (the backend uses what the device reports)
        peak_force_n=3.3,
        continuous_force_n=0.88,
        # not a datasheet value: the heat the motors may take above the continuous rating before derating ends in
        # HD_WARM_MOTORS, chosen so that 1.5 N lasts ~35 s (science.md §5, "an I²t or time-above-continuous budget")
        thermal_budget_n2s=60.0,
    ),
    # OpenHaptics Programmer's Guide: the HDAPI servo loop runs at 1 kHz
    servo_rate_hz=1000.0,
    backend="pipeline.backends.touch:TouchBackend",
    twin="pipeline.sim.touch:SimTouch",
    source="3D Systems Touch specifications; OpenHaptics Programmer's Guide (servo loop)",
)).key

#: The paper's robot, and the model of a hardware file that names none.
DEFAULT_ROBOT_MODEL = register_robot(RobotModel(
    key="ur3",
    name="UR3 (CB3)",
    # Universal Robots, RTDE guide: a CB3 controller runs and publishes at 125 Hz; ur_rtde's frequency -1 asks
    # for 125 Hz of a controller of major version 3 (RTDEReceiveInterface)
    control_rate_hz=125.0,
    backend="pipeline.backends.ur_backend:UrBackend",
    twin="pipeline.sim.robot:SimRobot",
    source="Universal Robots RTDE guide (CB3: 125 Hz); ur_rtde RTDEReceiveInterface",
)).key

register_robot(RobotModel(
    key="ur3e",
    name="UR3e (e-Series)",
    # Universal Robots, RTDE guide and e-Series specifications: the controller runs and publishes at 500 Hz;
    # ur_rtde's frequency -1 asks for 500 Hz of a controller of major version 5
    control_rate_hz=500.0,
    backend="pipeline.backends.ur_backend:UrBackend",
    twin="pipeline.sim.robot:SimRobot",
    source="Universal Robots RTDE guide and e-Series specifications (500 Hz); ur_rtde RTDEReceiveInterface",
))
