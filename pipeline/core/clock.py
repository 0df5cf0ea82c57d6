"""Clocks for the haptic loop: the real monotonic clock and a virtual one.

Everything that depends on time takes a :class:`Clock`, so the whole rig runs
on :class:`VirtualClock` in tests and headless studies -- deterministically and
as fast as the CPU allows, with no test sleeping on the wall clock -- and on
:class:`MonotonicClock` on the lab PC.
"""

from __future__ import annotations

import gc
import os
import time
from typing import Protocol, runtime_checkable

from foundation.platform_support.threads import pin_to_cpu, set_fifo_priority, set_timer_slack_ns, usable_cpus

__all__ = [
    "Clock", "MonotonicClock", "VirtualClock", "collect_garbage", "loop_cpu_problem", "manual_garbage_collection",
    "pin_loop_process", "prepare_helper_thread", "prepare_realtime_thread", "realtime_env_problem",
    "set_timer_slack_ns",
]


@runtime_checkable
class Clock(Protocol):
    """Time source with absolute-deadline waiting."""

    def now_ns(self) -> int:
        """Current time, integer nanoseconds on this clock's monotonic scale."""
        ...

    def sleep_until(self, t_ns: int) -> None:
        """Return when ``now_ns() >= t_ns`` (immediately if already past)."""
        ...


class VirtualClock:
    """A clock that only moves when told to: ``sleep_until`` jumps straight to the deadline.

    Parameters
    ----------
    start_ns
        Initial reading.
    """

    __slots__ = ("_now",)

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)

    def now_ns(self) -> int:
        """Current virtual time, ns."""
        return self._now

    def sleep_until(self, t_ns: int) -> None:
        """Advance virtual time to ``t_ns`` (never backwards)."""
        if t_ns > self._now:
            self._now = t_ns

    def advance(self, dt_ns: int) -> None:
        """Move time forward by ``dt_ns``."""
        if dt_ns < 0:
            raise ValueError(f"dt_ns = {dt_ns}: virtual time cannot go backwards")
        self._now += dt_ns


class MonotonicClock:
    """``time.perf_counter_ns`` with sleep-then-spin absolute-deadline waiting.

    Parameters
    ----------
    spin_ns
        The last part of each wait is a busy-wait: the kernel wakes a sleeping
        thread 50–100 µs late, a spin is exact (science.md §7: lateness p50
        90 µs → 0.1 µs for ~14 % of a core).
    """

    __slots__ = ("spin_ns",)

    def __init__(self, spin_ns: int = 200_000) -> None:
        self.spin_ns = int(spin_ns)

    def now_ns(self) -> int:
        """Current time, ns (CLOCK_MONOTONIC via perf_counter_ns)."""
        return time.perf_counter_ns()

    def sleep_until(self, t_ns: int) -> None:
        """Sleep until ``spin_ns`` before the deadline, then spin to it."""
        now = time.perf_counter_ns
        remaining = t_ns - now() - self.spin_ns
        if remaining > 0:
            time.sleep(remaining * 1e-9)
        while now() < t_ns:
            pass


#: Set to ``0`` to keep the loop thread at normal priority (``1``, or unset: ask for ``SCHED_FIFO``).
REALTIME_ENV = "HAPTIC_STUDY_REALTIME"


def realtime_env_problem() -> str | None:
    """What is wrong with :data:`REALTIME_ENV` in one line, or None when it is unset, empty, ``0`` or ``1``.

    Anything else (``banana``, ``off``, ``no``) would silently mean "real-time on"; the command line refuses it.
    """
    raw = os.environ.get(REALTIME_ENV)
    if raw is None or raw.strip() in ("", "0", "1"):
        return None
    return (f"{REALTIME_ENV} = {raw!r}: must be 0 (the loop at normal priority) or 1 (SCHED_FIFO, the default; "
            "also when unset)")


#: The CPU the loop's own process runs on (a number), or ``none`` for any; unset: the last CPU this process may use.
LOOP_CPU_ENV = "HAPTIC_STUDY_LOOP_CPU"


def loop_cpu_problem() -> str | None:
    """What is wrong with :data:`LOOP_CPU_ENV` in one line, or None (unset, empty, ``none`` or a CPU we may use)."""
    raw = os.environ.get(LOOP_CPU_ENV, "").strip()
    if raw in ("", "none"):
        return None
    cpus = usable_cpus()
    if not raw.isdigit() or int(raw) not in cpus:
        return f"{LOOP_CPU_ENV} = {raw!r}: must be 'none' or one of the CPUs this process may use ({_cpu_list(cpus)})"
    return None


def _cpu_list(cpus: list[int]) -> str:
    return f"{cpus[0]}-{cpus[-1]}" if len(cpus) > 1 and cpus == list(range(cpus[0], cpus[-1] + 1)) else \
        ", ".join(str(c) for c in cpus)


