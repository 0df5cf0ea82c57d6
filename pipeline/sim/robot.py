"""Simulated UR3 (CB3) following the haptic stylus in position mode (science.md §3 item 4).

The controller runs at 125 Hz: every 8 ms it samples the commanded TCP
position (a zero-order hold) and publishes the actual pose, which is what
RTDE would return until the next cycle.  The tool itself tracks the held
target with a first-order lag (τ ≈ 20–50 ms), integrated exactly at the
loop rate -- the "lagging robot" of the simulated rig, nothing more.
Orientation changes (calibration poses) are applied at the next controller
cycle.

It is also the simulated twin of the teleoperation servo adapter
(:class:`pipeline.devices.interfaces.TcpServo`): ``servo_tcp`` sets the target like
``servoL``, and ``stop_servo`` -- like ``servoStop`` -- makes the controller
hold the tool where it is at its next cycle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.devices.interfaces import PoseSample
from pipeline.force.frames import Mat3, Vec3

__all__ = ["TOOL_DOWN", "RobotParams", "SimRobot"]

#: Tool pointing straight down: tip z axis along base −z (rotation π about base x).
TOOL_DOWN: Mat3 = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)


@dataclass(frozen=True, slots=True)
class RobotParams:
    """Timing of the simulated arm.

    ``controller_rate_hz`` is the controller's cycle: the simulated rig takes its robot model's
    (:mod:`pipeline.devices.registry`: 125 Hz on the UR3's CB3, 500 Hz on an e-Series; the default here is the
    UR3's, for an arm built on its own).  ``tracking_lag_s`` is the first-order lag of the tool behind its target
    (science.md §3: τ ≈ 20–50 ms observed for the teleoperated UR3; 30 ms).
    """

    controller_rate_hz: float = 125.0
    tracking_lag_s: float = 0.03

    def __post_init__(self) -> None:
        for name in ("controller_rate_hz", "tracking_lag_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"robot.{name} = {v!r}: must be a finite number > 0")


class SimRobot:
    """A ``Robot`` with a settable target; the rig advances it each tick.

    ``frozen = True`` stops pose publication (a dead RTDE link) for watchdog tests.
    """

    def __init__(self, home_m: Vec3, orientation: Mat3 = TOOL_DOWN, params: RobotParams | None = None) -> None:
        self.params = params or RobotParams()
        self._cycle_ns = int(round(1e9 / self.params.controller_rate_hz))
        self.position_m: list[float] = list(home_m)
        self.orientation: Mat3 = orientation
        self._target: Vec3 = tuple(home_m)  # type: ignore[assignment]  # a Vec3: mypy cannot count tuple()
        self._held_target: Vec3 = self._target
        self._pending_orientation: Mat3 = orientation
        self._next_cycle_ns: int | None = None
        self._pose = PoseSample(0, tuple(home_m), orientation, 0.0)  # type: ignore[arg-type]  # as above
        self.frozen = False
        self._stop_requested = False
        #: True between a ``servo_tcp`` and the controller cycle that carries out a ``stop_servo``.
        self.servoing = False
        self.servo_commands = 0
        self.servo_stops = 0
        #: Set to make the adapter report an error (a protective stop), for tests.
        self.fail_servo = ""
        self._lag_dt_s = -1.0  # the dt the lag factor was computed for (the tick period, nearly always the same)
        self._lag_a = 0.0

    def command(self, target_m: Vec3) -> None:
        """Set the TCP position the teleoperation program asks for (base frame, m)."""
        self._target = target_m

    # -- TcpServo -----------------------------------------------------------------------------
    def servo_tcp(self, position_m: Vec3, rot_base_tip: Mat3) -> None:
        """Servo toward ``position_m`` (base frame, m) at ``rot_base_tip`` from the next controller cycle."""
        self._stop_requested = False
        self.servoing = True
        self.servo_commands += 1
        self._target = position_m
        if rot_base_tip != self._pending_orientation:
            self._pending_orientation = rot_base_tip

    def stop_servo(self) -> None:
        """Hold the tool where it is at the next controller cycle (idempotent)."""
        if self.servoing and not self._stop_requested:
            self._stop_requested = True
            self.servo_stops += 1

    @property
    def servo_error(self) -> str:
        """"" unless a test injected a failure through :attr:`fail_servo`."""
        return self.fail_servo

    def set_orientation(self, rot_base_tip: Mat3) -> None:
        """Re-orient the tool (taken at the next controller cycle)."""
        self._pending_orientation = rot_base_tip

    def advance(self, now_ns: int, dt_s: float) -> None:
        """Run the controller cycle if due and integrate the tracking lag over ``dt_s``."""
        if self._next_cycle_ns is None:
            self._next_cycle_ns = now_ns
        if now_ns >= self._next_cycle_ns:
            if self._stop_requested:
                # servoStop: the controller holds the tool where it is now
                self._target = (self.position_m[0], self.position_m[1], self.position_m[2])
                self._stop_requested = False
                self.servoing = False
            self._held_target = self._target
            self.orientation = self._pending_orientation
            if not self.frozen:
                self._pose = PoseSample(
                    now_ns, (self.position_m[0], self.position_m[1], self.position_m[2]),
                    self.orientation, now_ns * 1e-9,
                )
            while self._next_cycle_ns <= now_ns:
                self._next_cycle_ns += self._cycle_ns
        if dt_s > 0:
            if dt_s != self._lag_dt_s:
                self._lag_dt_s = dt_s
                self._lag_a = 1.0 - math.exp(-dt_s / self.params.tracking_lag_s)
            a = self._lag_a
            p, t = self.position_m, self._held_target
            p[0] += (t[0] - p[0]) * a
            p[1] += (t[1] - p[1]) * a
            p[2] += (t[2] - p[2]) * a

    def teleport(self, position_m: Vec3) -> None:
        """Place the tool at ``position_m`` at rest (set-up and calibration, not teleoperation)."""
        self.position_m = list(position_m)
        self._target = self._held_target = tuple(position_m)  # type: ignore[assignment]  # a Vec3: mypy cannot count tuple()

    def read_pose(self) -> PoseSample:
        """The pose published at the last controller cycle."""
        return self._pose

    def close(self) -> None:
        """Nothing to release (also the :class:`TcpServo` close)."""
