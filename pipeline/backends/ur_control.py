"""UR TCP servoing over ``ur_rtde``'s ``RTDEControlInterface`` -- app-side teleoperation only.

Used only with ``robot.mode = "teleop"`` (pipeline/devices/teleop.py): the control
interface uploads a URScript and takes control of the robot, so in the
default ``"observe"`` mode it is never constructed (docs/hardware.md §1.2).

The loop thread must never block on the network, so :class:`UrRtdeServo`
only drops the newest target (or a stop request) into a slot and wakes its
own worker thread, which calls ``servoL(pose, 0, 0, period, lookahead, gain)``
or ``servoStop(a)``.  The worker is a second deadman: if no new target arrives
for ``target_timeout_s`` while servoing (the loop stalled or died), it stops
the robot by itself and reports it through :attr:`UrRtdeServo.servo_error`,
which makes the teleoperation controller latch a fault.  An error stays
latched (new targets are ignored) until a stop requested through
:meth:`UrRtdeServo.stop_servo` -- which the controller sends on every call
while it is faulted -- has been accepted by the controller.

Construction is bounded: a plain TCP probe of the RTDE port first (``ur_rtde``
holds the GIL while it connects, see pipeline/backends/ur.py), then the
constructor runs in a thread and is abandoned with a clear error after
``control_timeout_s``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from pipeline.backends.ur import RtdeLink, rtde_interface
from pipeline.core.clock import Clock
from pipeline.devices.interfaces import DeviceError
from pipeline.force.frames import Mat3, Vec3, matrix_to_rotvec

__all__ = ["UrRtdeServo"]


def _default_factory(host: str, frequency_hz: float) -> Any:
    # only teleop mode takes control of the robot: rtde_control is imported (and the script uploaded) only then
    return rtde_interface("rtde_control", "RTDEControlInterface", host, frequency_hz, "teleoperation")


class UrRtdeServo:
    """A :class:`pipeline.devices.interfaces.TcpServo` streaming ``servoL`` targets to a UR controller.

    Parameters
    ----------
    link
        The controller, the rate asked of it (its period is each ``servoL``'s time; with -1 the robot model's
        control period, :attr:`pipeline.backends.ur.RtdeLink.rate_hz`), the loop's clock (the target ages) and the
        bound of the TCP probe.
    control_timeout_s
        Bound of ``RTDEControlInterface`` construction (it uploads and starts a script).
    lookahead_s, gain
        ``servoL`` look-ahead time (0.03–0.2 s; its lag is about its own length, so the smallest by default: the
        robot's share of the latency a participant feels, docs/hardware-setup.md) and proportional gain (100–2000).
    target_timeout_s
        No new target for this long while servoing → ``servoStop`` and an error.
    stop_deceleration_m_s2
        ``servoStop`` deceleration of the tool.
    control_factory
        ``factory(host, frequency_hz)`` returning an object with the
        ``RTDEControlInterface`` methods used here (default: ur_rtde's).
    """

    def __init__(
        self,
        link: RtdeLink,
        *,
        control_timeout_s: float = 5.0,
        lookahead_s: float = 0.03,
        gain: float = 300.0,
        target_timeout_s: float = 0.05,
        stop_deceleration_m_s2: float = 10.0,
        control_factory: Callable[[str, float], Any] | None = None,
    ) -> None:
        if not 0.03 <= lookahead_s <= 0.2:
            raise ValueError(f"lookahead_s = {lookahead_s!r}: servoL allows 0.03 to 0.2 s")
        if not 100 <= gain <= 2000:
            raise ValueError(f"gain = {gain!r}: servoL allows 100 to 2000")
        self.host = link.host
        self.period_s = 1.0 / link.rate_hz
        self.clock: Clock = link.clock
        self.lookahead_s = lookahead_s
        self.gain = gain
        self.target_timeout_s = target_timeout_s
        self.stop_deceleration_m_s2 = stop_deceleration_m_s2
        self._cond = threading.Condition()
        self._target: tuple[float, ...] | None = None
        self._target_ns = 0
        self._target_seq = 0
        self._stop_requested = False
        self._closing = False
        self._error = ""
        self.servoing = False
        self.servo_commands = 0
        self.servo_stops = 0
        link.require_reachable(" for teleoperation")
        self._ctrl = self._construct(control_factory or _default_factory, link.host, link.frequency_hz,
                                     control_timeout_s)
        self._thread = threading.Thread(target=self._work, name="ur-servo", daemon=True)
        self._thread.start()

    @staticmethod
    def _construct(factory: Callable[[str, float], Any], host: str, frequency_hz: float, timeout_s: float) -> Any:
        box: dict[str, Any] = {}
        done = threading.Event()

        def _run() -> None:
            try:
                box["ctrl"] = factory(host, frequency_hz)
            except Exception as exc:  # reported to the caller below
                box["error"] = exc
            done.set()

        threading.Thread(target=_run, name="ur-control-connect", daemon=True).start()
        if not done.wait(timeout_s):
            raise DeviceError(
                f"the UR controller at {host} did not start the ur_rtde control script within {timeout_s:g} s; "
                "is the robot in remote control mode, powered on and brakes released?"
            )
        if "error" in box:
            raise DeviceError(f"ur_rtde could not take control of the UR controller at {host}: {box['error']}")
        return box["ctrl"]

    # -- TcpServo -----------------------------------------------------------------------------
    def servo_tcp(self, position_m: Vec3, rot_base_tip: Mat3) -> None:
        """Hand the newest target to the worker (returns at once)."""
        rx, ry, rz = matrix_to_rotvec(rot_base_tip)
        with self._cond:
            self._target = (position_m[0], position_m[1], position_m[2], rx, ry, rz)
            self._target_ns = self.clock.now_ns()
            self._target_seq += 1
            self._stop_requested = False
            self._cond.notify_all()

    def stop_servo(self) -> None:
        """Ask the worker to ``servoStop`` (idempotent; returns at once)."""
        with self._cond:
            if not (self.servoing or self._error or self._target is not None):
                return  # nothing moving: do not wake the worker on every idle call
            if not self._stop_requested:
                self._stop_requested = True
                self._target = None
                self._cond.notify_all()

    @property
    def servo_error(self) -> str:
        """The last servo failure ("" while healthy); cleared by a successful ``servoStop``."""
        return self._error

    def close(self) -> None:
        """Stop the robot, end the control script and disconnect."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        t = getattr(self, "_thread", None)
        if t is not None and t.is_alive() and threading.current_thread() is not t:
            t.join(2.0)
        ctrl, self._ctrl = self._ctrl, None
        if ctrl is None:
            return
        for call in (lambda: ctrl.servoStop(self.stop_deceleration_m_s2), ctrl.stopScript, ctrl.disconnect):
            try:
                call()
            except Exception:  # the link may already be gone; keep releasing
                pass

    # -- worker -------------------------------------------------------------------------------
    def _work(self) -> None:
        sent_seq = 0
        timeout_ns = int(self.target_timeout_s * 1e9)
        while True:
            with self._cond:
                self._cond.wait_for(
                    # wait_for calls it at once, in this iteration
                    lambda: self._closing or self._stop_requested or self._target_seq != sent_seq,  # noqa: B023
                    timeout=self.period_s,
                )
                if self._closing:
                    return
                stop = self._stop_requested
                target, seq, target_ns = self._target, self._target_seq, self._target_ns
            ctrl = self._ctrl
            now = self.clock.now_ns()
            try:
                if stop:
                    if self.servoing or self._error:
                        self._do_stop(ctrl)
                        with self._cond:
                            if self._stop_requested and self._target_seq == seq:
                                self._stop_requested = False
                    else:
                        with self._cond:
                            self._stop_requested = False
                elif target is not None and seq != sent_seq and not self._error:
                    sent_seq = seq
                    if now - target_ns > timeout_ns:
                        continue  # picked up too late: the check below stops the robot if nothing newer comes
                    ok = ctrl.servoL(list(target), 0.0, 0.0, self.period_s, self.lookahead_s, self.gain)
                    self.servo_commands += 1
                    if ok is False:
                        self._error = ("servoL refused the target (protective stop, or the control script is not "
                                       "running)")
                        self._do_stop(ctrl, clears_error=False)
                    else:
                        self.servoing = True
                elif self.servoing and now - target_ns > timeout_ns:
                    self._error = f"no teleoperation target for {(now - target_ns) * 1e-6:.0f} ms: stopped the robot"
                    self._do_stop(ctrl, clears_error=False)
            except Exception as exc:  # a lost link or a controller error: stop and report
                self._error = f"RTDE control: {exc}"
                self.servoing = False

    def _do_stop(self, ctrl: Any, clears_error: bool = True) -> None:
        """``servoStop``; only a requested stop (``clears_error``) the UR accepted clears the error.

        The worker's own stops (after a failure) keep the error latched, so the
        teleoperation controller sees it and latches a fault.
        """
        ok = ctrl.servoStop(self.stop_deceleration_m_s2)
        self.servo_stops += 1
        self.servoing = False
        if ok is False:
            if "servoStop refused" not in self._error:
                self._error = (self._error + "; " if self._error else "") + "servoStop refused"
        elif clears_error:
            self._error = ""
