"""The simulated rig's compiled kernels (pipeline/core/compiled.py) give the bits of the Python they are compiled from.

Two guarantees, each on any CPU: every kernel's compiled code and its ``py_func`` (the same function run by the
interpreter) leave the same state and return the same values, bit for bit, at the extremes too (hypothesis); and the
rig's one-call tick (:func:`pipeline.sim.rig.step_kernel`) is its models' methods run one by one, in order, tick for
tick -- so a study stores the same bytes whichever path each tick took.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from kernel_checks import bits, compiled_on_construction, same

from pipeline.sim import hand, robot, sensor, tissue
from pipeline.sim.hand import CompliantArm, ScriptedPresses
from pipeline.sim.rig import SimRig, SimRigConfig, step_kernel, target_kernel
from pipeline.sim.robot import SimRobot
from pipeline.sim.sensor import SensorParams, SimForceSensor
from pipeline.sim.tissue import HuntCrossleyTissue, TissueParams

# any double: zero and both signs of it, subnormals, huge values, infinities, NaN
ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
FINITE = st.floats(allow_nan=False, allow_infinity=False, allow_subnormal=True)
DT = st.one_of(st.just(0.001), st.floats(0.0, 0.02), st.floats(-1.0, 0.0))  # a tick, a stall, a clock step back
POSITIVE = st.floats(1e-6, 1e6)  # a model's parameters: what their dataclasses accept


@given(y=FINITE, v=FINITE, k=POSITIVE, b=st.floats(0.0, 1e3), m=POSITIVE, y_c=ANY, felt=ANY, dt=DT)
def test_arm_step(y: float, v: float, k: float, b: float, m: float, y_c: float, felt: float, dt: float) -> None:
    s = np.array([y, v, k, b, m])
    same(hand.step_kernel, s, y_c, felt, dt)
    same(hand.substeps_kernel, s, y_c, felt, abs(dt), 3)


@given(depth=ANY, prev=FINITE, maxwell=FINITE, dt=DT, relax=st.sampled_from([0.0, 40.0]), n=st.floats(1.0, 2.5))
def test_tissue_step(depth: float, prev: float, maxwell: float, dt: float, relax: float, n: float) -> None:
    t = HuntCrossleyTissue(TissueParams(exponent=n, relax_stiffness_n_per_m=relax))
    s = t.array.copy()
    s[0], s[1] = prev, maxwell
    same(tissue.step_kernel, s, depth, dt)


# (times up to 100 s: a first cycle at half of it leaves the interpreted catch-up loop ≤ 6 250 controller cycles)
@given(pos=st.tuples(FINITE, FINITE, FINITE), target=st.tuples(ANY, ANY, ANY), now=st.integers(0, 10**11),
       dt=DT, first=st.booleans())
def test_robot(pos: tuple[float, float, float], target: tuple[float, float, float], now: int, dt: float,
               first: bool) -> None:
    r = SimRobot(pos)
    if not first:
        r.advance(now // 2, 0.001)  # a controller cycle already ran: the next one is due later
    same(robot.command_kernel, r.array, *target)
    r.command(target)
    same(robot.advance_kernel, r.array, now, dt)


@given(contact=st.tuples(ANY, ANY, ANY), t_ns=st.integers(0, 2**53 - 10**7), dt=DT, loss=st.sampled_from([0.0, 0.3]),
       stalled=st.booleans(), nan=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_sensor_sample(contact: tuple[float, float, float], t_ns: int, dt: float, loss: float, stalled: bool,
                       nan: bool, seed: int) -> None:
    s = SimForceSensor(SensorParams(packet_loss=loss), seed=seed)
    s.stalled, s.inject_nan = stalled, nan
    ni = s.next_noise_row()
    s.set_rotation((0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0))
    same(sensor.sample_kernel, s.array, s.noise, ni, t_ns, *contact, dt)
    s.sample(t_ns, (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 5.0), 0.001)  # a first sample set t0
    same(sensor.sample_kernel, s.array, s.noise, s.next_noise_row(), t_ns + 10**6, *contact, dt)


@given(y_c=ANY, felt=ANY, dt=DT, seed=st.integers(0, 1000), push=st.tuples(FINITE, FINITE, FINITE))
def test_rig_step(y_c: float, felt: float, dt: float, seed: int, push: tuple[float, float, float]) -> None:
    rig = SimRig(SimRigConfig(seed=seed))
    rig.push_base_n = push
    rig.advance(0)  # the sensor's orientation and first record
    same(step_kernel, rig.state, rig.sensor.noise, rig.sensor.next_noise_row(), y_c, felt, dt, 10**6, 10**6)
    same(target_kernel, rig.state, y_c)


class _Presses(ScriptedPresses):
    """The demo's presses, quick."""

    def __init__(self) -> None:
        super().__init__(depths_m=(0.002, 0.004), start_gap_m=0.015, period_s=1.2, rest_s=0.1, hold_s=0.3)


