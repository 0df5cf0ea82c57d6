"""Watchdog of the haptic loop on the simulated rig (science.md §5), entirely on the virtual clock.

Every case starts from a steady rendered force (> 0.3 N, feedback on, gain 1)
while the simulated hand presses ~2 mm into the tissue, injects one failure
through the simulation's fault switches and checks, tick by tick:

* the fault latches on exactly the tick its condition becomes true;
* the rendered force reaches exactly 0.0 within 50 ms (the safety ramp is
  ``fault_ramp_s`` = 40 ms = 40 ticks, counting the fault tick) and stays 0;
* the latch holds until an explicit :class:`ResetFaults`, which only clears
  conditions that have gone away.
"""

from __future__ import annotations

import dataclasses
import math

import pytest
from drivers import PressAndHold

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.devices.interfaces import Fault
from pipeline.devices.registry import haptic_model
from pipeline.devices.touch_output import HD_WARM_MOTORS
from pipeline.force.config import SafetyConfig
from pipeline.force.framework import STEP_FIELDS
from pipeline.runtime.loop_messages import OperatorStop, ResetFaults
from pipeline.sim.rig import SimRigConfig

PERIOD_NS = 1_000_000
DT_S = PERIOD_NS * 1e-9
SAFETY = SafetyConfig()
#: Ticks from gain 1 to exactly 0, counting the tick that latched the fault.
RAMP_TICKS = round(SAFETY.fault_ramp_s / DT_S)  # 40
#: Ticks from gain 0 to exactly 1 after a reset, counting the reset tick.
RAMP_IN_TICKS = round(SAFETY.ramp_in_s / DT_S)  # 500
MAX_ZERO_TICKS = 50  # science.md §5: zero within 50 ms
RENDER = ("render_fx", "render_fy", "render_fz")




def make_engine(sim: SimRigConfig | None = None, y_m: float = -0.018) -> Engine:
    cfg = EngineConfig(clock="virtual", driver="hold", sim=sim or SimRigConfig())
    eng = build_sim_engine(cfg)
    eng.rig.set_driver(PressAndHold(y_m))
    return eng


def ticks(eng: Engine, n: int) -> list[dict[str, float]]:
    """Run ``n`` ticks one by one; each record also gets the tick time (ns) and the device command."""
    loop = eng.loop
    out = []
    for _ in range(n):
        t_ns = eng.clock.now_ns()
        loop.run_ticks(1)
        rec = loop.last_record
        assert rec is not None
        rec["clock_ns"] = t_ns
        rec["cmd"] = eng.rig.haptic.output.commanded
        rec["limit_n"] = eng.framework.safety.limit_n  # the clamp this tick ran with
        out.append(rec)
    return out


def render_mag(rec: dict[str, float]) -> float:
    return math.hypot(rec["render_fx"], rec["render_fy"], rec["render_fz"])


def is_zero(rec: dict[str, float]) -> bool:
    return all(rec[k] == 0.0 for k in RENDER)


def first(recs: list[dict[str, float]], pred) -> int:
    for i, r in enumerate(recs):
        if pred(r):
            return i
    raise AssertionError("condition never met")


def settle(eng: Engine, n: int = 1500) -> list[dict[str, float]]:
    """Press and hold until the rendered force is steady; check it is."""
    recs = ticks(eng, n)
    tail = recs[-300:]
    mags = [render_mag(r) for r in tail]
    assert all(r["faults"] == 0.0 for r in recs), "no fault while pressing normally"
    assert all(r["gain"] == 1.0 and r["haptic_on"] == 1.0 for r in tail)
    assert min(mags) > 0.3, f"steady rendered force expected > 0.3 N, got {min(mags):.3f}"
    assert max(mags) - min(mags) < 0.1, "rendered force should be steady before the fault"
    assert eng.loop.faults == 0 and len(eng.loop.events) == 0
    return recs


@pytest.fixture
def eng() -> Engine:
    e = make_engine()
    settle(e)
    return e


