"""A simulated loop's ticks run in compiled blocks (pipeline/sim/block.py) are its ticks run one by one, bit for bit.

Three levels: each kernel the block is made of runs compiled as its ``py_func`` does (hypothesis, at the extremes);
a loop with a simulated participant run in blocks and the same loop run tick by tick leave the same records, replay
log, events and states through trials, a watchdog fault that trips and clears mid-block, lost packets, derating and
a reset; and a seeded study stores the same tables either way.
"""

from __future__ import annotations

import importlib.util
import math
import pickle
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kernel_checks import bits, compiled_on_construction, same

from pipeline.assembly.engine import EngineConfig, build_sim_engine
from pipeline.core.aim import TrialAim
from pipeline.core.ring import RingBuffer
from pipeline.core.tick_record import TICK_DTYPE
from pipeline.devices import touch_output
from pipeline.devices.interfaces import Fault
from pipeline.devices.touch_output import HapticLimits, TouchOutput
from pipeline.runtime import arm_channel
from pipeline.runtime.loop_messages import AllowBiasRefinement, Mark, ResetFaults, SetHaptics, StartRecording
from pipeline.sim import hand, participant_tick, percepts
from pipeline.sim import touch as sim_touch
from pipeline.sim.block import SimBlocks
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.rig import SimRigConfig
from pipeline.sim.sensor import SensorParams

ROOT = Path(__file__).resolve().parents[2]
ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
FORCE = st.one_of(st.floats(-20.0, 20.0), ANY)
TIME = st.one_of(st.floats(0.0, 1e4), ANY)


# -- the kernels, compiled and interpreted ----------------------------------------------------------------------------
@settings(max_examples=300)
@given(cmd=st.tuples(FORCE, FORCE, FORCE), has=st.booleans(), t_cmd=st.integers(-10**12, 10**12),
       now=st.integers(-10**12, 10**12), dt=st.one_of(st.just(0.001), st.floats(-1.0, 1.0)), enabled=st.booleans(),
       heat=st.one_of(st.floats(0.0, 12.0), ANY), warm=st.booleans(), err=st.sampled_from([0, 0x0200, 0x0300]))
def test_touch_output_kernels(cmd: tuple[float, float, float], has: bool, t_cmd: int, now: int, dt: float,
                              enabled: bool, heat: float, warm: bool, err: int) -> None:
    out = TouchOutput(HapticLimits(3.3, 0.88, 10.0))
    if has:
        out.command(*cmd, t_cmd)
    out.heat.heat_n2s = heat
    out.array[touch_output.WARM] = 1.0 if warm else 0.0
    same(touch_output.render_kernel, out.array, out.ints, now, dt, enabled)
    same(sim_touch.advance_kernel, out.array, out.ints, now, dt, err)
    same(touch_output.add_heat_kernel, out.array, abs(cmd[0]), dt)
    same(touch_output.set_heat_kernel, out.array, heat)


def test_a_command_renders_as_before() -> None:
    """The output's rules, read through its Python face: fresh, clamped, stale at the timeout, non-finite to zero."""
    out = TouchOutput(HapticLimits(3.3, 0.88, 10.0), 0.010)
    assert out.render(0, 0.001) == (0.0, 0.0, 0.0) and out.stale and out.stale_ticks == 1  # no command yet
    out.command(0.0, 4.0, 3.0, 1_000_000)
    fx, fy, fz = out.render(2_000_000, 0.001)
    assert (fx, fy, fz) == out.rendered_n and math.hypot(fx, fy, fz) == pytest.approx(3.3, rel=1e-15)  # clamped
    assert out.render(11_000_000, 0.001) == (0.0, 0.0, 0.0) and out.stale  # 10 ms old
    out.command(math.nan, 0.0, 0.0, 11_000_000)
    assert out.render(11_000_000, 0.001) == (0.0, 0.0, 0.0) and not out.stale
    out.heat.heat_n2s = 10.5  # past the budget: HD_WARM_MOTORS, nothing rendered until cooled and re-armed
    out.command(0.5, 0.0, 0.0, 12_000_000)
    assert out.render(12_000_000, 0.001) == (0.0, 0.0, 0.0) and out.warm and not out.rearm()
    out.heat.heat_n2s = 4.0
    assert out.rearm() and not out.warm and out.commanded == (0.0, 0.0, 0.0)


