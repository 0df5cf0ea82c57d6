"""``haptic-study bench pipeline``, its first measurement: the per-tick cost of Algorithm 1 against NumPy.

Our :class:`pipeline.force.framework.HapticFramework` against a straightforward NumPy transcription of Algorithm 1
(one array per step, ``@``, ``np.linalg.norm``, a deque for the moving average), both fed the same raw wrenches and
poses recorded from the simulated rig (:func:`record_samples`, which the other measurements replay too).  The
outputs are cross-checked against each other.
"""

from __future__ import annotations

import gc
import statistics
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.assembly.sim_config import sim_rig_config
from pipeline.devices.interfaces import HapticState, PoseSample, WrenchSample
from pipeline.force.framework import FrameworkConfig, HapticFramework

__all__ = ["measure_pipeline_cost", "naive_numpy_pipeline", "record_samples", "time_batches"]


def record_samples(n: int, seed: int = 0) -> dict[str, Any]:
    """Run the simulated rig (scripted presses, virtual clock) and record ``n`` ticks of raw input.

    ``peak_force_n`` is the simulated haptic device's peak (its model's), the clamp of every framework here.
    """
    eng = build_sim_engine(EngineConfig(clock="virtual", sim=sim_rig_config(seed)))
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
        "peak_force_n": eng.rig.haptic.peak_force_n,
    }


def naive_numpy_pipeline(cal: Any, cfg: FrameworkConfig,
                         peak_n: float) -> Callable[[tuple[float, ...], tuple[float, ...]], np.ndarray]:
    """A line-by-line NumPy transcription of Algorithm 1 with compensation and safety, as a first draft would be."""
    A = np.array(cal.gravity_matrix).reshape(3, 3)
    fb = np.array(cal.force_bias_n)
    rts = np.array(cfg.rot_tip_sensor).reshape(3, 3)
    rhb = np.array(cfg.rot_haptic_base).reshape(3, 3)
    g_base = np.array([0.0, 0.0, -9.80665])
    buf: deque[np.ndarray] = deque(maxlen=cfg.filter_window)
    state: dict[str, Any] = {"prev": np.zeros(3), "gain": 0.0}
    limit = min(cfg.f_max_n, peak_n)
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


def time_batches(fn: Callable[[int, int], None], n: int, batch: int) -> list[float]:
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

    return statistics.median(time_batches(harness_run, len(raws), batch))


def _max_abs_diff_to_naive(data: dict[str, Any], cfg: FrameworkConfig, m: int) -> float:
    """Largest difference (N) of the rendered force, ours against the NumPy transcription, first ``m`` ticks.

    Untimed, on fresh state, driven as the loop drives it (``set_pose`` when the pose's timestamp changes).
    """
    raws, rots, pose_t = data["raw"], data["rot"], data["pose_t_ns"]
    fw = HapticFramework(cfg, data["calibration"], device_peak_n=data["peak_force_n"])
    check = naive_numpy_pipeline(data["calibration"], cfg, data["peak_force_n"])
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
        fw = HapticFramework(cfg, cal, device_peak_n=data["peak_force_n"])
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

    ours = time_batches(make_ours(False), n, batch)
    every = time_batches(make_ours(True), n, batch)

    naive_step = naive_numpy_pipeline(cal, cfg, data["peak_force_n"])

    def naive_run(a: int, b: int) -> None:
        for i in range(a, b):
            out = naive_step(raws[i], rots[i])
        del out

    m = min(n, 20 * batch)  # the slow one on a subset is enough for a median
    naive = time_batches(naive_run, m, batch)

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