def check_ramp_to_zero(recs: list[dict[str, float]], fault_i: int, g0: float = 1.0) -> int:
    """The rendered force reaches exactly 0 within 50 ms of the fault and stays 0.

    From gain ``g0`` before the fault the gain drops by dt/fault_ramp_s per tick,
    so from full gain the output is exactly 0 on the RAMP_TICKS-th tick (40 ms).
    """
    zero_i = first(recs[fault_i:], is_zero) + fault_i
    assert zero_i - fault_i == math.ceil(g0 * RAMP_TICKS - 1e-9) - 1
    assert zero_i - fault_i + 1 <= MAX_ZERO_TICKS
    t_zero_ms = (recs[zero_i]["clock_ns"] - recs[fault_i]["clock_ns"]) / 1e6
    assert t_zero_ms <= 50.0
    # ramp: the gain drops by dt/fault_ramp_s per tick from the fault tick on
    for k in range(fault_i, zero_i):
        assert recs[k]["gain"] == pytest.approx(g0 - (k - fault_i + 1) / RAMP_TICKS, abs=1e-9)
        assert render_mag(recs[k]) <= recs[k]["gain"] * 3.0 + 1e-12
    for r in recs[zero_i:]:
        assert is_zero(r) and r["gain"] == 0.0
        assert r["cmd"] == (0.0, 0.0, 0.0)
    # the device gets exactly what the record says
    for r in recs:
        assert r["cmd"] == (r["render_fx"], r["render_fy"], r["render_fz"])
    return zero_i


def fault_events(eng: Engine) -> list:
    return [e for e in eng.loop.events if e.kind == "fault"]


# -- (a) the sensor stops -----------------------------------------------------------------------------
def test_sensor_stall_latches_when_sample_age_exceeds_5ms_and_ramps_to_zero(eng):
    last_sample_ns = eng.rig.sensor.read_wrench().t_ns
    assert last_sample_ns == eng.clock.now_ns() - PERIOD_NS  # sampled on the last tick

    eng.rig.sensor.stalled = True
    recs = ticks(eng, 200)

    ages_ns = [int(r["sensor_age_ns"]) for r in recs]
    assert ages_ns[:8] == [k * PERIOD_NS for k in range(1, 9)]
    fault_i = first(recs, lambda r: r["faults"] != 0.0)
    # age 5 ms is still fine, 6 ms (the 6th stalled tick) is a fault
    assert fault_i == 5
    assert ages_ns[fault_i - 1] == 5_000_000 and ages_ns[fault_i] == 6_000_000
    assert recs[fault_i]["clock_ns"] == last_sample_ns + 6_000_000
    assert all(r["gain"] == 1.0 for r in recs[:fault_i])
    assert all(r["faults"] == float(Fault.SENSOR_STALE) for r in recs[fault_i:])

    (ev,) = fault_events(eng)
    assert ev.t_ns == recs[fault_i]["t_ns"]  # on the records' time axis
    assert ev.faults == Fault.SENSOR_STALE
    assert ev.detail == "SENSOR_STALE: newest F/T sample 6.0 ms old (limit 5 ms)"

    check_ramp_to_zero(recs, fault_i)
    assert eng.loop.faults == Fault.SENSOR_STALE
    assert eng.loop.active_faults == Fault.SENSOR_STALE


