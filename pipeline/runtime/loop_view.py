"""The loop as the code beside it sees it: what the study engine and a session's set-up read of it and send it.

Two things satisfy :class:`LoopView`: the loop itself (:class:`pipeline.runtime.loop.HapticLoop`, in the driver's
process: the virtual clock, and the real clock where the loop cannot have a process of its own) and its stand-in
for a loop that runs alone in another process (:class:`pipeline.assembly.loop_client.RemoteLoop`).  Code that only
needs this view works with either.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Protocol

from pipeline.core.clock import Clock
from pipeline.force.config import FrameworkConfig
from pipeline.runtime.loop_messages import Command, LoopEvent
from pipeline.runtime.watchdog import WatchdogConfig

__all__ = ["ArmView", "FrameworkHolder", "LoopView", "MissedSlots"]


class FrameworkHolder(Protocol):
    """Something that holds an arm's Algorithm 1 settings (a :class:`pipeline.force.framework.HapticFramework`)."""

    @property
    def config(self) -> FrameworkConfig: ...


class MissedSlots(Protocol):
    """The loop's count of the period slots it skipped after running late."""

    @property
    def missed_slots(self) -> int: ...


class ArmView(Protocol):
    """One arm of the loop: its name, its latched faults, its replay log (taken by the session driver)."""

    @property
    def name(self) -> str: ...

    @property
    def faults(self) -> int: ...

    @property
    def replay_log(self) -> deque[tuple[int, str, object]]: ...


class LoopView(Protocol):
    """What runs beside the 1 kHz loop reads of it and sends it (see the module's docstring)."""

    #: Called with each :class:`LoopEvent` (the loop's thread, or the driver's when the loop has a process).
    on_event: Callable[[LoopEvent], None] | None

    @property
    def period_ns(self) -> int: ...

    @property
    def watchdog(self) -> WatchdogConfig: ...

    @property
    def clock(self) -> Clock: ...

    @property
    def t0_ns(self) -> int: ...

    @property
    def tick_count(self) -> int: ...

    @property
    def faults(self) -> int: ...

    @property
    def haptic_on(self) -> bool: ...

    @property
    def scheduling(self) -> str: ...

    @property
    def crash(self) -> str: ...

    @property
    def thread_alive(self) -> bool | None: ...

    @property
    def runs_in(self) -> str: ...

    @property
    def stats(self) -> MissedSlots: ...

    @property
    def framework(self) -> FrameworkHolder: ...

    @property
    def replay_log(self) -> deque[tuple[int, str, object]]: ...

    @property
    def last_record(self) -> dict[str, float | int] | None: ...

    def arm(self, name: str) -> ArmView: ...

    def submit(self, command: Command) -> None: ...

    def start(self) -> None: ...

    def stop(self, timeout_s: float = 2.0) -> None: ...

    def ramp_down(self, max_ticks: int = 200) -> None: ...

    def fail_safe(self, detail: str, *, thread_dead: bool) -> LoopEvent: ...
