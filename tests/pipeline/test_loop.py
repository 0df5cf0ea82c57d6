"""The 1 kHz haptic loop on the virtual clock: statistics, pacing, commands, ramp-down, determinism, force bound."""

from __future__ import annotations

import dataclasses
import math
import threading

import numpy as np
import pytest
from drivers import PressAndHold

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import Fault
from pipeline.devices.registry import haptic_model
from pipeline.force.config import FrameworkConfig, SafetyConfig
from pipeline.runtime.loop_messages import RECORD_FIELDS, ControllerDetached, Mark, OperatorStop, SetHaptics
from pipeline.runtime.loop_stats import LoopStats
from pipeline.sim.hand import ScriptedPresses
from pipeline.sim.rig import SimRigConfig

PERIOD_NS = 1_000_000
DT_S = PERIOD_NS * 1e-9
SAFETY = SafetyConfig()
RAMP_TICKS = round(SAFETY.fault_ramp_s / DT_S)  # 40: gain 1 → exactly 0
RAMP_IN_TICKS = round(SAFETY.ramp_in_s / DT_S)  # 500: gain 0 → exactly 1
RENDER = ("render_fx", "render_fy", "render_fz")




def press_engine(**config) -> Engine:
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", **config))
    eng.rig.set_driver(PressAndHold())
    return eng


def ticks(eng: Engine, n: int) -> list[dict[str, float]]:
    out = []
    for _ in range(n):
        t_ns = eng.clock.now_ns()
        eng.loop.run_ticks(1)
        rec = eng.loop.last_record
        rec["clock_ns"] = t_ns
        rec["cmd"] = eng.rig.haptic.output.commanded
        out.append(rec)
    return out


def render_mag(rec) -> float:
    return math.hypot(rec["render_fx"], rec["render_fy"], rec["render_fz"])


def row_times_ns(rows: np.ndarray) -> np.ndarray:
    """Record times in integer ns (on the loop's time axis; only differences are compared)."""
    return np.round(rows["t_s"] * 1e9).astype(np.int64)


def all_rows(eng: Engine) -> np.ndarray:
    ring = eng.ring
    assert ring.write_count <= ring.capacity
    r = ring.read_since(0)
    assert r.lost == 0
    return r.rows


@pytest.fixture
def steady() -> Engine:
    """Pressing ~2 mm into the tissue with feedback fully on (rendered force ≈ 0.45 N)."""
    eng = press_engine()
    recs = ticks(eng, 1500)
    assert all(r["faults"] == 0.0 for r in recs)
    assert all(r["gain"] == 1.0 and render_mag(r) > 0.3 for r in recs[-300:])
    return eng


# -- LoopStats --------------------------------------------------------------------------------------
def test_loop_stats_quantiles_on_a_constructed_sequence():
    s = LoopStats(PERIOD_NS)
    for _ in range(98):
        s.add(1_000_000)
    s.add(1_500_000)
    s.add(2_500_000)
    assert s.summary() == {
        "ticks": 100.0,
        "period_p50_us": 1000.0,
        "period_p99_us": 1500.0,  # 99th of 100 sorted periods
        "period_max_us": 2500.0,
        "abs_dev_p99_us": 500.0,  # deviations: 98 × 0, 500, 1500
        "periods_over_2ms": 1.0,
        "missed_slots": 0.0,
    }


def test_loop_stats_counts_the_nominal_period_as_any_other():
    """add only counts a period equal to the nominal one; every figure is what the histogram path gives."""
    slow = LoopStats(3_000_000)  # a nominal period over 2 ms: its ticks count there too
    for p in (3_000_000, 3_000_000, 3_000_400, 3_000_000):
        slow.add(p)
    assert (slow.count, slow.max_ns, slow.over_2ms) == (4, 3_000_400, 4)
    # exact: the quantiles are bin indices of a 1 µs integer histogram, no float arithmetic reaches them
    assert slow.summary()["period_p50_us"] == 3000.0 and slow.summary()["abs_dev_p99_us"] == 0.0
    only = LoopStats(PERIOD_NS)
    only.add(PERIOD_NS)
    assert (only.count, only.max_ns, only.over_2ms) == (1, PERIOD_NS, 0)
    only.reset()
    assert (only.count, only.max_ns, only.summary()["ticks"]) == (0, 0, 0.0)


