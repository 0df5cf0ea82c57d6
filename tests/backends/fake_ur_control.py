"""A stand-in for ur_rtde's ``RTDEControlInterface``, injected through ``UrRtdeServo``'s ``control_factory`` seam.

Why not a loopback fake of the wire protocol, as for the other backends: the
real ``RTDEControlInterface`` uploads a URScript program over the controller's
primary/secondary interfaces (TCP 30001/30002), waits for the script to start
and then exchanges commands through RTDE input registers, with the dashboard
server in the loop.  Faking all of that is a UR controller emulator (URSim),
out of scope here.  This object offers exactly the methods ``UrRtdeServo``
calls, records every call in order, and lets a test choose their results.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any


class FakeControl:
    """Records ``servoL``/``servoStop``/``stopScript``/``disconnect`` calls (thread-safe).

    Attributes
    ----------
    calls
        ``(name, args)`` in call order.
    servo_ok, stop_ok
        What ``servoL`` / ``servoStop`` return (ur_rtde returns False when the controller refuses).
    stop_raises
        If set, ``servoStop`` raises it (a lost link).
    on_call
        Called with the method name at each call, before it returns (from the caller's thread).
    """

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...]]] = []
        self.servo_ok = True
        self.stop_ok = True
        self.stop_raises: Exception | None = None
        self.on_call: Callable[[str], None] | None = None
        self._cond = threading.Condition()

    def _record(self, name: str, args: tuple[Any, ...]) -> None:
        if self.on_call is not None:
            self.on_call(name)
        with self._cond:
            self.calls.append((name, args))
            self._cond.notify_all()

    # -- the RTDEControlInterface methods UrRtdeServo uses ---------------------------------------
    def servoL(self, pose: list[float], speed: float, acceleration: float, time: float, lookahead_time: float,
               gain: float) -> bool:
        self._record("servoL", (list(pose), speed, acceleration, time, lookahead_time, gain))
        return self.servo_ok

    def servoStop(self, a: float) -> bool:
        self._record("servoStop", (a,))
        if self.stop_raises is not None:
            raise self.stop_raises
        return self.stop_ok

    def stopScript(self) -> None:
        self._record("stopScript", ())

    def disconnect(self) -> None:
        self._record("disconnect", ())

    # -- for tests ----------------------------------------------------------------------------
    def names(self) -> list[str]:
        with self._cond:
            return [n for n, _ in self.calls]

    def count(self, name: str) -> int:
        return self.names().count(name)

    def wait_count(self, name: str, n: int, timeout_s: float = 1.0) -> bool:
        """Wait (bounded) until ``name`` has been called at least ``n`` times."""
        with self._cond:
            return self._cond.wait_for(lambda: sum(1 for c, _ in self.calls if c == name) >= n, timeout_s)
