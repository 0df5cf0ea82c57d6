"""Device interfaces of the rig, defined by their consumer, the haptic loop.

Every device has a real backend (``pipeline.backends``) and a simulated twin
(``pipeline.sim``) that implement the same :class:`typing.Protocol`, so the
loop, the protocol and the GUI never know which one they drive (ophyd-async's
one-interface-many-backends).  All reads are non-blocking "latest value"
reads: a device that talks to hardware does its I/O in its own thread or
servo callback and hands the newest sample over through a single slot.

Timestamps ``t_ns`` are on the loop's clock (:mod:`pipeline.core.clock`).
"""

from __future__ import annotations

import math
from enum import IntFlag
from typing import NamedTuple, Protocol, runtime_checkable

from pipeline.force.frames import Mat3, Vec3

__all__ = [
    "DeviceError",
    "Fault",
    "ForceSensor",
    "HapticDevice",
    "HapticState",
    "JawActuator",
    "PoseSample",
    "Robot",
    "TcpServo",
    "WrenchSample",
]


class Fault(IntFlag):
    """Fault conditions latched by the loop's watchdog (bit flags, stored as an int)."""

    NONE = 0
    SENSOR_STALE = 1  # newest F/T sample older than the sensor age limit (5 ms)
    POSE_STALE = 2  # newest robot pose older than the pose age limit (50 ms)
    NON_FINITE = 4  # a NaN/inf in a wrench or pose
    SENSOR_STATUS = 8  # the Net F/T status word is non-zero
    SENSOR_SATURATION = 16  # a channel above 80 % of its range
    HAPTIC_DEVICE = 32  # the haptic device reported an error (e.g. warm motors)
    OPERATOR_STOP = 64  # the experimenter pressed stop
    ENGINE_DETACHED = 128  # the controlling process went away
    LOOP_STALLED = 256  # the loop thread died or ticked too late (the device's command watchdog zeroed it)
    OTHER_ARM = 512  # another arm of the rig latched a fault, and the rig's fault policy ("both") zeroes this one too

    def describe(self) -> str:
        """Human-readable list of the set flags, e.g. ``"SENSOR_STALE|NON_FINITE"``."""
        if not self:
            return "none"
        return "|".join(f.name or str(int(f)) for f in Fault if f and f in self)


class DeviceError(RuntimeError):
    """A device could not be opened or used; the message says what to check."""


class WrenchSample(NamedTuple):
    """One F/T reading in the sensor frame, in N and N·m.

    ``status`` is the Net F/T status word (0 = healthy); ``rdt_sequence`` and
    ``ft_sequence`` are the RDT counters, so the same health checks run on the
    real sensor and its simulated twin.
    """

    t_ns: int
    fx: float
    fy: float
    fz: float
    tx: float
    ty: float
    tz: float
    status: int = 0
    rdt_sequence: int = 0
    ft_sequence: int = 0


class PoseSample(NamedTuple):
    """Robot tool-centre-point pose: position in the base frame (m) and ``rot_base_tip``."""

    t_ns: int
    position_m: Vec3
    rot_base_tip: Mat3
    controller_time_s: float = 0.0


class HapticState(NamedTuple):
    """Haptic stylus state: position in the device frame (m), buttons bitmask, error code (0 = ok).

    ``force_limit_n`` is the force the device may render now (its peak, lowered by thermal derating;
    infinite if the device does not say) and ``heat_fraction`` its motor heat as a fraction of the
    thermal budget (:mod:`pipeline.devices.touch_output`).
    """

    t_ns: int
    position_m: Vec3
    buttons: int = 0
    error_code: int = 0
    force_limit_n: float = math.inf
    heat_fraction: float = 0.0


@runtime_checkable
class ForceSensor(Protocol):
    """Source of raw 6-axis wrench samples in the sensor frame."""

    def read_wrench(self) -> WrenchSample:
        """Return the newest sample without blocking."""
        ...

    @property
    def range_n(self) -> tuple[float, float, float, float, float, float]:
        """Full-scale range per channel (N, N, N, N·m, N·m, N·m), for the saturation check."""
        ...

    def close(self) -> None:
        """Release the device."""
        ...


@runtime_checkable
class Robot(Protocol):
    """The arm carrying the instrument; read-only from the loop's point of view."""

    def read_pose(self) -> PoseSample:
        """Return the newest TCP pose without blocking (held between controller updates)."""
        ...

    def close(self) -> None:
        """Release the connection."""
        ...


@runtime_checkable
class HapticDevice(Protocol):
    """A force-feedback stylus (3D Systems Touch or its simulated twin)."""

    @property
    def peak_force_n(self) -> float:
        """Peak force the device can render, N (the safety clamp never exceeds it)."""
        ...

    @property
    def continuous_force_n(self) -> float:
        """Force the device sustains indefinitely without overheating, N."""
        ...

    def command_force(self, fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
        """Set the force to render, N, device frame.

        Rendered only while fresh: a command as old as the device's command
        timeout (:data:`pipeline.devices.touch_output.DEFAULT_COMMAND_TIMEOUT_S`, 10 ms)
        renders as zero, in the device's own servo thread, so a loop that dies
        or freezes cannot leave a force on the hand.  ``t_ns`` is when the
        command was computed, on the device's clock (the loop's: the loop passes
        its tick time, so a tick that froze half-way cannot revive an old force);
        None: now.
        """
        ...

    def read_state(self) -> HapticState:
        """Return the newest stylus state without blocking."""
        ...

    def rearm(self) -> bool:
        """Re-enable output after a device error; True if the device accepted."""
        ...

    def close(self) -> None:
        """Zero the force and release the device."""
        ...


@runtime_checkable
class JawActuator(Protocol):
    """The instrument's jaw drive (PQ12-R servo on an Arduino)."""

    def set_position(self, fraction_open: float) -> None:
        """Move the jaw to a fraction of its stroke (0 closed, 1 open), within firmware limits."""
        ...

    def close(self) -> None:
        """Release the device."""
        ...


@runtime_checkable
class TcpServo(Protocol):
    """Streams TCP targets to the arm (app-side teleoperation only, ``robot.mode = "teleop"``).

    The real adapter wraps ``RTDEControlInterface.servoL``/``servoStop`` and
    does its I/O in its own thread; the simulated arm takes the targets into
    its 125 Hz controller.  Both calls return at once.
    """

    def servo_tcp(self, position_m: Vec3, rot_base_tip: Mat3) -> None:
        """Servo toward this TCP pose (base frame, m) from now on."""
        ...

    def stop_servo(self) -> None:
        """Stop servoing and hold the arm where it is (idempotent)."""
        ...

    @property
    def servo_error(self) -> str:
        """Why servoing failed ("" while healthy); teleoperation stops on a non-empty error."""
        ...

    def close(self) -> None:
        """Stop and release the connection."""
        ...