def test_loop_stats_edges():
    s = LoopStats(PERIOD_NS)
    summary = s.summary()
    assert summary["ticks"] == 0.0 and summary["period_max_us"] == 0.0
    assert math.isnan(summary["period_p50_us"]) and math.isnan(summary["period_p99_us"])

    for _ in range(50):
        s.add(999_999)  # truncated to the 999 µs bin
    for _ in range(50):
        s.add(2_000_000)  # exactly 2 ms is not "over 2 ms"
    out = s.summary()
    assert out["period_p50_us"] == 999.0  # the lower median
    assert out["period_p99_us"] == 2000.0
    assert out["period_max_us"] == 2000.0
    assert out["periods_over_2ms"] == 0.0
    assert out["abs_dev_p99_us"] == 1000.0

    s.add(2_000_001)
    s.add(80_000_000)  # beyond the 50 ms histogram: the overflow bin, but max is exact
    out = s.summary()
    assert out["periods_over_2ms"] == 2.0
    assert out["period_max_us"] == 80_000.0
    assert s.count == 102

    s.reset()
    assert s.count == 0 and s.max_ns == 0 and s.over_2ms == 0 and s.missed_slots == 0
    s.add(1_000_000)
    assert s.summary()["period_p99_us"] == 1000.0


def test_loop_stats_overflow_bin_quantile():
    s = LoopStats(PERIOD_NS)
    for _ in range(10):
        s.add(60_000_000)
    out = s.summary()
    assert out["period_p50_us"] == 50_000.0  # the last (overflow) bin
    assert out["period_max_us"] == 60_000.0


# -- pacing --------------------------------------------------------------------------------------------
def test_run_on_virtual_clock_has_exact_1ms_period_including_the_ramp_down():
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="scripted", calibrate=False))
    loop = eng.loop
    loop.run(max_ticks=1000)

    # feedback was fully on (gain 1 after 0.5 s): the ramp-down takes RAMP_TICKS more ticks
    assert loop.tick_count == 1000 + RAMP_TICKS
    rows = all_rows(eng)
    assert len(rows) == loop.tick_count
    np.testing.assert_array_equal(rows["tick"], np.arange(loop.tick_count, dtype=float))
    times = row_times_ns(rows)
    np.testing.assert_array_equal(times - times[0], PERIOD_NS * np.arange(loop.tick_count))
    np.testing.assert_array_equal(rows["period_ns"], np.full(loop.tick_count, float(PERIOD_NS)))
    assert rows["gain"][999] == 1.0
    assert np.all(rows["haptic_on"][1000:] == 0.0)
    assert rows["gain"][-1] == 0.0 and np.all(rows["gain"][1000:-1] > 0.0)
    assert eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)

    s = loop.stats.summary()
    assert s["ticks"] == loop.tick_count - 1  # periods between ticks
    assert s["period_p50_us"] == 1000.0
    assert s["period_p99_us"] == 1000.0
    assert s["period_max_us"] == 1000.0
    assert s["abs_dev_p99_us"] == 0.0
    assert s["periods_over_2ms"] == 0.0
    assert s["missed_slots"] == 0.0


def test_run_stops_on_the_stop_event():
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", calibrate=False, haptics_on=False))
    stop = threading.Event()
    loop = eng.loop

    def observer(ev):  # stop from "another thread" after a fault: here, an operator stop at tick 0
        stop.set()

    loop.on_event = observer
    loop.submit(OperatorStop())
    loop.run(stop, max_ticks=10_000)
    assert loop.tick_count == 1  # gain was 0: no ramp-down ticks needed
    assert loop.faults == Fault.OPERATOR_STOP


def test_between_ticks_runs_after_every_tick_before_the_sleep_and_not_during_the_ramp_down():
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="scripted", calibrate=False))
    loop, clock = eng.loop, eng.clock
    seen: list[tuple[int, int]] = []
    loop.run(max_ticks=50, between_ticks=lambda: seen.append((loop.tick_count, clock.now_ns())))
    t0 = seen[0][1]
    # after tick k (count k), still at that tick's time: the rest of the period is the hook's
    assert seen == [(k + 1, t0 + k * PERIOD_NS) for k in range(50)]
    assert loop.tick_count > 50  # the ramp-down ticks ran without it


def test_a_failing_between_ticks_hook_still_ramps_the_force_down():
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="scripted", calibrate=False))
    loop = eng.loop

    def boom() -> None:
        if loop.tick_count == 600:
            raise RuntimeError("housekeeping failed")

    with pytest.raises(RuntimeError, match="housekeeping failed"):
        loop.run(max_ticks=1000, between_ticks=boom)
    assert loop.framework.safety.gain == 0.0
    assert eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)


