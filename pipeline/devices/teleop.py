"""App-side teleoperation: stylus motion → UR TCP targets, with clutch, workspace box, speed limit and deadman.

Only for a rig where the app owns the robot (``robot.mode = "teleop"`` in
``hardware.toml``); in the default ``"observe"`` mode the robot runs its own
teleoperation program and this module is unused.  It is a lab-safety feature
that must be commissioned on site (docs/hardware-setup.md) -- the UR's own
safety configuration (joint/TCP limits, protective stop, e-stop) stays the
primary protection.

:class:`TeleopController` is the pure logic: no I/O, no threads, no clock of
its own.  It is handed ``now_ns``, the newest stylus state and robot pose at
every call and returns what to send to the robot:

* a :class:`ServoTarget` -- a TCP position (m, base frame) and the fixed
  orientation, for ``RTDEControlInterface.servoL``;
* :data:`STOP` -- stop servoing (``servoStop``), sent on every call while the
  robot must stand still (adapters make it idempotent);
* ``None`` -- nothing new this call (between control periods).

Mapping (position only; the tool orientation is held at what it was when the
operator engaged)::

    target_base_m = anchor_tcp_base_m + motion_scale · rot_base_haptic · (stylus_haptic_m − anchor_stylus_haptic_m)

then clamped into the workspace box and rate-limited so consecutive targets
are at most ``max_speed_m_s · period_s`` apart.

Buttons (OpenHaptics ``HD_CURRENT_BUTTONS`` bits; on the 3D Systems Touch
``HD_DEVICE_BUTTON_1`` = 1 is the front, dark-grey stylus button under the
index finger, ``HD_DEVICE_BUTTON_2`` = 2 the rear, light-grey one):

* **deadman** (default button 1, held): the robot moves only while it is
  held; releasing it stops the robot at once (within the same call).
  Pressing it engages: the anchor is the measured TCP and the current stylus
  position, so engaging never moves the robot.
* **clutch** (default button 2, held): the robot holds its last target while
  the stylus is repositioned; on release the stylus↔TCP anchor is re-taken
  from the last target, so the robot continues without a jump.

Any of these stops the robot and latches a fault until the deadman is
released (the operator must consciously re-engage): stylus or robot data
older than their age limit or non-finite, a stylus position outside the
plausible range or moving faster than a hand can, a TCP further from the
last target than ``max_tracking_error_m`` (collision, protective stop), an
error reported by the servo adapter, or engaging with the TCP outside the
workspace.

The haptic loop's faults stop the robot too: the loop tells the rig when its
latched fault set changes (:meth:`TeleopDriver.on_faults`) and when it stops
(:meth:`TeleopDriver.stop_motion`).  A latched loop fault (operator stop,
watchdog, engine detached, ...) stops the robot at once and keeps the
controller in FAULT while it stays latched; after the experimenter resets it,
the operator must still release and press the deadman to move again.

Safety checks run on every call (the loop calls at 1 kHz); new targets are
computed once per control period (8 ms on a CB3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from pipeline.devices.interfaces import Fault, HapticDevice, HapticState, PoseSample, Robot, TcpServo
from pipeline.force.frames import Mat3, Vec3, check_rotation, mat_vec, transpose

__all__ = [
    "STOP",
    "TOUCH_BUTTON_DARK_GREY",
    "TOUCH_BUTTON_LIGHT_GREY",
    "ServoTarget",
    "Stop",
    "TeleopCommand",
    "TeleopConfig",
    "TeleopController",
    "TeleopDriver",
    "TeleopState",
]

#: ``HD_DEVICE_BUTTON_1``: the Touch's front (dark-grey) stylus button.
TOUCH_BUTTON_DARK_GREY = 1
#: ``HD_DEVICE_BUTTON_2``: the Touch's rear (light-grey) stylus button.
TOUCH_BUTTON_LIGHT_GREY = 2


class TeleopState(Enum):
    """Where the controller is."""

    IDLE = "idle"  # deadman released: robot stopped
    ENGAGED = "engaged"  # following the stylus
    CLUTCHED = "clutched"  # holding the last target while the stylus is repositioned
    FAULT = "fault"  # stopped for a reason; cleared by releasing the deadman


class ServoTarget(NamedTuple):
    """A TCP target: position (m, base frame) and ``rot_base_tip`` (held fixed while engaged)."""

    position_m: Vec3
    rot_base_tip: Mat3


class Stop(NamedTuple):
    """Stop servoing and hold (``servoStop``); ``reason`` is for the experimenter's log."""

    reason: str