@settings(max_examples=300)
@given(t=TIME, t0=TIME, dur=st.one_of(st.floats(1e-3, 2.0), ANY), y0=FORCE, y1=FORCE)
def test_min_jerk(t: float, t0: float, dur: float, y0: float, y1: float) -> None:
    with np.errstate(all="ignore"):
        try:
            expect = hand.min_jerk.py_func(t, t0, dur, y0, y1)
        except ZeroDivisionError:
            with pytest.raises(ZeroDivisionError):
                hand.min_jerk(t, t0, dur, y0, y1)
            return
    assert bits(hand.min_jerk(t, t0, dur, y0, y1)) == bits(expect)


def _participant(seed: int, t: float, drift: bool, zi: int, nz: int) -> SimulatedParticipant:
    p = SimulatedParticipant(seed=seed)
    rng = np.random.default_rng(seed)
    p._z, p._zi, p._nz = rng.standard_normal(8), zi, nz
    p._p_t0, p._p_dur, p._p_y0, p._p_y1 = t - 0.3, 1.1, -0.002, -0.017
    p._p_end = p._p_t0 + p._p_dur
    p._drift_on, p._d_t0, p._d_t1 = drift, t - 0.015, t + float(rng.uniform(-0.05, 0.01))
    p._d0, p._d1, p._d_step = 1e-4, -2e-4, 3e-4
    return p


# (the participant's time is finite: a non-finite or absurd observation time is ignored before its tick, and a knot
# loop to an infinite time would not end, compiled or not)
@settings(max_examples=300)
@given(seed=st.integers(0, 1000), t=st.floats(0.0, 1e4), dt=st.one_of(st.floats(-2.0, 2.0), st.floats(-1e6, 1e6)),
       drift=st.booleans(), zi=st.integers(0, 8), obs=st.tuples(FORCE, FORCE, FORCE, FORCE))
def test_participant_kernels(seed: int, t: float, dt: float, drift: bool, zi: int,
                             obs: tuple[float, float, float, float]) -> None:
    p = _participant(seed, t, drift, zi, 8)
    same(participant_tick.plan_kernel, p.array, p.normals, t + dt)
    same(participant_tick.normals_short, p.array, t + dt)
    hist = p.history.copy()
    a, b = p.array.copy(), p.array.copy()
    participant_tick.remember_kernel(a, hist, t, *obs)
    h2 = p.history.copy()
    participant_tick.remember_kernel.py_func(b, h2, t, *obs)
    assert bits(a) == bits(b) and bits(hist) == bits(h2)
    j = int(a[1])
    assert participant_tick.newest_at(hist[0], j, t + dt, t - 1.0) == percepts.newest_at.py_func(hist[0], j, t + dt,
                                                                                              t - 1.0)


def test_the_drift_asks_for_normals_it_has_not() -> None:
    """A knot due with no normal left: the plan says so (NaN) and changes nothing; drawn, it goes on."""
    p = _participant(3, 5.0, True, 8, 8)
    p._d_t1 = 4.99
    before = p.array.copy()
    assert participant_tick.normals_short(p.array, 5.0)
    assert math.isnan(participant_tick.plan_kernel(p.array, p.normals, 5.0))
    assert bits(p.array) == bits(before)
    p.more_normals()
    assert p._nz == 1024 and not math.isnan(participant_tick.plan_kernel(p.array, p.normals, 5.0))


@settings(max_examples=300)
@given(now=st.integers(0, 10**13), w_age=st.integers(-10**7, 10**8), raw=st.tuples(*[FORCE] * 6),
       status=st.sampled_from([0, 0x80020000]), pose_age=st.integers(-10**7, 10**9))
