"""``haptic-study bench pipeline``: the cost of Algorithm 1, the 1 kHz loop's timing, the filter trade.

Three measurements in one run, on the same recorded samples:

1. **Per-tick pipeline cost.** Our :class:`pipeline.force.framework.HapticFramework`
   against a straightforward NumPy transcription of Algorithm 1, both fed
   the same raw wrenches and poses recorded from the simulated rig
   (:mod:`bench.pipeline_cost`).
2. **Loop timing.** The real 1 kHz loop in the study-engine process (as the
   app runs it, without a GUI), paced on the monotonic clock for ``--loop-seconds``.
3. **Filter trade.** Moving-average window vs output noise RMS, group delay
   and step settling time: how users choose the window (speed vs accuracy).
4. **Both arms.** The loop's whole tick with two arms against one, replaying the same recorded inputs, and
   the 1 kHz loop with two simulated arms against one (:mod:`bench.pipeline_arms`).

Another version's figures, measured in turn with ours in the same run, are :mod:`bench.pipeline_reference`'s.
"""

from __future__ import annotations

import math
import platform
import statistics
import sys
from collections.abc import Callable
from typing import Any

from bench.machine import bare_loop_stats, cpu_times, engine_loop_health, format_late_ticks, load_average, steal_percent
from bench.pipeline_arms import arms_lines, measure_arms_cost, measure_arms_loop
from bench.pipeline_cost import measure_pipeline_cost, record_samples
from pipeline.force.filters import MovingAverage3
from pipeline.force.framework import FrameworkConfig, HapticFramework

__all__ = ["filter_trade_table", "format_pipeline_bench", "measure_loop", "run_pipeline_bench"]


def filter_trade_table(data: dict[str, Any],
                       windows: tuple[int, ...] = (1, 2, 5, 10, 20, 50, 100)) -> list[dict[str, float]]:
    """Window length vs output noise RMS, group delay and 2 % step settling time.

    Noise is the compensated force magnitude error while the simulated tool
    rests out of contact (the same recorded samples as the cost benchmark);
    group delay is the lag of the response to a 1 N/s ramp; settling is the
    time a 1 N step takes to stay within 2 %.
    """
    eng = data["engine"]
    fw0 = HapticFramework(FrameworkConfig(filter_window=1), data["calibration"], device_peak_n=data["peak_force_n"])
    rest: list[tuple[float, float, float]] = []
    last = None
    for raw, rot, tf in zip(data["raw"], data["rot"], data["true_force_n"], strict=True):
        if rot is not last:
            fw0.set_pose(rot)
            last = rot
        out = fw0.step(raw[0], raw[1], raw[2], False, 0.001)
        if tf == 0.0:
            rest.append((out[0], out[1], out[2]))
    del eng
    mean = [statistics.fmean(c) for c in zip(*rest, strict=True)]
    rows = []
    for w in windows:
        ma = MovingAverage3(w)
        sq = []
        for i, (x, y, z) in enumerate(rest):
            mx, my, mz = ma.update(x - mean[0], y - mean[1], z - mean[2])
            if i >= w:
                sq.append(mx * mx + my * my + mz * mz)
        noise = math.sqrt(statistics.fmean(sq)) if sq else math.nan
        ma = MovingAverage3(w)
        lag = 0.0
        for k in range(1000):
            x = k * 0.001
            y = ma.update(x, 0.0, 0.0)[0]
            lag = (x - y) / 0.001  # samples behind the ramp
        ma = MovingAverage3(w)
        for _ in range(w):
            ma.update(0.0, 0.0, 0.0)
        settle: int | None = None
        for k in range(2 * w + 10):  # k = samples since the 1 N step
            y = ma.update(1.0, 0.0, 0.0)[0]
            settle = (k if settle is None else settle) if abs(y - 1.0) <= 0.02 else None
        rows.append(
            {
                "window": float(w),
                "noise_rms_n": round(noise, 5),
                "group_delay_ms": round(lag, 3),
                "settling_ms": float(settle) if settle is not None else math.nan,
            }
        )
    return rows


def measure_loop(seconds: float, explain: bool = False) -> dict[str, Any]:
    """Run the real 1 kHz loop in the study-engine process for ``seconds`` and return its period statistics.

    The engine is the app's own (:class:`study_app.engine.client.EngineClient`:
    the simulated rig, the loop in its thread, the engine's driver draining the
    ring beside it), without a GUI (``bench gui`` adds one).  With ``explain``
    the engine traces every late tick's cause
    (:class:`pipeline.runtime.jitter_trace.LateTickTracer`, ~30 µs per tick, which
    shows in the p99).  The share of CPU time the hypervisor stole and the
    load average are reported either way.
    """
    first, last, cpu0 = engine_loop_health(seconds, explain)
    steal = steal_percent(cpu0, cpu_times())
    out: dict[str, Any] = {
        "ticks": last.ticks, "period_p50_us": last.period_p50_us, "period_p99_us": last.period_p99_us,
        "abs_dev_p99_us": last.abs_dev_p99_us, "period_max_us": last.period_max_us,
        "periods_over_2ms": last.periods_over_2ms, "missed_slots": last.missed_slots - first.missed_slots,
        "scheduling": last.scheduling, "steal_percent": steal, "load_average": load_average(),
    }
    if last.late_periods is not None:
        out["late_ticks"] = last.late_periods
    return out


