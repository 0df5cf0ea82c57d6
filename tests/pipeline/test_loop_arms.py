"""Both arms of the rig in one 1 kHz loop, on the virtual clock: one pipeline per arm, faults per arm, the policy.

A fault injected on each arm in turn (stale sensor, NaN, device error) ramps
that arm to zero within 50 ms and is an event naming the arm; with the fault
policy ``both`` the other arm goes to zero too (``Fault.OTHER_ARM``), with
``independent`` it keeps rendering.  The one-arm loop is what it was.
"""

from __future__ import annotations

import math

import pytest

from pipeline.assembly.engine import Engine, EngineConfig, build_sim_engine
from pipeline.devices.interfaces import Fault
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.arm_channel import ArmChannel
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import RECORD_FIELDS, OperatorStop, ResetFaults
from pipeline.runtime.supervisor import LoopSupervisor
from pipeline.sim.arms import SimArms

MS = 1_000_000
ARMS = ("right", "left")


def two_arms(policy: str = "both") -> Engine:
    """A two-arm simulated engine, ramped in (no payload calibration: the tool's weight is a steady force)."""
    eng = build_sim_engine(EngineConfig(clock="virtual", calibrate=False, arms=ARMS, fault_policy=policy,
                                        ring_seconds=2.0))
    eng.loop.run_ticks(560)  # past the 0.5 s ramp-in
    for ch in eng.loop.arms:
        assert ch.framework.safety.gain == 1.0 and render(ch) > 0.5, ch.name
    return eng


def render(ch: ArmChannel) -> float:
    r = ch.last_record
    assert r is not None
    return math.hypot(*(r[RECORD_FIELDS.index(f"render_f{axis}")] for axis in "xyz"))


def test_each_arm_runs_its_own_pipeline_into_its_own_ring() -> None:
    eng = build_sim_engine(EngineConfig(clock="virtual", calibrate=False, arms=ARMS, ring_seconds=1.0))
    loop = eng.loop
    assert [ch.name for ch in loop.arms] == list(ARMS) and isinstance(eng.rig, SimArms)
    assert loop.ring is eng.ring is eng.rings["right"] and eng.rings["left"] is not eng.ring
    assert loop.framework is eng.frameworks["right"] is not eng.frameworks["left"]
    loop.run_ticks(300)
    right, left = (eng.rings[a].read_since(0).rows for a in ARMS)  # type: ignore[union-attr]
    assert list(right["tick"]) == list(left["tick"]) == list(range(300))  # the same ticks
    assert (right["t_ns"] == left["t_ns"]).all()
    # each arm from its own sensor: its own noise (its own seed)
    assert not (right["raw_fx"] == left["raw_fx"]).all()
    # each arm's device commanded its own force; the first arm's record is the loop's own
    assert eng.rig.rig("left").haptic is loop.arm("left").haptic is not loop.arms[0].haptic
    assert loop.last_record is not None and loop.last_record["raw_fx"] == right["raw_fx"][-1]


@pytest.mark.parametrize("policy", ["both", "independent"])
@pytest.mark.parametrize("arm", ARMS)
@pytest.mark.parametrize(("kind", "fault"), [
    ("sensor-stall", Fault.SENSOR_STALE), ("nan-burst", Fault.NON_FINITE), ("device-error", Fault.HAPTIC_DEVICE),
])
def test_a_fault_on_one_arm_zeroes_it_within_50_ms_and_the_policy_decides_the_other(
        policy: str, arm: str, kind: str, fault: Fault) -> None:
    eng = two_arms(policy)
    loop = eng.loop
    at = eng.clock.now_ns() + 2 * MS
    eng.rig.inject_fault(kind, at, arm=arm)
    faulty = loop.arm(arm)
    other = next(ch for ch in loop.arms if ch.name != arm)
    zero_at: dict[str, int] = {}
    for _ in range(60):
        loop.run_ticks(1)
        for ch in loop.arms:
            if ch.name not in zero_at and render(ch) == 0.0:
                zero_at[ch.name] = eng.clock.now_ns()
    assert faulty.faults & fault
    assert zero_at[arm] - at <= 50 * MS
    ev = next(e for e in loop.events if e.kind == "fault" and e.faults & fault)
    assert ev.arm == arm and ev.faults == faulty.faults
    if policy == "both":
        assert other.faults == Fault.OTHER_ARM and zero_at[other.name] - at <= 50 * MS
        ev_other = next(e for e in loop.events if e.arm == other.name and e.kind == "fault")
        assert ev_other.faults == Fault.OTHER_ARM and f"arm {arm!r}" in ev_other.detail
    else:
        assert other.faults == 0 and other.name not in zero_at and other.framework.safety.gain == 1.0
        assert not any(e.arm == other.name for e in loop.events)
    # once the condition is gone a reset clears every arm, and both ramp in again
    loop.run_ticks(30)
    loop.submit(ResetFaults())
    loop.run_ticks(1)
    assert faulty.faults == 0 and other.faults == 0
    assert {e.arm for e in loop.events if e.kind == "faults_reset"} == set(ARMS)


