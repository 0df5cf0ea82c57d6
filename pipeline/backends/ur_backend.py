"""The Universal Robots arms' backend in the device registry: a UR's pose stream and, for teleoperation, its servo.

Every UR model (:mod:`pipeline.devices.registry`: the UR3 on a CB3 controller, the UR3e) is opened the same way,
over RTDE with ur_rtde; what differs is the controller's own rate, which the model gives and
:class:`pipeline.backends.ur.RtdeLink` applies (``frequency_hz = -1``).  The pose stream is
:class:`pipeline.backends.ur.UrRtdeRobot` (read only), run in a process of its own
(:class:`pipeline.backends.ur_process.UrPoseProcess`: ur_rtde holds the interpreter lock while it connects, which
must not stall the loop); the servo, :class:`pipeline.backends.ur_control.UrRtdeServo`, is imported only when
teleoperation takes control of the robot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.backends.ur import RtdeLink
from pipeline.backends.ur_process import UrPoseProcess
from pipeline.core.clock import Clock
from pipeline.devices.interfaces import Robot, TcpServo
from pipeline.devices.registry import RobotConnection, RobotModel, ServoConnection
from pipeline.force.frames import Vec3

__all__ = ["UrBackend"]


class UrBackend:
    """Opens robots of one UR model (:class:`pipeline.devices.registry.RobotBackend`)."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model

    def link(self, settings: RobotConnection, clock: Clock) -> RtdeLink:
        """The RTDE link to the controller ``settings`` describe."""
        return RtdeLink(settings.host, settings.frequency_hz, self.model, clock, settings.connect_timeout_s)

    def open_robot(self, settings: RobotConnection, clock: Clock, tcp_correction_m: Vec3) -> Robot:
        """Connect read-only (the robot runs its own program), from a process of its own; poses at the calibrated
        tip."""
        return UrPoseProcess(self.link(settings, clock), tcp_correction_m=tcp_correction_m)

    def open_servo(self, settings: RobotConnection, servo: ServoConnection, clock: Clock,
                   control_factory: Callable[[str, float], Any] | None) -> TcpServo:
        """Take control of the UR for teleoperation (uploads ur_rtde's control script)."""
        from pipeline.backends.ur_control import UrRtdeServo

        return UrRtdeServo(self.link(settings, clock), control_timeout_s=servo.control_timeout_s,
                           lookahead_s=servo.lookahead_s, gain=servo.gain, control_factory=control_factory)