def run_pipeline_bench(
    loop_seconds: float = 30.0,
    ticks: int = 20_000,
    progress: Callable[[str], None] | None = None,
    explain: bool = False,
    reference: bool = False,
) -> dict[str, Any]:
    """All three measurements; returns the JSON-ready result.

    ``explain``: see :func:`measure_loop`.  ``reference``: afterwards, run a
    loop with nothing in its tick for as long (:func:`bench.machine.bare_loop_stats`),
    the machine's own floor for the loop figures.
    """
    say = progress or (lambda s: None)
    say("recording samples from the simulated rig")
    data = record_samples(ticks)
    say("timing the pipeline (ours vs NumPy transcription)")
    cost = measure_pipeline_cost(data, FrameworkConfig())
    say("filter trade table")
    trade = filter_trade_table(data)
    say("timing the loop's tick with two arms against one (the same recorded inputs)")
    arms = measure_arms_cost(data)
    say(f"running the 1 kHz loop for {loop_seconds:g} s in the study-engine process")
    stats = measure_loop(loop_seconds, explain) if loop_seconds > 0 else {}
    if loop_seconds > 0:
        say(f"running the 1 kHz loop with one arm and with two, alternating, {loop_seconds:g} s in all")
        arms.update(measure_arms_loop(loop_seconds))
    bare: dict[str, Any] | None = None
    if reference and loop_seconds > 0:
        say(f"running an empty reference loop for {loop_seconds:g} s: the machine's own floor")
        bare = bare_loop_stats(loop_seconds)
    result: dict[str, Any] = dict(cost)
    result.update(arms)
    result.update(
        {
            "loop_seconds": loop_seconds,
            "loop_period_p50_us": stats.get("period_p50_us"),
            "loop_period_p99_us": stats.get("period_p99_us"),
            "loop_abs_dev_p99_us": stats.get("abs_dev_p99_us"),
            "loop_period_max_us": stats.get("period_max_us"),
            "loop_periods_over_2ms": stats.get("periods_over_2ms"),
            "loop_missed_slots": stats.get("missed_slots"),
            "loop_ticks": stats.get("ticks"),
            "loop_scheduling": stats.get("scheduling", ""),
            "loop_steal_percent": stats.get("steal_percent"),
            "loop_load_average": stats.get("load_average"),
            "loop_late_ticks": stats.get("late_ticks"),
            "bare_loop": bare,
            "filter_trade": trade,
            "python": sys.version.split()[0],
            "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        }
    )
    return result


def _loop_lines(r: dict[str, Any]) -> list[str]:
    if r["loop_ticks"] is None:
        return ["1 kHz loop: not run (--loop-seconds 0)"]
    return [
        f"1 kHz loop in the study-engine process, {r['loop_seconds']:g} s of real time "
        f"({r.get('loop_scheduling') or 'normal'}):",
        f"  period p50 / p99 / max    {r['loop_period_p50_us']:.0f} / {r['loop_period_p99_us']:.0f} / "
        f"{r['loop_period_max_us']:.0f} µs",
        f"  p99 |period - 1 ms|       {r['loop_abs_dev_p99_us']:.0f} µs",
        f"  periods over 2 ms         {r['loop_periods_over_2ms']:.0f}   (missed slots {r['loop_missed_slots']:.0f})",
        *_machine_lines(r),
    ]


def _machine_lines(r: dict[str, Any]) -> list[str]:
    lines = []
    if r.get("loop_load_average") is not None:
        steal = r.get("loop_steal_percent")
        lines.append(
            f"  machine                   load {r['loop_load_average'][0]:.2f}"
            + ("" if steal is None else f", CPU stolen by the hypervisor {steal:.1f} %")
        )
    if r.get("loop_late_ticks"):
        lines.append(format_late_ticks(r["loop_late_ticks"], indent="  "))
    b = r.get("bare_loop")
    if b:
        lines.append(
            f"  empty reference loop, the next {r['loop_seconds']:g} s: p99 |period - 1 ms| {b['abs_dev_p99_us']:.0f} "
            f"µs, max {b['period_max_us']:.0f} µs, periods over 2 ms {b['periods_over_2ms']:.0f}"
        )
    return lines


def format_pipeline_bench(r: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_pipeline_bench`."""
    lines = [
        "Per-tick pipeline (compensation + filter + 3 rotations + scaling + safety), median µs:",
        f"  ours                      {r['ours_us_per_tick']:8.3f}   (pose change every tick: "
        f"{r['ours_pose_every_tick_us']:.3f})",
        f"  NumPy transcription       {r['naive_numpy_us_per_tick']:8.3f}",
        f"  speed-up                  {r['speedup']:8.1f}x   "
        f"(outputs agree to {r['ours_vs_naive_max_abs_diff_n']:.2e} N)",
        f"  (timing-harness overhead of {r['harness_overhead_us']:.3f} µs per tick subtracted from both)",
        "",
        *_loop_lines(r),
        "",
        *arms_lines(r),
        "",
        "Moving-average window: speed against accuracy",
        "  window  noise RMS (N)  group delay (ms)  2% settling (ms)",
    ]
    for row in r["filter_trade"]:
        lines.append(
            f"  {row['window']:6.0f}  {row['noise_rms_n']:13.5f}  {row['group_delay_ms']:16.1f}  "
            f"{row['settling_ms']:16.0f}"
        )
    return "\n".join(lines)