# -- (b) a NaN burst ------------------------------------------------------------------------------------
def test_nan_burst_latches_non_finite_never_reaches_device_and_does_not_poison_the_filter(eng):
    w = eng.framework.config.filter_window
    eng.rig.sensor.inject_nan = True
    burst = ticks(eng, 20)
    eng.rig.sensor.inject_nan = False
    after = ticks(eng, 100)
    recs = burst + after

    assert all(math.isnan(r["raw_fx"]) for r in burst)
    assert all(math.isfinite(r["raw_fx"]) for r in after)
    assert burst[0]["faults"] == float(Fault.NON_FINITE)
    (ev,) = fault_events(eng)
    assert ev.faults == Fault.NON_FINITE and ev.detail == "NON_FINITE: fx = nan"
    assert ev.t_ns == burst[0]["t_ns"]

    # nothing non-finite ever goes to the device, and the filter rejected the bad samples
    stage_cols = STEP_FIELDS[STEP_FIELDS.index("filt_fx") :]  # filt_* ... render_*: downstream of the filter
    assert stage_cols[-3:] == RENDER
    for r in recs:
        assert all(math.isfinite(r[c]) for c in stage_cols), r
        assert all(math.isfinite(v) for v in r["cmd"])

    check_ramp_to_zero(recs, 0)

    # the moving average is not poisoned: W clean ticks after the burst it is the
    # plain mean of the last W compensated samples again
    for k in range(w, len(after)):
        window = after[k - w + 1 : k + 1]
        for axis in ("x", "y", "z"):
            mean = math.fsum(r[f"comp_f{axis}"] for r in window) / w
            assert after[k][f"filt_f{axis}"] == pytest.approx(mean, abs=1e-9)
    assert after[-1]["filt_fz"] != 0.0

    # condition gone, but still latched until the operator resets
    assert eng.loop.active_faults == 0
    assert eng.loop.faults == Fault.NON_FINITE
    assert all(r["faults"] == float(Fault.NON_FINITE) for r in after)

    eng.loop.submit(ResetFaults())
    back = ticks(eng, RAMP_IN_TICKS + 200)
    assert eng.loop.faults == 0
    assert all(r["faults"] == 0.0 for r in back)
    reset_ev = eng.loop.events[-1]
    assert reset_ev.kind == "faults_reset" and reset_ev.faults == 0 and reset_ev.detail == "NON_FINITE"
    assert reset_ev.t_ns == back[0]["t_ns"]

    gains = [r["gain"] for r in back]
    # ramp in at dt/ramp_in_s per tick from the reset tick on; exactly 1 after ramp_in_s
    for k in range(RAMP_IN_TICKS - 1):
        assert gains[k] == pytest.approx((k + 1) / RAMP_IN_TICKS, abs=1e-9)
        assert gains[k] < 1.0
    assert gains.index(1.0) == RAMP_IN_TICKS - 1
    assert all(g == 1.0 for g in gains[RAMP_IN_TICKS - 1 :])
    assert all(math.isfinite(r[c]) for r in back for c in stage_cols)
    assert min(render_mag(r) for r in back[-100:]) > 0.3  # feedback is back


# -- (c) the robot stops publishing ---------------------------------------------------------------------
def test_stale_pose_latches_when_pose_age_exceeds_50ms():
    e = make_engine()
    recs = settle(e)
    # CB3 at 125 Hz: a new pose every 8 ms, so the age never reaches 8 ms normally
    ages_ns = [int(r["pose_age_ns"]) for r in recs[-500:]]
    assert max(ages_ns) == 7_000_000 and min(ages_ns) == 0
    assert all(r["faults"] == 0.0 for r in recs)

    pose_t_ns = e.rig.robot.read_pose().t_ns
    e.rig.robot.frozen = True
    recs = ticks(e, 150)
    fault_i = first(recs, lambda r: r["faults"] != 0.0)
    assert recs[fault_i]["clock_ns"] == pose_t_ns + 51_000_000
    assert recs[fault_i]["pose_age_ns"] == 51_000_000
    assert recs[fault_i - 1]["pose_age_ns"] == 50_000_000
    assert recs[fault_i - 1]["faults"] == 0.0 and recs[fault_i - 1]["gain"] == 1.0
    assert all(r["faults"] == float(Fault.POSE_STALE) for r in recs[fault_i:])
    (ev,) = fault_events(e)
    assert ev.faults == Fault.POSE_STALE and ev.detail == "POSE_STALE: newest robot pose 51.0 ms old (limit 50 ms)"
    check_ramp_to_zero(recs, fault_i)


# -- (d) the sensor reports a bad status --------------------------------------------------------------
@pytest.mark.parametrize("status", [0x80010000, 0x1])
def test_bad_sensor_status_latches_sensor_status(eng, status):
    eng.rig.sensor.status_override = status
    recs = ticks(eng, 100)
    # the next sample carries the status: fault on the very next tick
    assert recs[0]["faults"] == float(Fault.SENSOR_STATUS)
    assert all(r["faults"] == float(Fault.SENSOR_STATUS) for r in recs)
    (ev,) = fault_events(eng)
    assert ev.faults == Fault.SENSOR_STATUS and ev.detail == f"SENSOR_STATUS: status word 0x{status:08X}"
    check_ramp_to_zero(recs, 0)