def test_conditions_kernel(now: int, w_age: int, raw: tuple[float, ...], status: int, pose_age: int) -> None:
    sat = np.array([123.5, 123.5, 380.0, 9.5, 9.5, 9.5])
    args = (sat, 5_000_000, 50_000_000, now, now - w_age, *raw, status, now - pose_age)
    assert arm_channel.conditions_kernel(*args) == arm_channel.conditions_kernel.py_func(*args)


# -- a loop in blocks and tick by tick --------------------------------------------------------------------------------
def _engine(blocks: bool) -> tuple[Any, SimulatedParticipant]:
    eng = build_sim_engine(EngineConfig(sim=SimRigConfig(seed=4, sensor=SensorParams(packet_loss=0.02)),
                                        clock="virtual", driver="hold", haptics_on=False, refine_bias=True))
    assert (eng.loop.block_runner is not None) == True  # noqa: E712  (the simulated engine installs it)
    if not blocks:
        eng.loop.block_runner = None
        eng.rig.sensor.rows_per_draw = 64  # the sensor's noise drawn as a rig on its own draws it: the same stream
    p = SimulatedParticipant(seed=12)
    eng.rig.set_driver(p)
    return eng, p


def _script(eng: Any, p: SimulatedParticipant) -> list[Any]:
    """Trials with and without feedback, a sensor stall mid-block (a fault latched and its condition gone), a reset,
    derating, the bias refined between trials; what each step leaves."""
    loop, rig = eng.loop, eng.rig
    seen: list[Any] = []

    def run(n: int) -> None:
        loop.run_ticks(n)
        seen.append((loop.tick_count, bits(rig.state), bits(p.array), bits(loop.framework.array),
                     bits(rig.haptic.output.array), rig.sim_time_s, rig.last_observation, rig.sensor.read_wrench(),
                     rig.robot.read_pose(), rig.haptic.read_state(), loop.last_record, loop.faults,
                     loop.active_faults))

    loop.submit(StartRecording(1))  # (the replay log: the poses the framework takes, logged from here on)
    run(300)
    for k, (force, on) in enumerate(((1.2, True), (0.6, False), (1.2, False))):
        loop.submit(AllowBiasRefinement(False))
        loop.submit(SetHaptics(on))
        loop.submit(Mark(k, 1))
        p.begin_trial(TrialAim.constant(force, on), rig.sim_time_s)
        for _ in range(120):
            run(50)
        if k == 1:
            rig.sensor.stalled = True  # the box stops sending: SENSOR_STALE latches 5 ms later, mid-block
            run(50)
            rig.sensor.stalled = False
            run(50)
            loop.submit(ResetFaults())
            run(50)
        if k == 2:
            heat = rig.haptic.output.heat
            heat.heat_n2s = 0.75 * heat.spec.thermal_budget_n2s  # warm motors: the device derates
            run(50)
        p.end_trial(rig.sim_time_s)
        loop.submit(Mark(-1, 0))
        loop.submit(AllowBiasRefinement(True))
        run(700)
    return seen


def test_a_loop_in_blocks_is_the_loop_tick_by_tick() -> None:
    (fast, pf), (slow, ps) = _engine(True), _engine(False)
    a, b = _script(fast, pf), _script(slow, ps)
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x == y, f"step {k}"
    ra, rb = fast.ring.read_since(0), slow.ring.read_since(0)
    assert ra.rows.tobytes() == rb.rows.tobytes() and len(ra.rows) > 10_000
    assert list(fast.loop.events) == list(slow.loop.events)
    assert list(fast.loop.replay_log) == list(slow.loop.replay_log)
    assert sum(1 for e in fast.loop.replay_log if e[1] == "pose") > 1000  # a pose every 8 ms, logged
    kinds = [ev.kind for ev in fast.loop.events]
    assert "fault" in kinds and "fault_cleared" in kinds and "faults_reset" in kinds and "derating" in kinds
    assert fast.rig.sensor.lost_packets > 0 and pf.decisions > 3  # lost packets, and the participant decided
    runner = fast.loop.block_runner.__self__  # type: ignore[union-attr]  # (a bound method)
    assert runner.block_ticks > 0.9 * fast.loop.tick_count  # most ticks ran in blocks ...
    assert runner.python_ticks > 20  # ... and the events', faults' and commands' in Python
    assert runner.half_ticks >= 3  # the fault, its condition gone and the derating: mid-tick