def pin_loop_process() -> str:
    """Run the loop's own process on one CPU; say which, among which (``"CPU 1 of 0-1"``), or why not.

    The choice: :data:`LOOP_CPU_ENV` if set, else the last CPU this process may use -- on Linux CPU 0 serves most
    interrupts and housekeeping.  Pinned, the loop keeps its caches and never migrates; under ``SCHED_FIFO`` it
    preempts whatever else runs on that CPU the moment its sleep ends.  With one CPU there is nothing to choose.
    Other programs still run on that CPU (only the kernel's ``isolcpus`` keeps them off).
    """
    cpus = usable_cpus()
    raw = os.environ.get(LOOP_CPU_ENV, "").strip()
    if raw == "none":
        return f"any CPU ({LOOP_CPU_ENV}=none)"
    if len(cpus) < 2 and not raw:
        return "any CPU (this process may use one only)"
    cpu = int(raw) if raw.isdigit() and int(raw) in cpus else cpus[-1]
    got = pin_to_cpu(cpu)
    return f"{got} of {_cpu_list(cpus)}" if got.startswith("CPU") else got


#: SCHED_FIFO priority of the loop thread: above every normal thread, far below the kernel's own (50+).
REALTIME_PRIORITY = 20
#: SCHED_FIFO priority of the other threads of the loop's process (:func:`prepare_helper_thread`): below the loop.
HELPER_PRIORITY = 10


def prepare_realtime_thread(priority: int = REALTIME_PRIORITY) -> str:
    """Make the calling thread fit for a 1 kHz deadline loop; return what it got.

    Sets a 1 ns timer slack (:func:`set_timer_slack_ns`) and asks for
    ``SCHED_FIFO`` at ``priority``, so the loop preempts the GUI, the recorder
    and anything else on the machine the moment its sleep ends instead of
    waiting for the scheduler's next turn.  The loop sleeps most of each
    period, so it never monopolises a core (and the kernel caps real-time
    threads at 95 % of a core regardless).  Without the privilege
    (``CAP_SYS_NICE`` / rtprio limit) the thread stays at normal priority;
    that costs only precision.  Call it only from a thread that paces itself
    on the real clock, never from a simulation.

    Returns
    -------
    str
        ``"SCHED_FIFO/<priority>"`` or ``"normal (…why…)"``.
    """
    set_timer_slack_ns(1)
    return _set_fifo(priority)


def prepare_helper_thread(priority: int = HELPER_PRIORITY) -> str:
    """Put a thread that shares the loop's process (and so its GIL) on ``SCHED_FIFO`` below the loop.

    Why: the loop thread cannot run Python without the GIL.  If another
    thread of its process holds the GIL and the kernel preempts that thread
    for an ordinary process (a busy machine), the real-time loop waits for a
    normal-priority thread to be scheduled again -- milliseconds: a priority
    inversion through the GIL.  At ``SCHED_FIFO`` just below the loop the
    holder keeps its CPU until it releases the GIL.  Threads created
    afterwards by this thread inherit the policy, so calling it first in a
    process's main thread covers the threads it starts (the loop thread then
    raises itself to :data:`REALTIME_PRIORITY`).  These threads block on
    queues, pipes and timeouts most of the time; the kernel still caps
    real-time threads at 95 % of a CPU.  Honours ``HAPTIC_STUDY_REALTIME=0``
    like :func:`prepare_realtime_thread`.

    Returns
    -------
    str
        ``"SCHED_FIFO/<priority>"`` or ``"normal (…why…)"``.
    """
    return _set_fifo(priority)


def _set_fifo(priority: int) -> str:
    """``SCHED_FIFO`` at ``priority`` for the calling thread, unless disabled or not permitted; what it got."""
    if os.environ.get(REALTIME_ENV, "1").strip() == "0":
        return f"normal ({REALTIME_ENV}=0)"
    return set_fifo_priority(priority)  # normal priority where the OS has no SCHED_FIFO (platform_support)


def manual_garbage_collection() -> None:
    """Take the cyclic garbage collector's timing out of the interpreter's hands, for a real-time process.

    Collects once, freezes what exists (it lives as long as the process: a
    full pass over it, numpy and the rig included, holds the GIL for 6–10 ms)
    and disables automatic collection, which would otherwise start in
    whichever thread allocates -- often the loop thread itself, mid-tick.
    The process must then call :func:`collect_garbage` regularly, at a moment
    when a short pause costs nothing (just after a loop tick).
    """
    gc.collect()
    gc.freeze()
    gc.disable()


def collect_garbage() -> int | None:
    """Run the collector pass the interpreter would have started by itself by now, if any; return its generation.

    For processes under :func:`manual_garbage_collection`, called right after
    a loop tick.  Same thresholds as the automatic collector
    (:func:`gc.get_threshold`), without its heuristic of postponing full
    passes; with the long-lived objects frozen, even a full pass only visits
    what was allocated since.
    """
    t0, t1, t2 = gc.get_threshold()
    c0, c1, c2 = gc.get_count()
    if c0 < t0:
        return None
    gen = 2 if (c1 >= t1 and c2 >= t2) else 1 if c1 >= t1 else 0
    gc.collect(gen)
    return gen
