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

import numpy as np

from pipeline.core.compiled import KernelState, State, kernel
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


# The arm's state, a float64 array (its kernel's layout): the tool's position, the target asked for, the target the
# controller holds, the next controller cycle (ns since the first step; NaN before it), the cycle (ns), the dt the lag
# factor was computed for and that factor, the lag's time constant, and the position published at the last cycle.
_POS, _TARGET, _HELD, _NEXT, _CYCLE, _LAG_DT, _LAG_A, _TAU, _POSE = 0, 3, 6, 9, 10, 11, 12, 13, 14
STATE_SIZE = 17
#: Where the state holds the position published at the last cycle.
POSE_AT = _POSE


@kernel
def advance_kernel(st: State, t_ns: int, dt_s: float) -> bool:
    """The controller cycle if one is due at ``t_ns`` (ns since the first step: :meth:`SimRobot.since_first_ns`; the
    held target, the published position), then the tracking lag over ``dt_s``; True if a cycle ran."""
    if st[_NEXT] != st[_NEXT]:  # (NaN: the first step)
        st[_NEXT] = t_ns
    cycled = False
    if t_ns >= st[_NEXT]:
        cycled = True
        for i in range(3):
            st[_HELD + i] = st[_TARGET + i]
            st[_POSE + i] = st[_POS + i]
        while st[_NEXT] <= t_ns:
            st[_NEXT] += st[_CYCLE]
    if dt_s > 0:
        if dt_s != st[_LAG_DT]:
            st[_LAG_DT] = dt_s
            st[_LAG_A] = 1.0 - math.exp(-dt_s / st[_TAU])
        a = st[_LAG_A]
        for i in range(3):
            st[_POS + i] += (st[_HELD + i] - st[_POS + i]) * a
    return cycled


@kernel
def command_kernel(st: State, x_m: float, y_m: float, z_m: float) -> None:
    """Set the TCP position the teleoperation program asks for (base frame, m)."""
    st[_TARGET] = x_m
    st[_TARGET + 1] = y_m
    st[_TARGET + 2] = z_m


class SimRobot(KernelState):
    """A ``Robot`` with a settable target; the rig advances it each tick.

    ``frozen = True`` stops pose publication (a dead RTDE link) for watchdog tests.  The motion is
    :func:`advance_kernel`'s, compiled, over the state array :attr:`array` (the rig's compiled step runs the same
    kernel on the same array); the controller's cycle in Python (:meth:`cycled`) only re-orients and publishes.
    """

    def __init__(self, home_m: Vec3, orientation: Mat3 = TOOL_DOWN, params: RobotParams | None = None) -> None:
        self._params = params or RobotParams()
        #: The clock reading of the first step: the state counts time from it (None before it).
        self.origin_ns: int | None = None
        #: The state :func:`advance_kernel` works on (the rig may move it into
        #: its own array: :meth:`~pipeline.core.compiled.KernelState.adopt`).
        self.array = st = np.zeros(STATE_SIZE)
        st[_POS:_POS + 3] = st[_TARGET:_TARGET + 3] = st[_HELD:_HELD + 3] = home_m
        st[_NEXT], st[_CYCLE] = math.nan, int(round(1e9 / self._params.controller_rate_hz))
        st[_LAG_DT], st[_TAU] = -1.0, self._params.tracking_lag_s  # (the dt the lag factor is for: none yet)
        self.orientation: Mat3 = orientation
        self._pending_orientation: Mat3 = orientation
        self._pose = PoseSample(0, tuple(home_m), orientation, 0.0)  # type: ignore[arg-type]  # a Vec3: mypy cannot count tuple()
        self.frozen = False
        self._stop_requested = False
        #: True between a ``servo_tcp`` and the controller cycle that carries out a ``stop_servo``.
        self.servoing = False
        self.servo_commands = 0
        self.servo_stops = 0
        #: Set to make the adapter report an error (a protective stop), for tests.
        self.fail_servo = ""

    @property
    def params(self) -> RobotParams:
        """The arm's timing (read-only: it is in :attr:`array`)."""
        return self._params

    @property
    def position_m(self) -> list[float]:
        """The tool's position now (base frame, m; a copy)."""
        return self.array[_POS:_POS + 3].tolist()  # type: ignore[no-any-return]  # a float64 array's list: floats

    @property
    def moves_smoothly(self) -> bool:
        """Nothing for the Python side to do at the next controller cycle but publish: no re-orientation, no stop
        (the rig's compiled step may run the arm)."""
        return self._pending_orientation is self.orientation and not self._stop_requested

    def command(self, target_m: Vec3) -> None:
        """Set the TCP position the teleoperation program asks for (base frame, m)."""
        self.array[_TARGET:_TARGET + 3] = target_m

    # -- TcpServo -----------------------------------------------------------------------------
    def servo_tcp(self, position_m: Vec3, rot_base_tip: Mat3) -> None:
        """Servo toward ``position_m`` (base frame, m) at ``rot_base_tip`` from the next controller cycle."""
        self._stop_requested = False
        self.servoing = True
        self.servo_commands += 1
        self.array[_TARGET:_TARGET + 3] = position_m
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

    def since_first_ns(self, now_ns: int) -> int:
        """``now_ns`` as the state counts it: ns since the first step (the first call's reading)."""
        if self.origin_ns is None:
            self.origin_ns = now_ns
        return now_ns - self.origin_ns

    def advance(self, now_ns: int, dt_s: float) -> None:
        """Run the controller cycle if due and integrate the tracking lag over ``dt_s``."""
        st = self.array
        t_ns = self.since_first_ns(int(now_ns))
        if self._stop_requested:
            nxt = st[_NEXT]
            if nxt != nxt or t_ns >= nxt:
                # servoStop: the controller holds the tool where it is now
                st[_TARGET:_TARGET + 3] = st[_POS:_POS + 3]
                self._stop_requested = False
                self.servoing = False
        if advance_kernel(st, t_ns, float(dt_s)):
            self.cycled(now_ns)

    def cycled(self, now_ns: int) -> None:
        """A controller cycle ran at ``now_ns``: take the pending orientation, publish the pose (unless frozen)."""
        self.orientation = self._pending_orientation
        if not self.frozen:
            x, y, z = self.array[_POSE:_POSE + 3].tolist()
            self._pose = PoseSample(now_ns, (x, y, z), self.orientation, now_ns * 1e-9)

    def teleport(self, position_m: Vec3) -> None:
        """Place the tool at ``position_m`` at rest (set-up and calibration, not teleoperation)."""
        st = self.array
        st[_POS:_POS + 3] = st[_TARGET:_TARGET + 3] = st[_HELD:_HELD + 3] = position_m

    def read_pose(self) -> PoseSample:
        """The pose published at the last controller cycle."""
        return self._pose

    def close(self) -> None:
        """Nothing to release (also the :class:`TcpServo` close)."""
