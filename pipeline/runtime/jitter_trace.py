"""Why was a loop tick late?  A tracing clock for an engine process (debug and benchmarks only).

The 1 kHz loop shares its process -- and the GIL -- with the engine's other
threads (the command receiver; in the study engine also the driver / session
runner, recorder and event feeder).
:class:`LateTickTracer` wraps the loop's :class:`pipeline.core.clock.MonotonicClock`
(the loop's only contact with time, so :mod:`pipeline.runtime.loop` is untouched) and,
at the start of every tick, snapshots from the loop thread:

* the CPU time of every thread of the process (``pthread_getcpuclockid``) and
  the kernel's scheduler counters of every task (``/proc/self/task/*/schedstat``:
  time run, time spent runnable but waiting for a CPU) -- read through a
  ``PyDLL`` ``pread`` that keeps the GIL, so tracing never hands the GIL away;
* garbage-collector passes (``gc.callbacks``: which thread, how long).

When a tick starts more than 100 µs after its deadline (so its period, or
the next one, is off by more than the issue's 100 µs), or a period exceeds
2 ms, it compares with the previous tick's snapshot and names the cause that
explains most of the delay:

``gc``
    a garbage-collector pass ran in the interval (the thread that ran it holds the GIL throughout);
``gil:<thread>``
    the loop was blocked (not sleeping, not runnable) while ``<thread>`` used the CPU: it held the GIL;
``gil-holder-preempted:<thread>``
    the thread holding the GIL was runnable but had no CPU (other processes), so the loop waited for it;
``cpu-busy``
    the loop thread itself was runnable but got no CPU (other real-time work, or the hypervisor);
``loop-work``
    the loop thread's own tick took the extra time (CPU time of the loop thread);
``machine``
    nothing in this process explains it: a late timer, or the hypervisor took the virtual CPU (steal).

Each late period also records where the culprit thread was (its innermost
frames from ``sys._current_frames()``) so the offending code can be found.
Cost: ≈ 25–35 µs per tick in the loop thread (it shows in the p99); enable
it only to diagnose (``HostConfig.trace_jitter``, ``EngineConfig.trace_jitter``)
or in ``haptic-study bench gui|pipeline --explain``.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

from foundation.platform_support.threads import gil_keeping_pread, open_schedstat, thread_ids
from pipeline.core.clock import MonotonicClock

__all__ = ["LateTickTracer"]


class _SchedReader:
    """``/proc/self/task/<tid>/schedstat`` → (run_ns, wait_ns) without releasing the GIL."""

    def __init__(self) -> None:
        self._pread = gil_keeping_pread(128)  # None where the OS has none: the tracer then reads zeros

    def open(self, tid: int) -> int:
        if self._pread is None:
            return -1
        return open_schedstat(tid)

    def read(self, fd: int) -> tuple[int, int]:
        if fd < 0:
            return (0, 0)
        raw = self._pread(fd) if self._pread is not None else b""
        if not raw:
            return (0, 0)
        parts = raw.split()
        return (int(parts[0]), int(parts[1]))


@dataclass
class _Task:
    tid: int
    name: str
    ident: int | None  # Python thread ident (for frames), None for native threads
    fd: int


@dataclass
class LatePeriod:
    """One late tick and what explains it (all µs)."""

    period_us: float
    late_us: float  # after the deadline
    cause: str
    where: str
    loop_tick_us: float  # the previous tick's own duration (wall)
    loop_blocked_us: float  # loop neither running nor runnable beyond its planned sleep (GIL wait, late timer)
    loop_wait_us: float  # loop runnable without a CPU
    gc_us: float
    others_cpu_us: dict[str, float]
    others_wait_us: dict[str, float]


class LateTickTracer:
    """A :class:`pipeline.core.clock.Clock` that times the loop like ``MonotonicClock`` and explains late periods.

    Parameters
    ----------
    inner
        The clock being wrapped (its ``spin_ns`` is kept).
    late_ns
        Ticks starting later than this after their deadline are explained (and periods over 2 ms).
    keep
        How many late periods to keep in full (the counts cover all).
    """

    def __init__(self, inner: MonotonicClock | None = None, *, late_ns: int = 100_000, keep: int = 200) -> None:
        self.spin_ns = (inner or MonotonicClock()).spin_ns
        self.late_ns = int(late_ns)
        self.keep = keep
        self._sched = _SchedReader()
        self._tasks: list[_Task] = []
        self._loop_tid = 0
        self._loop_fd = -1
        self._graveyard: list[int] = []
        self._prev_ret: int | None = None
        self._prev_snap: dict[int, tuple[int, int]] = {}
        self._planned_sleep = 0
        self._tick_ns = 0
        self._run_norm = 300_000.0
        self._gc_log: list[tuple[int, int, int, int]] = []  # (start_ns, end_ns, tid, generation)
        self._gc_start: dict[int, int] = {}
        self.reset()
        gc.callbacks.append(self._on_gc)

    # -- results ------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the counts (with the engine's stats reset)."""
        self.causes: Counter[str] = Counter()
        self.causes_over_2ms: Counter[str] = Counter()
        self.culprits: Counter[str] = Counter()
        self.late: list[LatePeriod] = []
        self.periods = 0
        #: garbage-collector passes: "gen<g> in loop|other thread" → (count, longest µs)
        self.gc_passes: dict[str, tuple[int, float]] = {}

    def summary(self, top: int = 6) -> dict[str, Any]:
        """Counts of late periods by cause and the most frequent culprit code locations.

        Called from another thread while the loop thread counts: every container is first copied
        in one C-level call (atomic under the GIL), never iterated in Python while it may change.
        """
        causes, over = Counter(dict(self.causes)), Counter(dict(self.causes_over_2ms))
        culprits = Counter(dict(self.culprits))
        late, gc_passes = list(self.late), dict(self.gc_passes)
        return {
            "late_threshold_us": self.late_ns / 1000.0,
            "ticks": self.periods,
            "late_ticks": sum(causes.values()),
            "causes": dict(causes.most_common()),
            "over_2ms": sum(over.values()),
            "causes_over_2ms": dict(over.most_common()),
            "culprits": dict(culprits.most_common(top)),
            "gc_passes": {k: {"count": n, "longest_us": round(w)} for k, (n, w) in sorted(gc_passes.items())},
            "worst": [
                {"period_us": round(p.period_us), "late_us": round(p.late_us), "cause": p.cause, "where": p.where,
                 "gc_us": round(p.gc_us), "loop_blocked_us": round(p.loop_blocked_us),
                 "loop_wait_us": round(p.loop_wait_us),
                 "others_cpu_us": {k: round(v) for k, v in p.others_cpu_us.items() if v >= 50},
                 "others_wait_us": {k: round(v) for k, v in p.others_wait_us.items() if v >= 50}}
                for p in sorted(late, key=lambda p: -p.period_us)[:top]
            ],
        }

    def restart(self) -> None:
        """The loop paused (a calibration): the next period is not a loop period."""
        self._prev_ret = None

    def close(self) -> None:
        """Stop watching the garbage collector and close the scheduler-counter files."""
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)
        for fd in [t.fd for t in self._tasks] + self._graveyard:
            if fd >= 0:
                os.close(fd)
        self._tasks, self._graveyard = [], []
        if self._loop_fd >= 0:
            os.close(self._loop_fd)
            self._loop_fd = -1

    # -- the Clock interface --------------------------------------------------------------------------
    def now_ns(self) -> int:
        """Current time, ns (as :class:`MonotonicClock`)."""
        return time.perf_counter_ns()

    def sleep_until(self, t_ns: int) -> None:
        """Sleep then spin to ``t_ns`` (as :class:`MonotonicClock`), then account for the period just ended."""
        now = time.perf_counter_ns
        t_call = now()
        remaining = t_ns - t_call - self.spin_ns
        if remaining > 0:
            time.sleep(remaining * 1e-9)
        while now() < t_ns:
            pass
        t_ret = now()
        prev = self._prev_ret
        self._tick_ns = 0 if prev is None else t_call - prev
        self._planned_sleep = max(0, t_ns - self.spin_ns - t_call)
        self._account(t_ret, t_ret - t_ns)

    # -- internals -----------------------------------------------------------------------------------
    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        tid = threading.get_native_id()
        if phase == "start":
            self._gc_start[tid] = time.perf_counter_ns()
        else:
            t0 = self._gc_start.pop(tid, None)
            if t0 is not None:
                t1 = time.perf_counter_ns()
                gen = int(info.get("generation", -1))
                key = f"gen{gen} in {'loop' if tid == self._loop_tid else 'other'} thread"
                n, worst = self.gc_passes.get(key, (0, 0.0))
                self.gc_passes[key] = (n + 1, max(worst, (t1 - t0) / 1000.0))
                log = self._gc_log
                log.append((t0, t1, tid, gen))
                if len(log) > 64:
                    del log[:32]

    def refresh(self) -> None:
        """Re-list the process's threads (call from a thread other than the loop's, about twice a second).

        Listing and opening files releases the GIL and takes ~0.1 ms: never in the loop thread.
        """
        by_tid = {t.native_id: t for t in threading.enumerate() if t.native_id is not None}
        known = {t.tid: t for t in self._tasks}
        tids = thread_ids() or list(by_tid)  # /proc/self/task (elsewhere: Python's threads; platform_support)
        tasks = []
        loop_tid = self._loop_tid
        for tid in tids:
            if tid == loop_tid:
                continue
            old = known.pop(tid, None)
            th = by_tid.get(tid)
            name = th.name if th is not None else f"native-{tid}"
            if old is not None:
                old.name = name
                tasks.append(old)
            else:
                tasks.append(_Task(tid, name, th.ident if th is not None else None, self._sched.open(tid)))
        # files of threads gone are closed one refresh later: the loop may still be reading the old list
        for fd in self._graveyard:
            os.close(fd)
        self._graveyard = [t.fd for t in known.values() if t.fd >= 0]
        self._tasks = tasks

    def _snapshot(self) -> dict[int, tuple[int, int]]:
        read = self._sched.read
        snap = {t.tid: read(t.fd) for t in self._tasks if t.tid != self._loop_tid}
        snap[0] = read(self._loop_fd)
        return snap

    def _account(self, t_ret: int, late: int) -> None:
        if threading.get_native_id() != self._loop_tid:  # first tick of a (re)started loop thread
            if self._loop_fd >= 0:
                self._graveyard.append(self._loop_fd)
            self._loop_tid = threading.get_native_id()
            self._loop_fd = self._sched.open(self._loop_tid)
            self._prev_ret = None
            return
        snap = self._snapshot()
        prev_ret, prev = self._prev_ret, self._prev_snap
        self._prev_ret, self._prev_snap = t_ret, snap
        if prev_ret is None or not prev:
            return
        self.periods += 1
        period = t_ret - prev_ret
        if late <= self.late_ns and period <= 2_000_000:
            # the loop thread's usual CPU per period (tick + spin), to tell a long tick from a normal one
            self._run_norm += ((snap[0][0] - prev[0][0]) - self._run_norm) * 0.01
            return
        self._explain(period, late, prev_ret, t_ret, prev, snap)

    def _explain(self, period: int, late: int, t0: int, t1: int, prev: dict[int, tuple[int, int]],
                 snap: dict[int, tuple[int, int]]) -> None:
        excess = max(late, period - 1_000_000)
        loop_run = snap[0][0] - prev[0][0]
        loop_wait = snap[0][1] - prev[0][1]
        blocked = max(0, period - loop_run - loop_wait - self._planned_sleep)
        others_cpu: dict[str, float] = {}
        others_wait: dict[str, float] = {}
        names: dict[str, _Task] = {}
        for t in self._tasks:
            a, b = prev.get(t.tid), snap.get(t.tid)
            if a is None or b is None:
                continue
            others_cpu[t.name] = others_cpu.get(t.name, 0.0) + (b[0] - a[0]) / 1000.0
            others_wait[t.name] = others_wait.get(t.name, 0.0) + (b[1] - a[1]) / 1000.0
            names[t.name] = t
        gc_ns = gc_loop_ns = 0
        for s, e, tid, _ in self._gc_log:
            if e > t0 and s < t1:
                gc_ns += min(e, t1) - max(s, t0)
                if tid == self._loop_tid:
                    gc_loop_ns += min(e, t1) - max(s, t0)
        busiest = max(others_cpu, key=others_cpu.__getitem__, default="")
        waitiest = max(others_wait, key=others_wait.__getitem__, default="")
        # what explains most of the excess
        scores = {
            "gc": gc_ns,
            "cpu-busy": loop_wait,
            "loop-work": loop_run - self._run_norm - gc_loop_ns,  # a pass in the loop thread counts as "gc"
            f"gil:{busiest}": min(blocked, others_cpu.get(busiest, 0.0) * 1000.0) if busiest else 0,
            f"gil-holder-preempted:{waitiest}": min(blocked,
                                                    others_wait.get(waitiest, 0.0) * 1000.0) if waitiest else 0,
        }
        cause, score = max(scores.items(), key=lambda kv: kv[1])
        if score < 0.3 * excess:
            cause = "machine"
        where = ""
        culprit = None
        if cause.startswith("gil:"):
            culprit = names.get(busiest)
        elif cause.startswith("gil-holder-preempted:"):
            culprit = names.get(waitiest)
        elif cause == "gc":
            passes = [(e - s, tid, gen) for s, e, tid, gen in self._gc_log if e > t0 and s < t1]
            _, gc_tid, gen = max(passes)
            culprit = next((t for t in self._tasks if t.tid == gc_tid), None)
            where = f"generation {gen} in the " + ("loop thread" if culprit is None else culprit.name)
            culprit = None
        if culprit is not None:
            where = culprit.name
            if culprit.ident is not None:
                frame = sys._current_frames().get(culprit.ident)
                if frame is not None:
                    where = f"{culprit.name}: {_frames(frame)}"
        self.causes[cause] += 1
        if period > 2_000_000:
            self.causes_over_2ms[cause] += 1
        if where:
            self.culprits[where] += 1
        if len(self.late) < self.keep:
            self.late.append(LatePeriod(
                period / 1000.0, late / 1000.0, cause, where, self._tick_ns / 1000.0, blocked / 1000.0,
                loop_wait / 1000.0,
                gc_ns / 1000.0, others_cpu, others_wait,
            ))


def _frames(frame: Any, depth: int = 3) -> str:
    """``fn (file:line) < caller (file:line) ...`` innermost first, paths shortened to the package."""
    out: list[str] = []
    f = frame
    while f is not None and len(out) < depth:
        code = f.f_code
        path = code.co_filename
        parts = path.replace("\\", "/").split("/")
        short = "/".join(parts[-2:])
        out.append(f"{code.co_name} ({short}:{f.f_lineno})")
        f = f.f_back
    return " < ".join(out)
