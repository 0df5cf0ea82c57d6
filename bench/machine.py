"""What the machine did during a timing benchmark: CPU stolen by the hypervisor, load, late-tick causes.

Shared by the loop-timing benchmarks (``bench pipeline``, ``bench gui``): a
loop's period statistics mean little without knowing whether the machine was
quiet, and on a shared virtual machine the hypervisor takes the CPU away in
bursts that no process can cause or cure.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import time
from typing import Any

from foundation.platform_support.machine import cpu_times
from foundation.platform_support.machine import load_average as load_avg
from pipeline.core.clock import MonotonicClock, prepare_realtime_thread
from pipeline.runtime.loop_stats import LoopStats
from study_app.engine import messages as m
from study_app.engine.client import EngineClient
from study_app.engine.setup import HostConfig

__all__ = ["bare_loop_stats", "cpu_times", "format_late_ticks", "load_average", "steal_percent"]


def steal_percent(before: list[int] | None, after: list[int] | None) -> float | None:
    """Share of all CPU time between two :func:`cpu_times` readings that the hypervisor stole, %."""
    if before is None or after is None:
        return None
    total = sum(after) - sum(before)
    return round(100.0 * (after[7] - before[7]) / total, 1) if total > 0 else None


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages, rounded to 0.01."""
    return [round(x, 2) for x in load_avg() or (float("nan"),) * 3]


def format_late_ticks(late: dict[str, Any], indent: str = "      ") -> str:
    """One or more lines from a :meth:`pipeline.runtime.jitter_trace.LateTickTracer.summary`: late ticks by cause."""
    causes = ", ".join(f"{k} {v}" for k, v in late["causes"].items()) or "none"
    text = (f"{indent}ticks > {late['late_threshold_us']:.0f} µs late: {late['late_ticks']} ({causes}); "
            "periods > 2 ms by cause: "
            + (", ".join(f"{k} {v}" for k, v in late["causes_over_2ms"].items()) or "none"))
    text += "".join(f"\n{indent}  {n} × {where}" for where, n in list(late["culprits"].items())[:3])
    return text


def _bare_loop(seconds: float, out: Any) -> None:
    scheduling = prepare_realtime_thread()
    clock = MonotonicClock()
    stats = LoopStats(1_000_000)
    t = deadline = clock.now_ns()
    for _ in range(int(seconds * 1000)):
        deadline += 1_000_000
        clock.sleep_until(deadline)
        now = clock.now_ns()
        stats.add(now - t)
        t = now
    out.put({**stats.summary(), "scheduling": scheduling})


def bare_loop_stats(seconds: float) -> dict[str, Any]:
    """The machine's own floor: a loop with nothing in its tick, paced and scheduled as the haptic loop is.

    Same clock (:class:`pipeline.core.clock.MonotonicClock`: sleep, then spin),
    same thread preparation (``SCHED_FIFO``, 1 ns timer slack) and the same
    statistics (:class:`pipeline.runtime.loop.LoopStats`), in a process of its own.
    Periods over 2 ms here are the machine's (a late timer, the hypervisor),
    since there is nothing else to be late for.
    """
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    proc = ctx.Process(target=_bare_loop, args=(seconds, q), name="bare-loop", daemon=True)
    proc.start()
    try:
        result: dict[str, Any] = q.get(timeout=seconds * 3 + 30)
    finally:
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
    return result


def engine_loop_health(seconds: float, explain: bool, sim_arms: tuple[str, ...] | None = None,
                       ) -> tuple[m.Health, m.Health, list[int] | None]:
    """Run the study engine (simulated rig, real clock, no GUI) for ``seconds`` after a timing reset.

    Returns the first :class:`study_app.engine.messages.Health` after the reset, the first one published after
    ``seconds`` (its timing covers the whole window), and the CPU times at the window's start
    (:func:`cpu_times`).  ``explain``: trace every late tick's cause (``HostConfig.trace_jitter``).
    ``sim_arms``: the simulated rig's arms by name (``HostConfig.sim_arms``; None: the one-arm rig).
    """
    cfg = HostConfig(clock="real", trace_jitter=explain)
    client = EngineClient(cfg if sim_arms is None else dataclasses.replace(cfg, sim_arms=sim_arms))
    try:
        client.wait_ready(60.0)
        client.send(m.ResetStats())
        first: m.Health | None = None
        while first is None:  # the loop's missed slots count from start-up: the caller takes the difference
            ev = client.get(1.0)
            first = ev if isinstance(ev, m.Health) else None
        cpu0 = cpu_times()
        t_end = time.monotonic() + seconds
        last: m.Health | None = None
        while last is None:
            ev = client.get(0.2)
            if isinstance(ev, m.Health) and time.monotonic() >= t_end:
                last = ev
        return first, last, cpu0
    finally:
        client.shutdown()
