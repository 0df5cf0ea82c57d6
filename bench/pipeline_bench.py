"""``haptic-study bench pipeline``: the cost of Algorithm 1, the 1 kHz loop's timing, the filter trade.

Three measurements in one run, on the same recorded samples:

1. **Per-tick pipeline cost.** Our :class:`pipeline.force.framework.HapticFramework`
   against a straightforward NumPy transcription of Algorithm 1 (one array per
   step, ``@``, ``np.linalg.norm``, a deque for the moving average), both fed
   the same raw wrenches and poses recorded from the simulated rig.  The
   outputs are cross-checked against each other.
2. **Loop timing.** The real 1 kHz loop in the study-engine process (as the
   app runs it, without a GUI), paced on the monotonic clock for ``--loop-seconds``.
3. **Filter trade.** Moving-average window vs output noise RMS, group delay
   and step settling time: how users choose the window (speed vs accuracy).
4. **Both arms.** The loop's whole tick (every arm's devices read, watchdog, Algorithm 1, command, record
   into its ring) with two arms against one, replaying the same recorded inputs (the devices cost nothing:
   :func:`measure_arms_cost`); and the 1 kHz loop's p99 |period - 1 ms| with two simulated arms against one,
   alternating in the same run (:func:`measure_arms_loop`).
"""

from __future__ import annotations

import gc
import math
import platform
import statistics
import sys
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.machine import bare_loop_stats, cpu_times, engine_loop_health, format_late_ticks, load_average, steal_percent
from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.core.tick_record import TICK_DTYPE
from pipeline.devices.interfaces import HapticState, PoseSample, WrenchSample
from pipeline.devices.rig import RigArm
from pipeline.force.filters import MovingAverage3
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import SetHaptics
from pipeline.runtime.ring import RingBuffer

__all__ = ["filter_trade_table", "measure_arms_cost", "measure_arms_loop", "naive_numpy_pipeline", "record_samples",
           "run_pipeline_bench"]

#: The arms of the two-arm figures.
_TWO_ARMS = ("right", "left")


def record_samples(n: int, seed: int = 0) -> dict[str, Any]:
    """Run the simulated rig (scripted presses, virtual clock) and record ``n`` ticks of raw input."""
    eng = build_sim_engine(EngineConfig(clock="virtual", sim=_sim_cfg(seed)))
    loop = eng.loop
    raws: list[tuple[float, ...]] = []
    rots: list[tuple[float, ...]] = []
    pose_t_ns: list[int] = []
    true_f: list[float] = []
    samples: list[tuple[int, WrenchSample, PoseSample, HapticState]] = []
    for _ in range(n):
        loop.run_ticks(1)
        w = eng.rig.sensor.read_wrench()
        raws.append(tuple(w[1:7]))
        pose = eng.rig.robot.read_pose()
        rots.append(pose.rot_base_tip)
        pose_t_ns.append(pose.t_ns)
        true_f.append(eng.rig.true_contact_force()[2])
        samples.append((eng.clock.now_ns(), w, pose, eng.rig.haptic.read_state()))
    return {
        "raw": raws, "rot": rots, "pose_t_ns": pose_t_ns, "true_force_n": true_f,
        "calibration": eng.calibration, "engine": eng, "samples": samples,
    }


def _sim_cfg(seed: int) -> Any:
    from pipeline.sim.rig import SimRigConfig

    return SimRigConfig(seed=seed)


