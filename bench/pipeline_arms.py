"""``haptic-study bench pipeline``, both arms: the loop's whole tick and the 1 kHz loop with two arms against one.

The loop's whole tick (every arm's devices read, watchdog, Algorithm 1, command, record into its ring) with two arms
against one, replaying the same recorded inputs (the devices cost nothing: :func:`measure_arms_cost`); and the
1 kHz loop's p99 |period - 1 ms| with two simulated arms against one, alternating in the same run
(:func:`measure_arms_loop`).
"""

from __future__ import annotations

import gc
import math
import statistics
import time
from typing import Any

from bench.machine import engine_loop_health
from pipeline.core.tick_record import TICK_DTYPE
from pipeline.devices.interfaces import HapticState, PoseSample, WrenchSample
from pipeline.devices.rig import RigArm
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import SetHaptics
from pipeline.runtime.ring import RingBuffer

__all__ = ["arms_lines", "measure_arms_cost", "measure_arms_loop", "replay_loop"]

#: The arms of the two-arm figures.
_TWO_ARMS = ("right", "left")


class _Replay:
    """A clock and the devices of any number of arms, replaying one recorded run tick by tick (no physics, no I/O).

    ``i`` is the tick to replay; :meth:`now_ns` is its recorded time, and every arm's sensor, robot and Touch
    read that tick's recorded sample.  What a loop commands is kept, not rendered.
    """

    range_n = (660.0, 660.0, 1980.0, 60.0, 60.0, 60.0)
    command_timeout_s = 0.010

    def __init__(self, samples: list[tuple[int, WrenchSample, PoseSample, HapticState]], names: tuple[str, ...],
                 peak_force_n: float):
        self.samples = samples
        #: The recorded run's haptic device's peak force, N.
        self.peak_force_n = peak_force_n
        self.i = 0
        self.command = (0.0, 0.0, 0.0)
        self.arms = tuple(RigArm(name, self, self, self) for name in names)  # type: ignore[arg-type]
        self.sensor = self.robot = self.haptic = self

    def now_ns(self) -> int:
        return self.samples[self.i][0]

    def sleep_until(self, t_ns: int) -> None:
        pass

    def read_wrench(self) -> WrenchSample:
        return self.samples[self.i][1]

    def read_pose(self) -> PoseSample:
        return self.samples[self.i][2]

    def read_state(self) -> HapticState:
        return self.samples[self.i][3]

    def command_force(self, fx: float, fy: float, fz: float, t_ns: int | None = None) -> None:
        self.command = (fx, fy, fz)

    def rearm(self) -> bool:
        return True

    def advance(self, now_ns: int) -> None:
        pass

    def true_contact_force(self) -> None:
        return None

    def close(self) -> None:
        pass


def replay_loop(data: dict[str, Any], names: tuple[str, ...]) -> tuple[_Replay, HapticLoop]:
    """A loop over :class:`_Replay`'s arms, each with its own framework and ring, feedback on."""
    rep = _Replay(data["samples"], names, data["peak_force_n"])
    pipes = [(HapticFramework(FrameworkConfig(), data["calibration"], device_peak_n=rep.peak_force_n),
              RingBuffer.create(TICK_DTYPE, 30_000, shared=False))
             for _ in names]
    loop = HapticLoop(rep, pipes[0][0], rep, pipes[0][1], arm_pipelines=pipes[1:])  # type: ignore[arg-type]
    loop.submit(SetHaptics(True))
    return rep, loop


def measure_arms_cost(data: dict[str, Any], batch: int = 1000) -> dict[str, Any]:
    """Median cost of the loop's whole tick (:meth:`HapticLoop.tick`) with one arm and with two, µs.

    Both loops replay the same recorded run (:class:`_Replay`: every device read is a list lookup), in
    alternating batches so that both see the same machine; each arm has its own framework and ring.
    """
    n = len(data["samples"])
    runs = {k: replay_loop(data, _TWO_ARMS[:k]) for k in (1, 2)}
    times: dict[int, list[float]] = {1: [], 2: []}
    enabled = gc.isenabled()
    try:
        for start in range(0, n - batch + 1, batch):
            for k, (rep, loop) in runs.items():
                tick = loop.tick
                gc.disable()
                t0 = time.perf_counter_ns()
                for i in range(start, start + batch):
                    rep.i = i
                    tick()
                t1 = time.perf_counter_ns()
                if enabled:
                    gc.enable()
                if start:  # the first batch warms up
                    times[k].append((t1 - t0) / batch / 1000.0)
    finally:
        if enabled:
            gc.enable()
    one, two = statistics.median(times[1]), statistics.median(times[2])
    return {"arms_tick_one_us": round(one, 3), "arms_tick_two_us": round(two, 3),
            "arms_cost_ratio": round(two / one, 3), "arms_ticks_timed": len(times[1]) * batch}