def test_a_stall_counts_missed_slots_and_keeps_the_deadline_grid():
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", calibrate=False, haptics_on=False))
    loop, clock = eng.loop, eng.clock
    assert isinstance(clock, VirtualClock)
    real_advance = eng.rig.advance

    def stalling_advance(now_ns: int) -> None:
        real_advance(now_ns)
        if loop.tick_count == 100:
            clock.advance(3_500_000)  # tick 100 takes 3.5 ms

    eng.rig.advance = stalling_advance
    loop.run(max_ticks=200)

    times = row_times_ns(all_rows(eng))
    times -= times[0]
    assert list(times[:101]) == [k * PERIOD_NS for k in range(101)]
    # slots 101 and 102 are skipped, tick 101 runs late at 103.5 ms, then back on the grid
    assert times[101] == 100 * PERIOD_NS + 3_500_000
    assert list(times[102:]) == [k * PERIOD_NS for k in range(104, 104 + 98)]
    s = loop.stats.summary()
    assert s["missed_slots"] == 2.0
    assert s["periods_over_2ms"] == 1.0  # 100 → 103.5 ms
    assert s["period_max_us"] == 3500.0
    assert s["ticks"] == 199.0
    # the late tick's own period is what the record says
    assert all_rows(eng)["period_ns"][101] == 3_500_000


# -- commands ------------------------------------------------------------------------------------------
def test_mark_and_set_haptics_apply_from_the_next_tick(steady):
    eng = steady
    loop = eng.loop
    before = loop.last_record
    assert before["trial_index"] == -1.0 and before["phase"] == 0.0 and before["haptic_on"] == 1.0
    c = eng.ring.write_count

    loop.submit(Mark(3, 7))
    assert loop.trial_index == -1  # queued, not applied
    ticks(eng, 2)
    loop.submit(SetHaptics(False))
    loop.submit(Mark(4, 2))
    ticks(eng, 2)

    rows = eng.ring.read_since(c).rows
    assert list(rows["trial_index"]) == [3.0, 3.0, 4.0, 4.0]
    assert list(rows["phase"]) == [7.0, 7.0, 2.0, 2.0]
    assert list(rows["haptic_on"]) == [1.0, 1.0, 0.0, 0.0]
    assert list(rows["tick"]) == [float(c + k) for k in range(4)]


def test_haptics_off_ramps_rendered_force_to_exactly_zero_while_the_pipeline_runs(steady):
    eng = steady
    eng.loop.submit(SetHaptics(False))
    recs = ticks(eng, 300)

    zero_i = next(i for i, r in enumerate(recs) if all(r[k] == 0.0 for k in RENDER))
    assert zero_i == RAMP_TICKS - 1  # exactly zero on the 40th tick: within fault_ramp_s
    assert (zero_i + 1) * DT_S <= SAFETY.fault_ramp_s + 1e-12
    for k in range(zero_i):
        assert recs[k]["gain"] == pytest.approx(1.0 - (k + 1) / RAMP_TICKS, abs=1e-9)
        assert render_mag(recs[k]) > 0.0
    for r in recs[zero_i:]:
        assert r["gain"] == 0.0 and r["cmd"] == (0.0, 0.0, 0.0)
        assert all(r[k] == 0.0 for k in RENDER)
        assert r["faults"] == 0.0 and r["haptic_on"] == 0.0
        # the rest of Algorithm 1 keeps running for the record while the hand presses
        assert abs(r["comp_fz"]) > 0.5 and abs(r["filt_fz"]) > 0.5
        assert r["force_n"] == pytest.approx(math.hypot(r["filt_fx"], r["filt_fy"], r["filt_fz"]), rel=1e-12)
        assert math.hypot(r["scaled_fx"], r["scaled_fy"], r["scaled_fz"]) > 0.3
        assert r["true_fz"] > 0.5
    assert len(eng.loop.events) == 0  # feedback off is not a fault

    # and back on: it fades in over ramp_in_s
    eng.loop.submit(SetHaptics(True))
    back = ticks(eng, RAMP_IN_TICKS + 10)
    assert back[0]["gain"] == pytest.approx(1 / RAMP_IN_TICKS, abs=1e-12)
    assert [r["gain"] for r in back].index(1.0) == RAMP_IN_TICKS - 1
    assert render_mag(back[-1]) > 0.3


def test_ramp_down_ends_with_the_device_commanded_to_zero(steady):
    eng = steady
    loop = eng.loop
    assert eng.rig.haptic.output.commanded != (0.0, 0.0, 0.0)
    n0 = loop.tick_count
    c = eng.ring.write_count
    loop.ramp_down()
    assert loop.tick_count - n0 == RAMP_TICKS
    assert loop.haptic_on is False
    assert eng.framework.safety.gain == 0.0
    assert eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)
    rows = eng.ring.read_since(c - 1).rows  # the last tick before the ramp-down, then the ramp
    assert len(rows) == RAMP_TICKS + 1
    assert rows["render_fx"][-1] == 0.0 and rows["render_fy"][-1] == 0.0 and rows["render_fz"][-1] == 0.0
    # the ramp ticks keep the 1 ms grid: the first one at the next slot, not one slot later
    assert np.all(np.diff(row_times_ns(rows)) == PERIOD_NS)
    np.testing.assert_array_equal(rows["period_ns"][1:], np.full(RAMP_TICKS, float(PERIOD_NS)))
    # the device actually renders nothing from its next servo step on
    eng.rig.advance(eng.clock.now_ns())
    assert eng.rig.haptic.applied_force_n == (0.0, 0.0, 0.0)
    # idempotent: nothing left to ramp
    loop.ramp_down()
    assert loop.tick_count - n0 == RAMP_TICKS