def naive_numpy_pipeline(cal: Any,
                         cfg: FrameworkConfig) -> Callable[[tuple[float, ...], tuple[float, ...]], np.ndarray]:
    """A line-by-line NumPy transcription of Algorithm 1 with compensation and safety, as a first draft would be."""
    A = np.array(cal.gravity_matrix).reshape(3, 3)
    fb = np.array(cal.force_bias_n)
    rts = np.array(cfg.rot_tip_sensor).reshape(3, 3)
    rhb = np.array(cfg.rot_haptic_base).reshape(3, 3)
    g_base = np.array([0.0, 0.0, -9.80665])
    buf: deque[np.ndarray] = deque(maxlen=cfg.filter_window)
    state: dict[str, Any] = {"prev": np.zeros(3), "gain": 0.0}
    limit = min(cfg.f_max_n, 3.3)
    slew = cfg.safety.slew_n_per_s * 0.001

    def step(raw: tuple[float, ...], rot: tuple[float, ...]) -> np.ndarray:
        f_meas = np.array(raw[:3])
        rbt = np.array(rot).reshape(3, 3)
        rot_sensor_base = (rbt @ rts).T
        g_s = rot_sensor_base @ g_base
        f_ext = f_meas - A @ g_s - fb
        buf.append(f_ext)
        f_filt = np.mean(np.array(buf), axis=0)
        f_tip = rts @ f_filt
        f_base = rbt @ f_tip
        f_h = rhb @ f_base
        n = np.linalg.norm(f_h)
        f_scaled = f_h / n * np.tanh(n / cfg.f_scale_n) * cfg.f_max_n if n > 0 else np.zeros(3)
        if not np.all(np.isfinite(f_scaled)):
            f_scaled = np.zeros(3)
        m = np.linalg.norm(f_scaled)
        if m > limit:
            f_scaled = f_scaled / m * limit
        d = f_scaled - state["prev"]
        dn = np.linalg.norm(d)
        if dn > slew:
            d = d / dn * slew
        out = state["prev"] + d
        state["prev"] = out
        state["gain"] = min(1.0, state["gain"] + 0.001 / cfg.safety.ramp_in_s)
        return out * state["gain"]

    return step


def _time_batches(fn: Callable[[int, int], None], n: int, batch: int) -> list[float]:
    """Per-call µs for consecutive batches of ``batch`` calls, after one untimed warm-up batch.

    The cyclic garbage collector is paused while a batch runs, as :mod:`timeit`
    does and as the engine process runs its loop (automatic collection off,
    collections in the quiet part of a tick).
    """
    out = []
    enabled = gc.isenabled()
    fn(0, batch)  # warm-up: caches, specialised bytecode, the allocator's free lists
    try:
        for start in range(0, n - batch + 1, batch):
            gc.disable()
            t0 = time.perf_counter_ns()
            fn(start, start + batch)
            t1 = time.perf_counter_ns()
            if enabled:
                gc.enable()
            out.append((t1 - t0) / batch / 1000.0)
    finally:
        if enabled:
            gc.enable()
    return out


def _harness_cost(data: dict[str, Any], batch: int) -> float:
    """Median per-tick cost (µs) of the timing harness alone, subtracted from both pipelines' figures.

    The harness is what both timed runs do besides the pipeline: indexing the
    recorded samples, the pose timestamp test, unpacking the sample.
    """
    raws, pose_t = data["raw"], data["pose_t_ns"]

    def harness_run(a: int, b: int) -> None:
        last_t = -1
        for i in range(a, b):
            t = pose_t[i]
            if t != last_t:
                last_t = t
            w = raws[i]
            out = (w[0], w[1], w[2], True, 0.001)
        del out

    return statistics.median(_time_batches(harness_run, len(raws), batch))


def _max_abs_diff_to_naive(data: dict[str, Any], cfg: FrameworkConfig, m: int) -> float:
    """Largest difference (N) of the rendered force, ours against the NumPy transcription, first ``m`` ticks.

    Untimed, on fresh state, driven as the loop drives it (``set_pose`` when the pose's timestamp changes).
    """
    raws, rots, pose_t = data["raw"], data["rot"], data["pose_t_ns"]
    fw = HapticFramework(cfg, data["calibration"])
    check = naive_numpy_pipeline(data["calibration"], cfg)
    diff = 0.0
    last_t = -1
    for i in range(m):
        if pose_t[i] != last_t:
            fw.set_pose(rots[i])
            last_t = pose_t[i]
        w = raws[i]
        got = fw.step(w[0], w[1], w[2], True, 0.001)
        want = check(raws[i], rots[i])
        diff = max(diff, *(abs(got[18 + k] - float(want[k])) for k in range(3)))
    return diff