def measure_arms_loop(seconds: float, segment_s: float = 5.0) -> dict[str, Any]:
    """The 1 kHz loop where a study runs it -- the study-engine process, SCHED_FIFO where allowed, the engine's driver
    draining the rings -- with the simulated rig of one arm and of two, alternating in segments of ``segment_s`` until
    each ran ``seconds / 2``; p99 |period - 1 ms| of each.

    Each segment is a fresh engine process (:func:`bench.machine.engine_loop_health`); a configuration's figure is the
    median of its segments' p99s (the engine reports a summary, not its histogram), and every segment's p99 is kept.
    """
    per = max(segment_s, 1.0)
    segments = max(1, round(seconds / 2 / per))
    each = seconds / 2 / segments
    p99: dict[int, list[float]] = {1: [], 2: []}
    over: dict[int, float] = {1: 0.0, 2: 0.0}
    ticks: dict[int, float] = {1: 0.0, 2: 0.0}
    for _ in range(segments):
        for k in (1, 2):
            _, last, _ = engine_loop_health(each, False, _TWO_ARMS[:k])
            p99[k].append(float(last.abs_dev_p99_us))
            over[k] += float(last.periods_over_2ms)
            ticks[k] += float(last.ticks)
    return {
        "arms_loop_seconds_each": round(seconds / 2, 3), "arms_loop_segments": segments,
        "arms_loop_one_abs_dev_p99_us": statistics.median(p99[1]),
        "arms_loop_two_abs_dev_p99_us": statistics.median(p99[2]),
        "arms_loop_one_segments_p99_us": p99[1], "arms_loop_two_segments_p99_us": p99[2],
        "arms_loop_one_over_2ms": over[1], "arms_loop_two_over_2ms": over[2],
        "arms_loop_one_ticks": ticks[1], "arms_loop_two_ticks": ticks[2],
    }


def arms_lines(r: dict[str, Any]) -> list[str]:
    ratio = r["arms_cost_ratio"]
    lines = [
        "Both arms of the rig (each arm: devices read, watchdog, Algorithm 1, command, its own ring):",
        f"  loop tick, one arm        {r['arms_tick_one_us']:8.3f} µs   (median, recorded inputs replayed)",
        f"  loop tick, two arms       {r['arms_tick_two_us']:8.3f} µs   = {ratio:.2f}x one arm "
        f"({'within' if ratio <= 2.2 else 'OVER'} the 2.2x target)",
    ]
    if r.get("arms_loop_one_ticks"):
        one, two = r["arms_loop_one_abs_dev_p99_us"], r["arms_loop_two_abs_dev_p99_us"]
        rel = (two - one) / one * 100.0 if one else math.nan
        lines += [
            f"  1 kHz loop in the study-engine process (simulated arms), {r['arms_loop_seconds_each']:g} s each, "
            f"alternating in {r['arms_loop_segments']} segments (median of the segments; 1 µs bins):",
            f"  p99 |period - 1 ms|       one arm {one:.0f} µs, two arms {two:.0f} µs ({rel:+.0f} %; target within "
            f"10 %)",
            *([f"  each segment's p99        one arm {_us_list(r['arms_loop_one_segments_p99_us'])}, two arms "
               f"{_us_list(r['arms_loop_two_segments_p99_us'])}"] if "arms_loop_one_segments_p99_us" in r else []),
            f"  periods over 2 ms         one arm {r['arms_loop_one_over_2ms']:.0f}, two arms "
            f"{r['arms_loop_two_over_2ms']:.0f}",
        ]
    return lines


def _us_list(values: list[float]) -> str:
    return " / ".join(f"{v:.0f}" for v in values) + " µs"