# -- (e) a reset while the condition persists ---------------------------------------------------------
@pytest.mark.parametrize(
    ("device", "switch", "value", "fault", "settle_ticks"),
    [
        ("sensor", "stalled", True, Fault.SENSOR_STALE, 60),
        ("sensor", "status_override", 0x80010000, Fault.SENSOR_STATUS, 60),
        ("robot", "frozen", True, Fault.POSE_STALE, 100),
    ],
)
def test_reset_while_condition_persists_keeps_fault_latched(eng, device, switch, value, fault, settle_ticks):
    dev = getattr(eng.rig, device)
    setattr(dev, switch, value)
    ticks(eng, settle_ticks)
    assert eng.loop.faults == fault

    eng.loop.submit(ResetFaults())
    recs = ticks(eng, 100)
    assert eng.loop.faults == fault
    assert all(r["faults"] == float(fault) for r in recs)
    assert all(is_zero(r) and r["gain"] == 0.0 for r in recs)
    ev = eng.loop.events[-1]
    assert ev.kind == "faults_reset" and ev.faults == fault and ev.detail == fault.name
    assert len(fault_events(eng)) == 1  # still the one fault: not re-raised as new

    # once the condition is gone (and seen gone by a tick), a reset clears it
    setattr(dev, switch, type(value)(0))
    ticks(eng, 10)
    assert eng.loop.active_faults == 0 and eng.loop.faults == fault
    eng.loop.submit(ResetFaults())
    recs = ticks(eng, 10)
    assert eng.loop.faults == 0
    assert recs[0]["faults"] == 0.0
    assert recs[0]["gain"] == pytest.approx(1 / RAMP_IN_TICKS, abs=1e-12)
    ev = eng.loop.events[-1]
    assert ev.kind == "faults_reset" and ev.faults == 0 and ev.detail == fault.name


# -- (f) the operator stops ----------------------------------------------------------------------------
def test_operator_stop_latches_and_ramps_to_zero_until_reset(eng):
    eng.loop.submit(OperatorStop())
    recs = ticks(eng, 100)
    assert recs[0]["faults"] == float(Fault.OPERATOR_STOP)
    assert all(r["faults"] == float(Fault.OPERATOR_STOP) for r in recs)
    (ev,) = fault_events(eng)
    assert ev.faults == Fault.OPERATOR_STOP and ev.detail == "OPERATOR_STOP: the experimenter stopped the force"
    assert ev.t_ns == recs[0]["t_ns"]
    check_ramp_to_zero(recs, 0)
    assert eng.loop.active_faults == 0  # not a sensed condition: only the reset clears it

    eng.loop.submit(ResetFaults())
    back = ticks(eng, RAMP_IN_TICKS + 100)
    assert eng.loop.faults == 0
    ev = eng.loop.events[-1]
    assert ev.kind == "faults_reset" and ev.faults == 0 and ev.detail == "OPERATOR_STOP"
    assert back[0]["gain"] == pytest.approx(1 / RAMP_IN_TICKS, abs=1e-12)
    assert back[RAMP_IN_TICKS - 1]["gain"] == 1.0
    assert min(render_mag(r) for r in back[-50:]) > 0.3