def measure_pipeline_cost(data: dict[str, Any], cfg: FrameworkConfig, batch: int = 1000) -> dict[str, Any]:
    """Median per-tick cost of ours vs the NumPy transcription on the same samples, and their agreement.

    Ours is driven as :class:`pipeline.runtime.loop.HapticLoop` drives it: ``set_pose``
    whenever the robot reports a new pose (its timestamp changes, 125 Hz on a
    CB3, every 8th tick), ``step`` on every sample.  Each timed run keeps only
    the latest output, as the loop does (it writes each record into the ring
    and keeps nothing); keeping 20 000 records would time the memory they
    take.  Every run is preceded by one untimed warm-up batch, and the outputs
    are compared with the transcription's in a separate, untimed pass.
    """
    raws, rots, pose_t = data["raw"], data["rot"], data["pose_t_ns"]
    n = len(raws)
    cal = data["calibration"]

    def make_ours(pose_every_tick: bool) -> Callable[[int, int], None]:
        fw = HapticFramework(cfg, cal)
        step = fw.step
        set_pose = fw.set_pose

        def run(a: int, b: int) -> None:
            last_t = -1
            for i in range(a, b):
                t = pose_t[i]
                if pose_every_tick or t != last_t:
                    set_pose(rots[i])
                    last_t = t
                w = raws[i]
                out = step(w[0], w[1], w[2], True, 0.001)
            del out

        return run

    ours = _time_batches(make_ours(False), n, batch)
    every = _time_batches(make_ours(True), n, batch)

    naive_step = naive_numpy_pipeline(cal, cfg)

    def naive_run(a: int, b: int) -> None:
        for i in range(a, b):
            out = naive_step(raws[i], rots[i])
        del out

    m = min(n, 20 * batch)  # the slow one on a subset is enough for a median
    naive = _time_batches(naive_run, m, batch)

    harness = _harness_cost(data, batch)
    diff = _max_abs_diff_to_naive(data, cfg, m)
    pose_updates = sum(1 for i in range(1, n) if pose_t[i] != pose_t[i - 1])
    ours_med = statistics.median(ours) - harness
    naive_med = statistics.median(naive) - harness
    return {
        "ours_us_per_tick": round(ours_med, 3),
        "ours_pose_every_tick_us": round(statistics.median(every) - harness, 3),
        "naive_numpy_us_per_tick": round(naive_med, 3),
        "harness_overhead_us": round(harness, 3),
        "speedup": round(naive_med / ours_med, 1),
        "ours_vs_naive_max_abs_diff_n": diff,
        "ticks_timed": n,
        "pose_updates_per_tick": round(pose_updates / max(1, n - 1), 4),
    }


class _Replay:
    """A clock and the devices of any number of arms, replaying one recorded run tick by tick (no physics, no I/O).

    ``i`` is the tick to replay; :meth:`now_ns` is its recorded time, and every arm's sensor, robot and Touch
    read that tick's recorded sample.  What a loop commands is kept, not rendered.
    """

    range_n = (660.0, 660.0, 1980.0, 60.0, 60.0, 60.0)
    peak_force_n = 3.3
    command_timeout_s = 0.010

    def __init__(self, samples: list[tuple[int, WrenchSample, PoseSample, HapticState]], names: tuple[str, ...]):
        self.samples = samples
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


def _replay_loop(data: dict[str, Any], names: tuple[str, ...]) -> tuple[_Replay, HapticLoop]:
    """A loop over :class:`_Replay`'s arms, each with its own framework and ring, feedback on."""
    rep = _Replay(data["samples"], names)
    pipes = [(HapticFramework(FrameworkConfig(), data["calibration"]), RingBuffer.create(TICK_DTYPE, 30_000,
                                                                                         shared=False))
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
    runs = {k: _replay_loop(data, _TWO_ARMS[:k]) for k in (1, 2)}
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


def filter_trade_table(data: dict[str, Any],
                       windows: tuple[int, ...] = (1, 2, 5, 10, 20, 50, 100)) -> list[dict[str, float]]:
    """Window length vs output noise RMS, group delay and 2 % step settling time.

    Noise is the compensated force magnitude error while the simulated tool
    rests out of contact (the same recorded samples as the cost benchmark);
    group delay is the lag of the response to a 1 N/s ramp; settling is the
    time a 1 N step takes to stay within 2 %.
    """
    eng = data["engine"]
    fw0 = HapticFramework(FrameworkConfig(filter_window=1), data["calibration"])
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


def _arms_lines(r: dict[str, Any]) -> list[str]:
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
        *_arms_lines(r),
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