# -- a study --------------------------------------------------------------------------------------------------------
def test_a_study_in_blocks_stores_the_study_tick_by_tick(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every table of a seeded study (training and experiment) run in blocks and run tick by tick, identical."""
    code = ("import sys\nfrom pipeline.sim.block import SimBlocks\n"
            "if sys.argv[2] == 'python':\n    SimBlocks.ready = lambda self, now: False\n"
            "from protocol.study.config import default_protocol\nimport dataclasses\n"
            "from study_app.headless import run_study\np = default_protocol()\n"
            "p = dataclasses.replace(p, trials_per_cell=1, trial=dataclasses.replace(p.trial, pause_s=0.5),\n"
            "    training=dataclasses.replace(p.training, seconds_per_target_per_mode=3.0))\n"
            "run_study(sys.argv[1], participants=1, seed=3, protocol=p, jobs=1)\n")
    dbs = []
    for how in ("blocks", "python"):
        db = str(tmp_path / f"{how}.db")
        subprocess.run([sys.executable, "-c", code, db, how], check=True, cwd=ROOT, capture_output=True)
        dbs.append(db)
    spec = importlib.util.spec_from_file_location("same_study", ROOT / "scripts" / "same_study.py")
    assert spec is not None and spec.loader is not None
    same_study = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(same_study)
    assert same_study.compare(*dbs)
    c = sqlite3.connect(dbs[0])
    assert c.execute("SELECT COUNT(*) FROM trials").fetchone()[0] >= 4
    c.close()


# -- the pieces around it -------------------------------------------------------------------------------------------
def test_rows_written_at_once_are_rows_written_one_by_one() -> None:
    """``write_rows`` leaves the ring ``write_row`` one at a time leaves, across its end; a shared ring refuses it."""
    rng = np.random.default_rng(1)
    a, b = RingBuffer.create(TICK_DTYPE, 7, shared=False), RingBuffer.create(TICK_DTYPE, 7, shared=False)
    for n in (3, 5, 1, 6):
        rows = rng.standard_normal((n, len(TICK_DTYPE.names or ())))
        a.write_rows(rows)
        for r in rows:
            b.write_row(r.tobytes())
        assert a.write_count == b.write_count and a.latest(6).tobytes() == b.latest(6).tobytes()
    shared = RingBuffer.create(TICK_DTYPE, 7)
    try:
        with pytest.raises(ValueError, match="shared"):
            shared.write_rows(np.zeros((1, len(TICK_DTYPE.names or ()))))
    finally:
        shared.close()


def test_blocks_need_one_arm_and_a_private_ring() -> None:
    eng = build_sim_engine(EngineConfig(clock="virtual", arms=("right", "left")))
    assert eng.loop.block_runner is None  # two arms: tick by tick
    with pytest.raises(ValueError, match="one-arm"):
        SimBlocks(eng.loop, eng.rig.rigs[0])
    assert build_sim_engine(EngineConfig(clock="virtual"), shared_ring=True).loop.block_runner is None


def test_the_kernels_are_compiled_when_a_simulated_engine_is_built() -> None:
    """No tick of a simulated engine waits for a compiler: the block's, the participant's and the Touch's kernels are
    compiled or loaded when it is built (in a fresh process: this one's may have compiled them already) -- the loop's
    own process too, where a participant arrives by pickle while the loop runs."""
    compiled_on_construction(
        "from pipeline.sim import block, participant_tick, percepts, hand, touch\n"
        "from pipeline.devices import touch_output\n"
        "from pipeline.assembly.engine import EngineConfig, build_sim_engine",
        # (the kernels Python calls: the block's steps are compiled into it, or loaded with it from numba's cache)
        "(block.block_kernel, block.hold_kernel, participant_tick.plan_kernel, "
        "participant_tick.remember_kernel, participant_tick.normals_short, percepts.newest_at, hand.min_jerk, "
        "touch.advance_kernel, touch_output.render_kernel, touch_output.command_kernel)",
        "build_sim_engine(EngineConfig(clock='virtual'))")


def test_an_unpickled_participant_is_ready() -> None:
    p = pickle.loads(pickle.dumps(SimulatedParticipant(seed=2)))
    assert participant_tick.plan_kernel.signatures and p.array.shape == (participant_tick.STATE_SIZE,)
    assert int(Fault.SENSOR_STALE) & arm_channel.conditions_kernel.py_func(
        np.ones(6), 5, 5, 100, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 100)[0]


def test_the_calibration_held_still_in_blocks_is_the_calibration_tick_by_tick(monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulated calibration's settling and averaging (:func:`pipeline.sim.block.hold_still`) in blocks and tick by
    tick: the same poses, calibration and rig, bit for bit (the robot turning to each pose runs tick by tick)."""
    from pipeline.core.clock import VirtualClock
    from pipeline.sim import block
    from pipeline.sim.calibration import auto_calibrate
    from pipeline.sim.rig import SimRig

    def calibrate() -> tuple[Any, ...]:
        rig, clock = SimRig(SimRigConfig(seed=8, sensor=SensorParams(packet_loss=0.05))), VirtualClock()
        cal, poses = auto_calibrate(rig, clock)
        return (cal, [(p.rot_base_sensor, bits(p.wrench)) for p in poses], bits(rig.state), rig.sim_time_s,
                rig.sensor.read_wrench(), rig.robot.read_pose(), clock.now_ns(), rig.one_call_ticks)

    python_ticks = []
    advance = SimRig.advance

    def counted(rig: SimRig, now_ns: int) -> None:
        python_ticks.append(now_ns)
        advance(rig, now_ns)

    monkeypatch.setattr(SimRig, "advance", counted)
    fast = calibrate()
    assert 0 < len(python_ticks) < 0.05 * 24 * 500  # most of the 24 poses' settling and averaging ran in blocks
    monkeypatch.setattr(block, "_hold_ready", lambda rig, clock, now: False)
    assert calibrate() == fast


def test_a_pose_turned_while_the_robot_was_frozen_is_taken_as_tick_by_tick() -> None:
    """The robot turns while it publishes nothing (frozen), then publishes again: the framework takes the turned pose
    (its payload compensation and the replay log with it) in blocks as tick by tick."""
    from pipeline.force.frames import axis_angle, mat_mul
    from pipeline.sim.robot import TOOL_DOWN

    def go(blocks: bool) -> tuple[Any, ...]:
        eng, _ = _engine(blocks)
        loop, rig = eng.loop, eng.rig
        loop.submit(StartRecording(1))
        loop.run_ticks(100)
        rig.robot.frozen = True
        rig.robot.set_orientation(mat_mul(TOOL_DOWN, axis_angle((1.0, 0.0, 0.0), 0.2)))
        loop.run_ticks(20)
        rig.robot.frozen = False
        loop.run_ticks(60)
        return (loop.framework.rot_base_tip, bits(loop.framework.array), list(loop.replay_log), loop.last_record,
                list(loop.events), eng.ring.read_since(0).rows.tobytes())

    fast = go(True)
    assert fast == go(False)
    assert fast[0] != TOOL_DOWN  # the turned pose was taken


def test_a_copied_touch_output_keeps_its_times_in_its_own_state() -> None:
    import copy

    out = TouchOutput(HapticLimits(3.3, 0.88, 10.0))
    out.command(0.5, 0.0, 0.0, 1_000_000)
    twin = copy.deepcopy(out)
    assert np.shares_memory(twin.ints, twin.array) and twin.heat.array is twin.array
    twin.command(1.0, 0.0, 0.0, 5_000_000)
    assert out.render(2_000_000, 0.001) == (0.5, 0.0, 0.0) and twin.render(6_000_000, 0.001) == (1.0, 0.0, 0.0)
    assert pickle.loads(pickle.dumps(twin)).render(6_000_000, 0.001) == (1.0, 0.0, 0.0)