# -- (g) the Touch's motors get warm -----------------------------------------------------------------------
def test_warm_motors_derate_the_output_and_the_loop_records_and_reports_it():
    budget = 0.5
    spec = dataclasses.replace(haptic_model("touch").limits, thermal_budget_n2s=budget)
    e = make_engine(SimRigConfig(touch=spec), y_m=-0.025)  # ~5 N of tissue force, ~1.9 N rendered
    touch = e.rig.haptic
    recs = ticks(e, 6000)
    assert e.loop.faults == 0  # derating, not a fault: the motors never pass the budget
    assert touch.heat_n2s < budget and touch.error_code == 0
    start = [ev for ev in e.loop.events if ev.kind == "derating"]
    # at the onset the limit is a hair below the peak: the event says that derating begins, not "limited to 3.30 N"
    assert len(start) == 1 and start[0].detail == (
        f"haptic device motors warm ({start[0].detail.split('(')[1].split(' %')[0]} % of the thermal budget): "
        "derating begins — the most it may render falls from its 3.3 N peak toward its 0.88 N continuous rating as "
        "they heat further, and rises again as they cool")
    assert 50 <= int(start[0].detail.split("(")[1].split(" %")[0]) <= 52
    # the rendered force never exceeds what the device may render, and the records say what was cut
    limited = [r for r in recs if r["derate"] < 1.0]
    assert limited, "the derated limit never cut the designed force"
    k = recs.index(limited[0])
    designed = math.hypot(recs[k]["scaled_fx"], recs[k]["scaled_fy"], recs[k]["scaled_fz"])
    assert recs[k]["derate"] == pytest.approx(recs[k]["limit_n"] / designed, rel=1e-9)
    assert all(r["derate"] == 1.0 for r in recs[:k])
    assert all(render_mag(r) <= r["limit_n"] * (1 + 1e-9) for r in recs)
    final_limit = e.rig.haptic.read_state().force_limit_n
    assert render_mag(recs[-1]) <= final_limit * (1 + 1e-9)
    assert spec.continuous_force_n < final_limit < 1.9

    # releasing lets the motors cool: derating ends (an event) and the full force comes back
    e.rig.set_driver(PressAndHold(0.0))
    ticks(e, 20000)
    assert touch.read_state().force_limit_n == spec.peak_force_n
    assert [ev.kind for ev in e.loop.events if ev.kind.startswith("derating")] == ["derating", "derating_ended"]
    assert e.loop.events[-1].detail.endswith("% of the thermal budget): derating over, its full 3.3 N peak again")


def test_warm_motors_past_the_budget_latch_haptic_device_and_reset_waits_for_cooling():
    budget = 2.0
    e = make_engine(SimRigConfig(touch=dataclasses.replace(haptic_model("touch").limits, thermal_budget_n2s=budget)))
    touch = e.rig.haptic
    settle(e, 1500)
    touch.output.heat.heat_n2s = budget * 1.01  # past the budget anyway (a servo stall at full force): the backstop
    recs = ticks(e, 1)
    assert recs[0]["faults"] == float(Fault.HAPTIC_DEVICE) and touch.error_code == HD_WARM_MOTORS
    ev = [ev for ev in fault_events(e) if ev.faults == Fault.HAPTIC_DEVICE][-1]
    assert ev.detail.startswith("HAPTIC_DEVICE: device error 0x0200 (HD_WARM_MOTORS: the motors are too warm")

    rearms: list[tuple[bool, float]] = []
    real_rearm = touch.rearm

    def spy_rearm() -> bool:
        ok = real_rearm()
        rearms.append((ok, touch.heat_n2s))
        return ok

    touch.rearm = spy_rearm
    # an immediate reset: the motors are still warm, the device refuses to re-arm
    e.loop.submit(ResetFaults())
    recs += ticks(e, 1)
    assert rearms == [(False, touch.heat_n2s)]
    assert e.loop.faults == Fault.HAPTIC_DEVICE
    # keep asking every tick while the device cools (it renders nothing meanwhile)
    attempts = 0
    while e.loop.faults:
        assert attempts < 5000, "the motors never cooled"
        e.loop.submit(ResetFaults())
        recs += ticks(e, 1)
        attempts += 1
        ok, h = rearms[-1]
        assert ok == (h <= 0.5 * budget)
        assert (e.loop.faults == Fault.HAPTIC_DEVICE) == (not ok)
        assert touch.applied_force_n == (0.0, 0.0, 0.0) or ok
    assert attempts > 10  # it really had to cool first



def test_a_value_beyond_its_limit_is_never_shown_as_within_it():
    """Issue 40, item 6: a 5.03 ms gap read "5.0 ms (limit 5 ms)"; as many decimals as show it beyond the limit."""
    from pipeline.runtime.watchdog import ms_beyond

    assert ms_beyond(5.03, 5.0) == "5.03" and ms_beyond(7.0, 5.0) == "7.0" and ms_beyond(5.0004, 5.0) == "5.0004"
    assert ms_beyond(50.2, 50.0) == "50.2" and ms_beyond(5.0006, 5.0) == "5.001"