def _run(rig: SimRig, ticks: int, t0_ns: int = 0) -> list[Any]:
    """The rig stepped ``ticks`` times from clock reading ``t0_ns`` (1 ms apart, but for a 15 ms stall and a repeated
    reading), a force commanded each tick, a push, a re-orientation and four rehearsed faults on the way; what the
    loop reads of it each tick, times as offsets from ``t0_ns``."""
    seen = []
    now = t0_ns
    for kind, at_s in (("sensor-stall", 0.5), ("nan-burst", 1.0), ("bad-status", 1.6), ("stale-pose", 2.2)):
        rig.inject_fault(kind, t0_ns + int(at_s * 1e9), 0.05)
    for k in range(1, ticks + 1):
        now += 15_000_000 if k == 700 else (0 if k == 900 else 1_000_000)
        if k == 1200:
            rig.push_base_n = (0.5, -0.25, 1.5)  # someone pushes on the tip
        rig.advance(now)
        if k == 1500:
            rig.robot.set_orientation((1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0))  # a re-orientation (a new tuple)
        # a felt force that depends on the state: the loop's output, roughly
        rig.haptic.command_force(0.0, 0.5 * math.tanh(rig.sensor.read_wrench()[3] / 7.0), 0.0, now)
        w, p = rig.sensor.read_wrench(), rig.robot.read_pose()
        seen.append((bits((w[0] - t0_ns, *w[1:])), bits((p[0] - t0_ns, *p[1], *p[2])), rig.haptic.stylus_m,
                     rig.true_contact_force(), bits(tuple(rig.last_observation)), bits(rig.state)))
    return seen


def test_one_call_tick_is_the_models_in_order() -> None:
    """A rig whose ticks take the one compiled call when they can and one whose every tick runs the models' methods
    see and store the same bits, through contact, lost packets, four kinds of fault, a stall, a repeated clock
    reading, a push and a re-orientation."""
    cfg = SimRigConfig(seed=5, sensor=SensorParams(packet_loss=0.01))
    fast, slow = SimRig(cfg, _Presses()), SimRig(cfg, _Presses())
    slow.one_call = False
    a, b = _run(fast, 3000), _run(slow, 3000)
    assert fast.one_call_ticks >= 2990 and slow.one_call_ticks == 0  # each took the path it was meant to
    assert max(r[3][2] for r in a) > 1.0  # the presses reached the tissue
    assert fast.sensor.lost_packets > 0
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x == y, f"tick {k + 1}"


def test_a_late_clock_reading_changes_nothing() -> None:
    """A rig on a clock that reads 2⁶⁰ ns at its first tick (a monotonic clock counts from boot) does what one
    starting at 0 does, to the bit: its models count time from their first tick (a float64 is exact to 2⁵³)."""
    cfg = SimRigConfig(seed=9)
    assert _run(SimRig(cfg, _Presses()), 1500) == _run(SimRig(cfg, _Presses()), 1500, t0_ns=2**60)


def test_teleoperation_takes_the_models_path() -> None:
    """With a teleoperation driver attached, the robot's targets are the driver's: every tick runs model by model."""

    class Servo:
        def __init__(self, rig: SimRig) -> None:
            self.rig = rig

        def update(self, now_ns: int) -> None:
            self.rig.robot.servo_tcp((0.3, 0.0, 0.099), self.rig.robot.orientation)

    rig = SimRig(SimRigConfig(seed=2))
    rig.attach_teleop(Servo(rig))
    for k in range(1, 400):
        rig.advance(k * 1_000_000)
    assert rig.one_call_ticks == 0
    assert rig.indentation_m > 0.0005  # the servo pressed the tip into the tissue


def test_kernels_are_compiled_when_a_rig_is_built() -> None:
    """A rig is built with its kernels compiled or loaded: its loop's first tick waits for no compiler (in a fresh
    process: this one's may have compiled them already)."""
    compiled_on_construction(
        "from pipeline.sim import hand, robot, sensor, tissue, touch\n"
        "from pipeline.devices import touch_output\n"
        "from pipeline.sim.rig import SimRig, step_kernel, target_kernel",
        "(step_kernel, target_kernel, hand.step_kernel, robot.advance_kernel, robot.command_kernel, tissue.step_kernel,"
        " sensor.sample_kernel, touch.advance_kernel, touch_output.render_kernel, touch_output.command_kernel)",
        "SimRig()")


def test_a_copy_shares_its_own_state() -> None:
    """A rig's copy keeps its models' states in its own array, as the original does."""
    rig = copy.deepcopy(SimRig())
    rig.robot.teleport((0.3, 0.0, 0.098))
    assert math.isclose(rig.indentation_m, 0.002, rel_tol=1e-12)  # 0.1 - 0.098 in doubles


def test_state_views() -> None:
    """The models of a rig keep their states in the rig's array: a model's change is the rig's."""
    rig = SimRig()
    rig.robot.teleport((0.3, 0.0, 0.105))
    assert rig.indentation_m == 0.0 and rig.robot.position_m == [0.3, 0.0, 0.105]
    rig.robot.teleport((0.3, 0.0, 0.098))
    assert math.isclose(rig.indentation_m, 0.002, rel_tol=1e-12)  # 0.1 - 0.098 in doubles
    arm = CompliantArm()
    assert arm.step(0.01, 0.0, 0.001) == arm.y_m != 0.0