def test_ramp_down_applies_commands_queued_before_the_stop():
    """A ControllerDetached queued together with the stop must still be latched (engine detach path)."""
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="hold", calibrate=False, haptics_on=False))
    loop = eng.loop
    loop.run_ticks(10)
    assert eng.framework.safety.gain == 0.0
    events = []
    loop.on_event = events.append

    # what the engine's command thread does when the pipe breaks: submit, then stop
    stop = threading.Event()
    loop.submit(ControllerDetached())
    stop.set()
    loop.run(stop)
    assert loop.faults & Fault.ENGINE_DETACHED
    assert [e.kind for e in events] == ["fault"] and events[0].detail.startswith("ENGINE_DETACHED: ")


def test_ramp_down_is_not_undone_by_a_queued_set_haptics_on(steady):
    eng = steady
    loop = eng.loop
    n0 = loop.tick_count
    loop.submit(SetHaptics(True))
    loop.ramp_down()
    assert loop.haptic_on is False
    assert eng.framework.safety.gain == 0.0
    assert loop.tick_count - n0 == RAMP_TICKS
    assert eng.rig.haptic.output.commanded == (0.0, 0.0, 0.0)


# -- determinism ----------------------------------------------------------------------------------------
def _scripted_rows(seed: int, n: int = 3000) -> np.ndarray:
    eng = build_sim_engine(EngineConfig(clock="virtual", driver="scripted", sim=SimRigConfig(seed=seed)))
    eng.loop.run_ticks(n)
    rows = all_rows(eng)
    assert len(rows) == n
    return rows


def test_same_seed_gives_identical_records_and_another_seed_differs():
    a = _scripted_rows(0)
    b = _scripted_rows(0)
    c = _scripted_rows(1)
    assert a.dtype.names == RECORD_FIELDS
    # on the virtual clock computing takes no time: the latency is the sample's age
    for rows in (a, b, c):
        np.testing.assert_array_equal(rows["latency_ns"], rows["sensor_age_ns"])
    assert a.tobytes() == b.tobytes()  # bit for bit, NaN-aware
    assert a.tobytes() != c.tobytes()
    # the difference is in the measurements, not in the bookkeeping
    np.testing.assert_array_equal(a["t_s"], c["t_s"])
    assert not np.array_equal(a["raw_fz"], c["raw_fz"])
    # and the run did something: presses with feedback
    assert np.nanmax(a["true_fz"]) > 0.5 and np.max(np.abs(a["render_fy"])) > 0.1


# -- the force bound --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("f_max_n", "peak_n", "limit_n"),
    [(3.0, 3.3, 3.0), (3.0, 2.0, 2.0), (1.5, 3.3, 1.5)],
    ids=["f_max", "touch-peak", "small-f_max"],
)
def test_rendered_force_never_exceeds_min_of_f_max_and_touch_peak(f_max_n, peak_n, limit_n):
    cfg = EngineConfig(
        clock="virtual",
        driver="hold",
        sim=SimRigConfig(touch=dataclasses.replace(haptic_model("touch").limits, peak_force_n=peak_n)),
        framework=FrameworkConfig(f_max_n=f_max_n),
    )
    eng = build_sim_engine(cfg)
    # hard presses: ~5 N and ~30 N of tissue force (far past the scaling knee)
    eng.rig.set_driver(ScriptedPresses(depths_m=(0.006, 0.02), period_s=3.0))
    eng.loop.run_ticks(9000)
    rows = all_rows(eng)
    assert np.all(rows["faults"] == 0.0)
    mag = np.hypot(np.hypot(rows["render_fx"], rows["render_fy"]), rows["render_fz"])
    assert np.all(np.isfinite(mag))
    assert mag.max() <= limit_n
    assert mag.max() > limit_n - 0.02  # the bound was actually reached
    assert np.nanmax(rows["true_fz"]) > 20.0
    # slew limit while fully on: at most slew·dt per tick
    on = (rows["gain"][1:] == 1.0) & (rows["gain"][:-1] == 1.0)
    step = np.sqrt(
        np.diff(rows["render_fx"]) ** 2 + np.diff(rows["render_fy"]) ** 2 + np.diff(rows["render_fz"]) ** 2
    )
    assert step[on].max() <= SAFETY.slew_n_per_s * DT_S * (1 + 1e-9)