#: The stop command issued while the robot must stand still.
STOP = Stop("idle")

TeleopCommand = ServoTarget | Stop


def _finite3(v: Vec3) -> bool:
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])


@dataclass(frozen=True, slots=True)
class TeleopConfig:
    """Teleoperation parameters (validated; ``hardware.toml`` ``[teleop]`` maps onto these).

    Attributes
    ----------
    workspace_min_m, workspace_max_m
        Opposite corners of the box (base frame, m) the TCP targets never leave.
    max_speed_m_s
        Largest TCP target speed, m/s: consecutive targets are at most
        ``max_speed_m_s · period_s`` apart.
    motion_scale
        TCP displacement per stylus displacement (0.5 = the robot moves half as far).
    period_s
        Control period, s: the UR controller's RTDE period (8 ms on a CB3, 2 ms on an e-Series).
    rot_haptic_base
        Robot base → Touch frame rotation (``frames.rot_haptic_base``); its
        transpose maps stylus motion into the base frame.
    deadman_button, clutch_button
        ``HD_CURRENT_BUTTONS`` bits of the deadman and clutch buttons.
    stylus_max_age_s, pose_max_age_s
        Stylus state / robot pose older than this is stale → stop.
    stylus_range_m
        A stylus coordinate beyond ±this is implausible (the Touch's workspace is ~0.16 m) → stop.
    stylus_max_speed_m_s
        A stylus moving faster than this is an encoder glitch, not a hand → stop.
    max_tracking_error_m
        Measured TCP further than this from the last target (collision, protective stop) → stop.
    settle_after_stop_s
        After a stop, engaging waits for a robot pose at least this much newer
        than the stop (the arm has come to rest), so the anchor is where the arm really is.
    """

    workspace_min_m: Vec3
    workspace_max_m: Vec3
    max_speed_m_s: float = 0.1
    motion_scale: float = 1.0
    period_s: float = 0.008
    rot_haptic_base: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    deadman_button: int = TOUCH_BUTTON_DARK_GREY
    clutch_button: int = TOUCH_BUTTON_LIGHT_GREY
    stylus_max_age_s: float = 0.02
    pose_max_age_s: float = 0.05
    stylus_range_m: float = 1.0
    stylus_max_speed_m_s: float = 3.0
    max_tracking_error_m: float = 0.05
    settle_after_stop_s: float = 0.03

    def __post_init__(self) -> None:
        lo, hi = self.workspace_min_m, self.workspace_max_m
        if len(lo) != 3 or len(hi) != 3 or not (_finite3(lo) and _finite3(hi)):
            raise ValueError(f"teleop workspace {lo!r}..{hi!r}: must be two finite 3-vectors in metres")
        for i, axis in enumerate("xyz"):
            if not lo[i] < hi[i]:
                raise ValueError(f"teleop.workspace_min_m[{axis}] = {lo[i]!r} must be below workspace_max_m[{axis}] = "
                                 f"{hi[i]!r}")
        for name in ("max_speed_m_s", "motion_scale", "period_s", "stylus_max_age_s", "pose_max_age_s",
                     "stylus_range_m", "stylus_max_speed_m_s", "max_tracking_error_m", "settle_after_stop_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"teleop.{name} = {v!r}: must be a finite number > 0")
        check_rotation(self.rot_haptic_base, "teleop.rot_haptic_base")
        for name in ("deadman_button", "clutch_button"):
            v = getattr(self, name)
            if v not in (TOUCH_BUTTON_DARK_GREY, TOUCH_BUTTON_LIGHT_GREY):
                raise ValueError(f"teleop.{name} = {v!r}: allowed values: 1 (front, dark grey), 2 (rear, light grey)")
        if self.deadman_button == self.clutch_button:
            raise ValueError(f"teleop.clutch_button = {self.clutch_button!r}: must differ from deadman_button")

    @property
    def max_step_m(self) -> float:
        """Largest distance between consecutive targets, m."""
        return self.max_speed_m_s * self.period_s

    def contains(self, p: Vec3) -> bool:
        """True if ``p`` (base frame, m) lies in the workspace box (boundary included)."""
        lo, hi = self.workspace_min_m, self.workspace_max_m
        return all(lo[i] <= p[i] <= hi[i] for i in range(3))


class TeleopController:
    """The teleoperation state machine (pure; see the module docstring).

    Parameters
    ----------
    config
        Validated parameters.
    """

    def __init__(self, config: TeleopConfig) -> None:
        self.config = config
        self._rot_base_haptic: Mat3 = transpose(config.rot_haptic_base)
        self._period_ns = int(round(config.period_s * 1e9))
        self.state = TeleopState.IDLE
        #: Why the robot last stopped ("" before the first stop).
        self.stop_reason = ""
        self.faults = 0
        self._anchor_stylus_m: Vec3 = (0.0, 0.0, 0.0)
        self._anchor_tcp_m: Vec3 = (0.0, 0.0, 0.0)
        self._rot_base_tip: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        #: The last target sent (base frame, m); None while not servoing.
        self.last_target_m: Vec3 | None = None
        self._next_ns: int | None = None
        self._now_ns = 0
        self._prev_stylus_m: Vec3 | None = None
        self._prev_stylus_ns = 0
        self._stop_ns: int | None = None
        self._settle_ns = int(round(config.settle_after_stop_s * 1e9))

    # -- helpers ------------------------------------------------------------------------------
    def _stop(self, state: TeleopState, reason: str) -> Stop:
        if state is TeleopState.FAULT and self.state is not TeleopState.FAULT:
            self.faults += 1
        self.state = state
        self.stop_reason = reason
        self.last_target_m = None
        self._next_ns = None
        self._stop_ns = self._now_ns
        return Stop(reason)

    def _data_problem(self, now_ns: int, stylus: HapticState, pose: PoseSample, servo_error: str, inhibit: str) -> str:
        cfg = self.config
        if inhibit:
            return inhibit
        if servo_error:
            return f"robot servo: {servo_error}"
        p = stylus.position_m
        if not _finite3(p):
            return f"stylus position {p!r} is not finite"
        if (now_ns - stylus.t_ns) * 1e-9 > cfg.stylus_max_age_s:
            return (f"stylus data stale ({(now_ns - stylus.t_ns) * 1e-6:.1f} ms old, "
                    f"limit {cfg.stylus_max_age_s * 1e3:g} ms)")
        r = cfg.stylus_range_m
        if not (-r <= p[0] <= r and -r <= p[1] <= r and -r <= p[2] <= r):
            return f"stylus position {p!r} m outside ±{r:g} m: implausible"
        q = pose.position_m
        if not (_finite3(q) and all(math.isfinite(x) for x in pose.rot_base_tip)):
            return f"robot pose {q!r} is not finite"
        if (now_ns - pose.t_ns) * 1e-9 > cfg.pose_max_age_s:
            return f"robot pose stale ({(now_ns - pose.t_ns) * 1e-6:.1f} ms old, limit {cfg.pose_max_age_s * 1e3:g} ms)"
        prev = self._prev_stylus_m
        if prev is not None and stylus.t_ns > self._prev_stylus_ns:
            dt = (stylus.t_ns - self._prev_stylus_ns) * 1e-9
            jump = math.dist(p, prev)
            # 1 mm slack for encoder quantisation on very short intervals
            if jump > cfg.stylus_max_speed_m_s * dt + 1e-3:
                return (f"stylus jumped {jump * 1e3:.1f} mm in {dt * 1e3:.1f} ms "
                        f"(faster than {cfg.stylus_max_speed_m_s:g} m/s)")
        last = self.last_target_m
        if last is not None and math.dist(q, last) > cfg.max_tracking_error_m:
            return (f"TCP {math.dist(q, last) * 1e3:.1f} mm from its target (limit {cfg.max_tracking_error_m * 1e3:g} "
                    "mm): collision or protective stop?")
        return ""

    def _servo(self, now_ns: int, target_m: Vec3) -> ServoTarget:
        self.last_target_m = target_m
        nxt = (self._next_ns if self._next_ns is not None else now_ns) + self._period_ns
        # a late call does not make up missed periods with a burst of steps
        self._next_ns = nxt if nxt > now_ns else now_ns + self._period_ns
        return ServoTarget(target_m, self._rot_base_tip)

    def _desired_m(self, stylus_m: Vec3) -> Vec3:
        """Mapped, clamped and rate-limited next target."""
        cfg = self.config
        a = self._anchor_stylus_m
        d = mat_vec(self._rot_base_haptic, (stylus_m[0] - a[0], stylus_m[1] - a[1], stylus_m[2] - a[2]))
        t = self._anchor_tcp_m
        lo, hi = cfg.workspace_min_m, cfg.workspace_max_m
        s = cfg.motion_scale
        want = tuple(min(max(t[i] + s * d[i], lo[i]), hi[i]) for i in range(3))
        last = self.last_target_m
        assert last is not None
        step = (want[0] - last[0], want[1] - last[1], want[2] - last[2])
        n = math.hypot(*step)
        limit = cfg.max_step_m
        if n > limit:
            k = limit / n
            step = (step[0] * k, step[1] * k, step[2] * k)
        # the last target and the wanted point are both in the (convex) box, so is every point between;
        # the final clamp only absorbs rounding
        return tuple(min(max(last[i] + step[i], lo[i]), hi[i]) for i in range(3))  # type: ignore[return-value]  # three items: mypy cannot count a generator

    # -- the step -----------------------------------------------------------------------------
    def halt(self, reason: str) -> Stop:
        """Stop from outside the state machine (a loop fault, the loop stopping).

        Latches FAULT like any other stop: the robot moves again only after the
        deadman has been released (with healthy data) and pressed again.

        Parameters
        ----------
        reason
            Why, for the experimenter's log (becomes :attr:`stop_reason`).

        Returns
        -------
        Stop
            The stop to send to the robot.
        """
        return self._stop(TeleopState.FAULT, reason)

    def step(
        self, now_ns: int, stylus: HapticState, pose: PoseSample, servo_error: str = "", inhibit: str = ""
    ) -> TeleopCommand | None:
        """Advance the state machine and say what to send to the robot.

        Parameters
        ----------
        now_ns
            Current time on the loop's clock.
        stylus
            Newest stylus state (device frame, m; buttons bitmask).
        pose
            Newest robot TCP pose (base frame).
        servo_error
            Error reported by the servo adapter ("" when healthy).
        inhibit
            Why the robot must not move ("" when nothing forbids it): a fault
            latched by the haptic loop.  Treated like a data problem: it stops
            the robot, and while it lasts the FAULT cannot be cleared.

        Returns
        -------
        ServoTarget | Stop | None
            A new target (once per control period while engaged or clutched),
            a stop (on every call while the robot must stand still), or None.
        """
        cfg = self.config
        self._now_ns = now_ns
        clutch = bool(stylus.buttons & cfg.clutch_button)
        try:
            if not stylus.buttons & cfg.deadman_button:
                latched = self.state is TeleopState.FAULT
                return self._released(self._data_problem(now_ns, stylus, pose, servo_error, inhibit) if latched else "")
            if self.state is TeleopState.FAULT:
                return Stop(self.stop_reason)
            problem = self._data_problem(now_ns, stylus, pose, servo_error, inhibit)
            if problem:
                return self._stop(TeleopState.FAULT, problem)
            if self.state is TeleopState.IDLE:
                return self._engage(now_ns, stylus.position_m, pose, clutch)
            return self._follow(now_ns, stylus.position_m, clutch)
        finally:
            if _finite3(stylus.position_m):
                self._prev_stylus_m = stylus.position_m
                self._prev_stylus_ns = stylus.t_ns

    def _released(self, problem: str) -> Stop:
        """The deadman is released: stop; a FAULT clears to IDLE once the data are healthy (``problem`` empty)."""
        if self.state is TeleopState.FAULT and problem:
            return Stop(self.stop_reason)  # stays latched until the data are healthy again
        if self.state in (TeleopState.ENGAGED, TeleopState.CLUTCHED):
            return self._stop(TeleopState.IDLE, "deadman released")
        if self.state is TeleopState.FAULT:
            self.state = TeleopState.IDLE
        return Stop(self.stop_reason or "deadman released")

    def _engage(self, now_ns: int, stylus_m: Vec3, pose: PoseSample, clutch: bool) -> TeleopCommand:
        """The deadman is pressed in IDLE: anchor the stylus at the TCP and hold there (inside the box, at rest)."""
        if not self.config.contains(pose.position_m):
            return self._stop(TeleopState.FAULT, f"TCP {pose.position_m!r} m is outside the teleoperation workspace; "
                                                 "jog it inside before engaging")
        if self._stop_ns is not None and pose.t_ns < self._stop_ns + self._settle_ns:
            return Stop("waiting for the arm to come to rest")
        self._anchor_stylus_m = stylus_m
        self._anchor_tcp_m = pose.position_m
        self._rot_base_tip = pose.rot_base_tip
        self.state = TeleopState.CLUTCHED if clutch else TeleopState.ENGAGED
        self._next_ns = None
        return self._servo(now_ns, pose.position_m)

    def _follow(self, now_ns: int, stylus_m: Vec3, clutch: bool) -> TeleopCommand | None:
        """ENGAGED or CLUTCHED with healthy data: the next target, once per control period."""
        last = self.last_target_m
        assert last is not None
        if self.state is TeleopState.ENGAGED and clutch:
            self.state = TeleopState.CLUTCHED
            return self._servo(now_ns, last)
        if self.state is TeleopState.CLUTCHED and not clutch:
            # re-anchor at the last target: the next target starts from where the robot was told to be
            self._anchor_stylus_m = stylus_m
            self._anchor_tcp_m = last
            self.state = TeleopState.ENGAGED
        if self._next_ns is not None and now_ns < self._next_ns:
            return None
        if self.state is TeleopState.CLUTCHED:
            return self._servo(now_ns, last)
        return self._servo(now_ns, self._desired_m(stylus_m))


class TeleopDriver:
    """Glue: feed a :class:`TeleopController` from the devices and send its commands to a :class:`TcpServo`.

    Called from the haptic loop's thread through the rig's ``advance`` (so it
    runs at 1 kHz on the loop's clock); it does no I/O itself -- the servo
    adapter hands targets to its own thread.  The loop's fault hooks
    (:meth:`on_faults`, :meth:`stop_motion`) reach it through the rig, on the
    same thread.

    Parameters
    ----------
    controller
        The state machine.
    haptic, robot, servo
        Where the stylus state, the TCP pose come from and where targets go.
    """

    def __init__(self, controller: TeleopController, haptic: HapticDevice, robot: Robot, servo: TcpServo) -> None:
        self.controller = controller
        self.haptic = haptic
        self.robot = robot
        self.servo = servo
        self.last_command: TeleopCommand | None = None
        #: Why the haptic loop forbids motion ("" while no loop fault is latched).
        self.inhibit = ""

    def update(self, now_ns: int) -> TeleopCommand | None:
        """One call of the controller; returns what was sent (None: nothing)."""
        cmd = self.controller.step(
            now_ns, self.haptic.read_state(), self.robot.read_pose(), self.servo.servo_error, self.inhibit
        )
        if cmd is None:
            return None
        if isinstance(cmd, Stop):
            self.servo.stop_servo()
        else:
            self.servo.servo_tcp(cmd.position_m, cmd.rot_base_tip)
        self.last_command = cmd
        return cmd

    def on_faults(self, faults: int) -> None:
        """The haptic loop's latched fault set changed (called by the loop through the rig).

        Any latched fault stops the robot in this very call and forbids motion
        until the set is empty again; an empty set lifts that, but the
        controller stays in FAULT until the deadman is released and pressed.

        Parameters
        ----------
        faults
            The loop's latched :class:`pipeline.devices.interfaces.Fault` flags (0: none).
        """
        if faults:
            self.inhibit = f"haptic loop fault {Fault(faults).describe()}"
            self._halt(self.inhibit)
        else:
            self.inhibit = ""

    def stop_motion(self, reason: str) -> None:
        """Stop the robot now (the loop is stopping); re-engaging needs the deadman released and pressed."""
        self._halt(reason)

    def _halt(self, reason: str) -> None:
        cmd = self.controller.halt(reason)
        self.servo.stop_servo()
        self.last_command = cmd

    def close(self) -> None:
        """Stop the robot and release the servo adapter."""
        try:
            self.servo.stop_servo()
        finally:
            self.servo.close()
