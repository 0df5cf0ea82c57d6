"""A clock the test steps, for a loop that runs in its own thread: the thread's waits end only when the test says.

:class:`pipeline.core.clock.VirtualClock` jumps straight to every deadline, so a
loop *thread* on it would race ahead of the test.  Here ``sleep_until``
blocks until the test has moved time past the deadline (:meth:`SteppedClock.step`),
and :meth:`SteppedClock.step` returns once the loop thread has run up to its
next wait (or the test's ``done`` says it never will: it froze or died): the
loop thread, the device's servo ticks and the supervisor's checks then happen
in a fixed order at known times.  Nothing sleeps on the wall clock; the
threads hand over through a condition variable (bounded waits).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class SteppedClock:
    """``now_ns`` moves only in :meth:`step`; ``sleep_until`` waits for it (see the module docstring)."""

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)
        self._cond = threading.Condition()
        self._entries = 0  # calls of sleep_until so far
        self.released = False

    def now_ns(self) -> int:
        return self._now

    def sleep_until(self, t_ns: int) -> None:
        with self._cond:
            self._entries += 1
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._now >= t_ns or self.released)

    def wait_for_sleeper(self, entries: int = 1, timeout_s: float = 5.0) -> bool:
        """Until ``sleep_until`` has been entered ``entries`` times in all."""
        with self._cond:
            return self._cond.wait_for(lambda: self._entries >= entries, timeout_s)

    def step(self, dt_ns: int = 1_000_000, done: Callable[[], bool] | None = None, timeout_s: float = 5.0) -> None:
        """Move time on by ``dt_ns``; return when a thread has entered ``sleep_until`` again, or ``done()``."""
        end = time.monotonic() + timeout_s
        with self._cond:
            before = self._entries
            self._now += dt_ns
            self._cond.notify_all()
            while self._entries == before and not (done is not None and done()):
                if time.monotonic() > end:
                    raise AssertionError("the loop thread neither waited again nor finished")
                self._cond.wait(0.002)  # re-check ``done`` (a thread dying does not notify us)

    def release(self) -> None:
        """End every wait (tear-down)."""
        with self._cond:
            self.released = True
            self._cond.notify_all()