def test_under_both_the_other_arm_stays_zero_while_the_faulty_arm_keeps_its_fault() -> None:
    eng = two_arms("both")
    loop = eng.loop
    eng.rig.inject_fault("sensor-stall", eng.clock.now_ns() + MS, duration_s=0.2, arm="left")
    loop.run_ticks(20)
    loop.submit(ResetFaults())  # the left sensor is still silent: neither arm may render
    loop.run_ticks(1)
    assert loop.arm("left").faults & Fault.SENSOR_STALE and loop.arm("right").faults == Fault.OTHER_ARM
    loop.run_ticks(250)
    loop.submit(ResetFaults())
    loop.run_ticks(1)
    assert loop.arm("left").faults == 0 and loop.arm("right").faults == 0


def test_rig_wide_faults_latch_on_every_arm_without_other_arm() -> None:
    eng = two_arms("both")
    loop = eng.loop
    loop.submit(OperatorStop())
    loop.run_ticks(1)
    assert [ch.faults for ch in loop.arms] == [Fault.OPERATOR_STOP, Fault.OPERATOR_STOP]
    assert {e.arm for e in loop.events if e.kind == "fault"} == set(ARMS)


def test_a_dead_loop_zeroes_every_arms_device() -> None:
    eng = two_arms("independent")
    loop = eng.loop
    loop._thread = type("Dead", (), {"is_alive": lambda self: False})()  # type: ignore[assignment]
    loop.crash = "RuntimeError('boom')"
    ev = LoopSupervisor(loop, eng.clock).check()
    assert ev is not None and ev.arm == "right"
    eng.rig.advance(eng.clock.now_ns())  # each Touch renders the zero command it was given
    for ch in loop.arms:
        assert ch.faults & Fault.LOOP_STALLED and ch.framework.safety.gain == 0.0
        assert ch.haptic.applied_force_n == (0.0, 0.0, 0.0)  # type: ignore[attr-defined]
    assert {e.arm for e in loop.events if "LOOP_STALLED" in e.detail} == set(ARMS)
    loop._thread = None


def test_a_late_tick_restarts_every_arm_from_zero() -> None:
    eng = two_arms("independent")
    loop = eng.loop
    eng.clock.advance(int(20 * MS))  # type: ignore[attr-defined]
    loop.tick()
    assert {e.arm for e in loop.events if e.kind == "output_restarted"} == set(ARMS)
    assert all(ch.framework.safety.gain == 0.0 or render(ch) < 0.1 for ch in loop.arms)


def test_one_arm_is_the_loop_of_before() -> None:
    eng = build_sim_engine(EngineConfig(clock="virtual", calibrate=False, ring_seconds=1.0))
    loop = eng.loop
    assert [ch.name for ch in loop.arms] == ["right"] and eng.rings == {"right": eng.ring}
    eng.rig.inject_fault("nan-burst", eng.clock.now_ns() + MS)
    loop.run_ticks(10)
    assert loop.faults == Fault.NON_FINITE and all(e.arm == "right" for e in loop.events)


def test_the_loop_refuses_a_pipeline_count_that_does_not_match_the_arms() -> None:
    rig = SimArms.build(ARMS)
    fw = HapticFramework(FrameworkConfig(), device_peak_n=3.3)
    with pytest.raises(ValueError, match=r"the rig has 2 arms \(right, left\)"):
        HapticLoop(rig, fw, eng_clock())
    with pytest.raises(ValueError, match="fault_policy = 'some'"):
        HapticLoop(rig, fw, eng_clock(), arm_pipelines=[(HapticFramework(FrameworkConfig(), device_peak_n=3.3), None)],
                   fault_policy="some")
    with pytest.raises(ValueError, match="arms = "):
        EngineConfig(arms=("left", "left"))
    with pytest.raises(KeyError, match="no arm 'middle'"):
        rig.rig("middle")


def eng_clock():  # type: ignore[no-untyped-def]
    from pipeline.core.clock import VirtualClock

    return VirtualClock()
