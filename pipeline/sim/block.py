"""A simulated rig's loop ticks in compiled blocks: the same ticks, bit for bit, at a fraction of the interpreter's
cost.

A simulated study is a million ticks a participant; as Python, each tick is a hundred-odd lines spread over the rig,
the Touch, the participant, the sensor, the robot, the loop and the arm's channel, at ~50 ns a line.  On a virtual
clock nothing waits between ticks, so :class:`SimBlocks` runs them as one compiled call (:func:`block_kernel`) until
something only Python does is due, and hands that tick to the loop's own Python:

* **before a tick** (nothing of it done yet): the participant's next event (a decision, a look, the start of the
  approach) or a time jump, the drift's next knot when its normals are used up, the sensor's next block of noise;
  and at a block's start, whatever the loop, the rig or the participant holds in Python only -- a queued command or
  a replay snapshot, a commanded force program, a fault being rehearsed, a teleoperation driver, a re-orientation, a
  frozen robot, a device error, a tracking trial or a trial being staged, a driver that is not the simulated
  participant (:meth:`SimBlocks.ready`): the tick is :meth:`pipeline.runtime.loop.HapticLoop.tick`;
* **after the rig's step** (the arm's part not begun): a watchdog condition that changes, a robot pose that is new
  in orientation or not finite, the device's error or derated limit changing: the arm's part is
  :meth:`pipeline.runtime.loop.HapticLoop.arms_tick`.

The arithmetic of every step of a tick in the block is the kernel its Python calls (one implementation): the
Touch's step (:func:`pipeline.sim.touch.advance_kernel`), the participant's tick
(:func:`pipeline.sim.participant_tick.remember_kernel`, :func:`~pipeline.sim.participant_tick.plan_kernel`), the
rig's physics (:func:`pipeline.sim.rig.step_kernel`), the watchdog's conditions
(:func:`pipeline.runtime.arm_channel.conditions_kernel`), the bias refinement
(:func:`pipeline.force.framework.refine_kernel`), Algorithm 1 and the record
(:func:`pipeline.runtime.arm_channel.record_kernel`) and the command
(:func:`pipeline.devices.touch_output.command_kernel`).  What the block writes again, as the lines it mirrors: the
sequencing (the order of :meth:`pipeline.sim.rig.SimRig.advance` and
:meth:`pipeline.runtime.arm_channel.ArmChannel.tick`), the rig's glue (the step's clamp, the felt force along the
hand's axis, the observation, the stylus, the truth), the tests that hand a tick to Python (the participant's time
window and next event; the arm's conditions changing, a pose's finiteness, the device's error or limit) and the
arm's switches (feedback enabled without a fault, the refinement without one); and the bookkeeping the Python
objects are given back when a block ends (their newest sample, pose, observation, counters; the records into the
ring, the poses into the replay log).  A change to those lines of the Python must be made here too:
``tests/pipeline/test_sim_block.py`` holds a loop's and a study's ticks run in blocks to the same ticks run one by
one, every record, replay-log entry, state and event, bit for bit.

One arm, a virtual clock, a private ring (no reader in another process or thread: the block writes its records
into the ring when it ends): what a simulated study's engine is (:func:`pipeline.assembly.engine.build_sim_engine`
installs it there); any other loop runs tick by tick.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from pipeline.core import exact, record_writer
from pipeline.core.clock import Clock, VirtualClock
from pipeline.core.compiled import State, fingerprint, is_warm, kernel, warm_once
from pipeline.core.record_writer import IntRow
from pipeline.core.tick_record import RECORD_FIELDS
from pipeline.devices import touch_output
from pipeline.force import bias_refinement, filters, frames, safety, scaling
from pipeline.force import framework as algorithm_1
from pipeline.runtime import arm_channel
from pipeline.runtime.loop import HapticLoop
from pipeline.sim import hand, participant_tick, sensor, tissue
from pipeline.sim import rig as sim_rig
from pipeline.sim import robot as sim_robot
from pipeline.sim import touch as sim_touch
from pipeline.sim.hand import HandObservation, HoldStill
from pipeline.sim.participant import SimulatedParticipant
from pipeline.sim.rig import SimRig

__all__ = ["SimBlocks", "arm_kernel", "block_kernel", "due_kernel", "hold_kernel", "hold_still", "observe_kernel",
           "physics_kernel", "rig_kernel", "step_s", "warm_kernels"]

# The block's state, one float64 array and its int64 view (the layout below): what the Python objects hold that a
# tick reads or changes, gathered when a block starts and given back when it ends.
# -- integers (the int64 view): times in ns, counters, codes
_NOW0, _PERIOD, _RIG_LAST, _ROBOT_ORIGIN, _SENSOR_ORIGIN, _TICK, _T0, _W_T, _W_STATUS, _POSE_T = range(10)
_CH_POSE_T, _FAULTS, _ACTIVE, _TRIAL, _PHASE, _ERR, _NI, _NOISE_ROWS, _SENSOR_MAX_AGE, _POSE_MAX_AGE = range(10, 20)
_ONE_AXIS, _N_POSES, _DONE, _STOP, _STARTED, _PUBLISHED, _CYCLED = range(20, 27)
# -- floats
_SIM_TIME, _AXIS, _ONE_SIGN, _SURFACE, _PUSH, _DEV_LIMIT, _LIMIT_N, _STATIC_LIMIT = 27, 28, 31, 32, 33, 36, 37, 38
_ON, _REFINE, _RECORDING, _DERATE_CHECK, _ROT_SAME, _ROT_SUM = 39, 40, 41, 42, 43, 44
_TIP, _Y, _F, _OBS = 45, 48, 49, 50
_SIZE = _OBS + 5
# how a block ended: every tick asked run; a tick's Python is due before it; the arm's part of a tick is Python's; the
# sensor's noise or the participant's normals are used up (drawn in Python, and the block goes on)
_RAN_ALL, _BEFORE, _MID, _NOISE, _NORMALS = 0, 1, 2, 3, 4

_R, _S = sim_rig.ROBOT_AT, sim_rig.SENSOR_AT


@kernel
def step_s(bi: IntRow, now: int) -> float:
    """The rig's step to the tick at ``now``, s (:meth:`pipeline.sim.rig.SimRig.advance`'s: at most ``MAX_DT_S``)."""
    dt = (now - bi[_RIG_LAST]) * 1e-9
    if dt < 0.0:
        return 0.0
    return sim_rig.MAX_DT_S if dt > sim_rig.MAX_DT_S else dt


def _compile_due(callees: int) -> Any:
    """:func:`due_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def due_kernel(b: State, bi: IntRow, ps: State, now: int) -> tuple[int, float, float]:
        """Whether Python is due before the tick at ``now`` (nothing of it done yet): its stop, or :data:`_RAN_ALL`
        for none, with the rig's step (s) and the participant's time then (:meth:`pipeline.sim.rig.SimRig.advance`'s
        and :meth:`pipeline.sim.participant.SimulatedParticipant.equilibrium_y`'s)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        dt = step_s(bi, now)
        t = b[_SIM_TIME] + dt
        pdt = t - ps[participant_tick.T_AT]
        if not (-0.5 <= pdt <= 0.5) or t >= ps[participant_tick.NEXT_AT]:
            return _BEFORE, dt, t
        if bi[_NI] >= bi[_NOISE_ROWS]:
            return _NOISE, dt, t
        if participant_tick.normals_short(ps, t):
            return _NORMALS, dt, t
        return _RAN_ALL, dt, t

    return due_kernel


def _compile_observe(callees: int) -> Any:
    """:func:`observe_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def observe_kernel(b: State, bi: IntRow, st: State, tst: State, tint: IntRow, now: int, dt: float,
                       t: float) -> float:
        """The rig's step of the tick at ``now`` up to the hand's decision (:meth:`pipeline.sim.rig.SimRig.advance`):
        the Touch renders, the hand's observation into the block's state; returns the felt force (N)."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        bi[_RIG_LAST] = now
        b[_SIM_TIME] = t
        ax, ay, az, err = sim_touch.advance_kernel(tst, tint, now, dt, bi[_ERR])
        bi[_ERR] = err
        one = bi[_ONE_AXIS]
        if one >= 0:  # one device axis: that component, exactly
            felt = (ax if one == 0 else (ay if one == 1 else az)) * b[_ONE_SIGN]
        else:
            felt = ax * b[_AXIS] + ay * b[_AXIS + 1] + az * b[_AXIS + 2]
        depth = b[_SURFACE] - st[_R + 2]
        b[_OBS], b[_OBS + 1], b[_OBS + 2] = t, st[sim_rig.ARM_AT], felt
        b[_OBS + 3], b[_OBS + 4] = depth if depth > 0 else 0.0, -depth if depth < 0 else 0.0
        return float(felt)

    return observe_kernel


def _compile_physics(callees: int) -> Any:
    """:func:`physics_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def physics_kernel(b: State, bi: IntRow, st: State, noise: State, y_c: float, felt: float, now: int,
                       dt: float) -> None:
        """The rig's step of the tick at ``now`` after the hand's decision ``y_c`` (the rig's ``step_kernel``); the
        newest sample and pose into the block's state."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        ni = bi[_NI]
        bi[_NI] = ni + 1
        # (the record's six values are in the sensor's state, read as the newest sample's)
        y, f, cycled, what, _r0, _r1, _r2, _r3, _r4, _r5 = sim_rig.step_kernel(
            st, noise, ni, y_c, felt, dt, now - bi[_ROBOT_ORIGIN], now - bi[_SENSOR_ORIGIN])
        b[_Y], b[_F] = y, f
        if cycled:  # the robot's controller published its pose (SimRobot.cycled)
            bi[_POSE_T] = now
            bi[_CYCLED] = 1
            p = _R + sim_robot.POSE_AT
            b[_TIP], b[_TIP + 1], b[_TIP + 2] = st[p], st[p + 1], st[p + 2]
        if what >= sensor.RECORD:  # a new newest sample (SimForceSensor.took)
            bi[_W_T] = now
            bi[_W_STATUS] = int(st[_S + sensor.STATUS_AT])
            bi[_PUBLISHED] += 1

    return physics_kernel


def _compile_rig(callees: int) -> Any:
    """:func:`rig_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def rig_kernel(b: State, bi: IntRow, st: State, noise: State, tst: State, tint: IntRow, ps: State, hist: State,
                   z: State, now: int, dt: float, t: float) -> None:
        """The rig's step of the tick at ``now`` (:meth:`pipeline.sim.rig.SimRig.advance`) with the simulated
        participant's decision."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        felt = observe_kernel(b, bi, st, tst, tint, now, dt, t)
        ps[participant_tick.T_AT] = t
        participant_tick.remember_kernel(ps, hist, t, b[_OBS + 1], felt, b[_OBS + 3], b[_OBS + 4])
        physics_kernel(b, bi, st, noise, participant_tick.plan_kernel(ps, z, t), felt, now, dt)

    return rig_kernel


def _compile_arm(callees: int) -> Any:
    """:func:`arm_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def arm_kernel(b: State, bi: IntRow, st: State, tst: State, tint: IntRow, fw: State, rls: State, sat: State,
                   row_f: State, row_i: IntRow, poses: State, now: int, period: int) -> bool:
        """The arm's part of the tick at ``now`` (:meth:`pipeline.runtime.arm_channel.ArmChannel.tick`), its record
        into ``row_f``/``row_i``; False, and nothing done, when it is Python's: a watchdog condition changes, the
        pose is new in orientation or not finite, the device's error or derated limit changed."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        w_t = bi[_W_T]
        o = _S + sensor.OUT
        r0, r1, r2, r3, r4, r5 = st[o], st[o + 1], st[o + 2], st[o + 3], st[o + 4], st[o + 5]
        cond, sensor_age_ns, pose_age_ns = arm_channel.conditions_kernel(
            sat, bi[_SENSOR_MAX_AGE], bi[_POSE_MAX_AGE], now, w_t, r0, r1, r2, r3, r4, r5, bi[_W_STATUS], bi[_POSE_T])
        new_pose = bi[_POSE_T] != bi[_CH_POSE_T]
        if new_pose:
            total = b[_ROT_SUM] + (b[_TIP] + b[_TIP + 1] + b[_TIP + 2])
            if b[_ROT_SAME] == 0.0 or total - total != 0.0:
                return False
        faults = bi[_FAULTS]
        if (bi[_ERR] != 0 or tst[touch_output.LIMIT_AT] != b[_DEV_LIMIT] or cond != bi[_ACTIVE]
                or cond & ~faults):
            return False
        if new_pose:  # the framework's pose is this orientation already (_ROT_SAME): only its time is new
            bi[_CH_POSE_T] = bi[_POSE_T]
            if b[_RECORDING] != 0.0:
                j = bi[_N_POSES]
                poses[j, 0], poses[j, 1], poses[j, 2] = bi[_TICK], b[_TIP], b[_TIP + 1]
                poses[j, 3], poses[j, 4] = b[_TIP + 2], bi[_POSE_T]
                bi[_N_POSES] = j + 1
        if b[_REFINE] != 0.0 and faults == 0:
            algorithm_1.refine_kernel(fw, rls, r0, r1, r2, r3, r4, r5)
        on = b[_ON] != 0.0
        enabled = on and faults == 0
        haptic_on = 1 if on else 0
        derate_check = b[_DERATE_CHECK] != 0.0
        true_fz = b[_F] + b[_PUSH + 2]
        y = b[_Y]
        ax_y, ay_y, az_y = b[_AXIS] * y, b[_AXIS + 1] * y, b[_AXIS + 2] * y  # the stylus (SimRig.advance)
        sx = ax_y if b[_AXIS] != 0.0 else 0.0
        sy = ay_y if b[_AXIS + 1] != 0.0 else 0.0
        sz = az_y if b[_AXIS + 2] != 0.0 else 0.0
        rfx, rfy, rfz = arm_channel.record_kernel(
            fw, row_f, row_i, r0, r1, r2, r3, r4, r5, 0.0, False, enabled, period * 1e-9, derate_check,
            b[_LIMIT_N], b[_STATIC_LIMIT], bi[_TICK], now - bi[_T0], period, sensor_age_ns, pose_age_ns, faults,
            haptic_on, bi[_TRIAL], bi[_PHASE], sx, sy, sz, b[_TIP], b[_TIP + 1], b[_TIP + 2], b[_PUSH],
            b[_PUSH + 1], true_fz)
        touch_output.command_kernel(tst, tint, rfx, rfy, rfz, now)
        row_i[arm_channel.LATENCY_AT] = now - w_t  # (on a virtual clock: the sample's age)
        bi[_TICK] += 1
        return True

    return arm_kernel


_TICK_MODULES = (exact, frames, filters, safety, scaling, algorithm_1, bias_refinement, record_writer, arm_channel,
                 touch_output, sim_touch, hand, participant_tick, sim_robot, tissue, sensor, sim_rig)
#: Whether Python is due before a tick; the rig's step to the hand's decision, after it, and with the simulated
#: participant's; the arm's part (block_kernel's steps, compiled).
due_kernel = _compile_due(fingerprint(*_TICK_MODULES))
observe_kernel = _compile_observe(fingerprint(*_TICK_MODULES))
physics_kernel = _compile_physics(fingerprint(*_TICK_MODULES))
rig_kernel = _compile_rig(fingerprint(*_TICK_MODULES))
arm_kernel = _compile_arm(fingerprint(*_TICK_MODULES))


def _compile_block(callees: int) -> Any:
    """:func:`block_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def block_kernel(n: int, b: State, bi: IntRow, st: State, noise: State, tst: State, tint: IntRow, ps: State,
                     hist: State, z: State, fw: State, rls: State, sat: State, rows: State, rows_i: Any,
                     poses: State) -> None:
        """Up to ``n`` ticks of a one-arm simulated loop from the block's state ``b``/``bi`` (the module's layout),
        the rig's state ``st`` and its sensor's ``noise``, the Touch output's ``tst``/``tint``, the participant's
        ``ps``, ``hist`` and ``z``, the framework's ``fw`` and its bias estimator's ``rls``, the watchdog's
        saturation limits ``sat``; each tick's record into ``rows``/``rows_i``, each pose logged for replay into
        ``poses`` (tick, x, y, z, t_ns).  How many ran whole, how many began and why it stopped are ``bi[_DONE]``,
        ``bi[_STARTED]``, ``bi[_STOP]``."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        period = bi[_PERIOD]
        now = bi[_NOW0]
        k = started = 0
        stop = _RAN_ALL
        while k < n:
            stop, dt, t = due_kernel(b, bi, ps, now)
            if stop != _RAN_ALL:
                break
            started += 1
            rig_kernel(b, bi, st, noise, tst, tint, ps, hist, z, now, dt, t)
            if not arm_kernel(b, bi, st, tst, tint, fw, rls, sat, rows[k], rows_i[k], poses, now, period):
                stop = _MID
                break
            k += 1
            now += period
        bi[_DONE] = k
        bi[_STOP] = stop
        bi[_STARTED] = started

    return block_kernel


#: Ticks of a one-arm simulated loop in one compiled call (:class:`SimBlocks`).
block_kernel = _compile_block(fingerprint(*_TICK_MODULES))


def _compile_hold(callees: int) -> Any:
    """:func:`hold_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls."""

    @kernel
    def hold_kernel(n: int, b: State, bi: IntRow, st: State, noise: State, tst: State, tint: IntRow, y_c: float,
                    sums: State) -> None:
        """Up to ``n`` ticks of the rig alone, the hand holding ``y_c`` (:func:`hold_still`), from the block's state
        ``b``/``bi``; each tick's newest wrench added into ``sums`` (if it has six entries).  How many ran and why it
        stopped are ``bi[_DONE]``, ``bi[_STOP]``."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        period = bi[_PERIOD]
        now = bi[_NOW0]
        o = _S + sensor.OUT
        k = 0
        stop = _RAN_ALL
        while k < n:
            if bi[_NI] >= bi[_NOISE_ROWS]:
                stop = _NOISE
                break
            dt = step_s(bi, now)
            felt = observe_kernel(b, bi, st, tst, tint, now, dt, b[_SIM_TIME] + dt)
            physics_kernel(b, bi, st, noise, y_c, felt, now, dt)
            if len(sums) == 6:
                for i in range(6):
                    sums[i] += st[o + i]
            k += 1
            now += period
        bi[_DONE] = bi[_STARTED] = k
        bi[_STOP] = stop

    return hold_kernel


#: Ticks of the rig alone, the hand held still, in one compiled call (:func:`hold_still`).
hold_kernel = _compile_hold(fingerprint(*_TICK_MODULES))

_new_tuple = tuple.__new__


class SimBlocks:
    """Runs a one-arm simulated loop's ticks in compiled blocks (see the module's docstring): the loop's
    :attr:`~pipeline.runtime.pacing.PacedTicks.block_runner`.

    Parameters
    ----------
    loop
        The loop (one arm, a virtual clock, a private ring or none).
    rig
        Its simulated rig.
    """

    #: Most ticks in one compiled call (the records it holds until it ends).
    ROWS = 256

    def __init__(self, loop: HapticLoop, rig: SimRig) -> None:
        if len(loop.arms) != 1 or loop.rig is not rig:
            raise ValueError("SimBlocks runs a one-arm loop of this simulated rig")
        ring = loop.ring
        if ring is not None and ring.segment:
            raise ValueError("SimBlocks writes a block's records when it ends: its loop's ring must be private")
        self.loop, self.rig, self.ch = loop, rig, loop.arms[0]
        self.rows: State = np.zeros((self.ROWS, len(RECORD_FIELDS)))
        self.rows_i: Any = self.rows.view(np.int64)
        self.poses: State = np.zeros((self.ROWS, 5))
        self.b: State = np.zeros(_SIZE)
        self.bi: IntRow = self.b.view(np.int64)
        self._no_rls: State = np.zeros(1)
        # the sensor's noise drawn 4096 rows at once from its next draw on (the same stream as 64 at a time: one
        # generator's consecutive draws), so that a refill, a block's pause, comes every 4 s of ticks, not 64 ms
        rig.sensor.rows_per_draw = 4096
        #: Ticks run in compiled blocks, one by one in Python, and in a block up to their arm's part (diagnostics).
        self.block_ticks = 0
        self.python_ticks = 0
        self.half_ticks = 0
        warm_once(__name__, self._compile)

    def run_ticks(self, n: int) -> None:
        """Run ``n`` ticks paced on the (virtual) clock, as :meth:`pipeline.runtime.pacing.PacedTicks.run_ticks`
        does, in compiled blocks where nothing on the Python side is due."""
        loop = self.loop
        clock = loop.clock
        period = loop.period_ns
        deadline = clock.now_ns()
        done = 0
        while done < n:
            stop = _BEFORE
            if self.ready(deadline):
                k, stop = self._block(min(n - done, self.ROWS), deadline)
                done += k
                deadline += k * period
                clock.sleep_until(deadline)
                if stop == _NOISE:  # (drawn where the tick would draw them: the rig's random streams are its own)
                    self.rig.sensor.refill_noise()
                elif stop == _NORMALS:
                    cast(SimulatedParticipant, self.rig.driver).more_normals()
                if stop in (_RAN_ALL, _NOISE, _NORMALS):
                    continue
            if stop == _MID:  # the rig's step of this tick ran in the block; the arm's part is Python's
                loop.arms_tick(deadline, period, period * 1e-9)
                self.half_ticks += 1
            else:
                loop.tick()
            self.python_ticks += 1
            done += 1
            deadline += period
            clock.sleep_until(deadline)

    def ready(self, now: int) -> bool:
        """Whether a block may start with the tick at ``now``: nothing the loop, the rig or the participant holds in
        Python only is due in it (see the module's docstring)."""
        loop, rig, ch = self.loop, self.rig, self.ch
        driver = rig.driver
        # (the exact class: a subclass may decide otherwise than the compiled tick)
        return (not loop.tick_due_work and now - cast(int, loop.last_tick_ns) == loop.period_ns
                and ch.program is None and ch.pose_time_ns is not None and rig.steps_elsewhere
                and type(driver) is SimulatedParticipant and driver.between_events and now < 2**53)

    def _block(self, n: int, now: int) -> tuple[int, int]:
        """One compiled call of up to ``n`` ticks from ``now``; the Python objects given back their state.  Returns
        the ticks run whole and how it stopped."""
        loop, rig, ch = self.loop, self.rig, self.ch
        b, bi = self.b, self.bi
        p = cast(SimulatedParticipant, rig.driver)
        fw = ch.framework
        rls = fw.rls
        _gather_rig(b, bi, rig, now, loop.period_ns)
        bi[_TICK], bi[_T0], bi[_CH_POSE_T] = loop.tick_count, loop.t0_ns, cast(int, ch.pose_time_ns)
        bi[_FAULTS], bi[_ACTIVE], bi[_TRIAL], bi[_PHASE] = ch.faults, ch.active_faults, loop.trial_index, loop.phase
        bi[_SENSOR_MAX_AGE], bi[_POSE_MAX_AGE] = ch.max_ages_ns
        bi[_N_POSES] = 0
        g = fw.safety
        b[_DEV_LIMIT], b[_LIMIT_N], b[_STATIC_LIMIT] = ch.device_limit_n, g.limit_n, g.static_limit_n
        b[_ON], b[_REFINE] = loop.haptic_on, loop.refine_bias and rls is not None
        b[_RECORDING], b[_DERATE_CHECK] = loop.recording, ch.derate_check
        # every pose a new one in the block: the last published (rig.steps_elsewhere: at the robot's orientation) or
        # one its cycles publish, at that orientation
        rot = rig.robot.orientation
        b[_ROT_SAME], b[_ROT_SUM] = fw.rot_base_tip == rot, sum(rot)  # (the sum: only whether it is finite)
        out, rls_array = rig.haptic.output, self._no_rls if rls is None else rls.array
        block_kernel(n, b, bi, rig.state, rig.sensor.noise, out.array, out.ints, p.array, p.history, p.normals,
                     fw.array, rls_array, ch.saturation_n, self.rows, self.rows_i, self.poses)
        # -- give back --
        k, stop, started = int(bi[_DONE]), int(bi[_STOP]), int(bi[_STARTED])
        if not started:
            return 0, stop
        last = _give_back_rig(b, bi, rig, now, loop.period_ns)
        loop.ticked_elsewhere(started, k, last)
        ch.ran_block(self.rows, k, int(bi[_CH_POSE_T]), self.poses, int(bi[_N_POSES]), rot)
        self.block_ticks += k
        return k, stop

    def _compile(self) -> None:
        """Compile :func:`block_kernel` (or load it from numba's cache) once a process, on scratch copies of this
        loop's states, for none of its ticks (a block of zero ticks)."""
        rig, ch = self.rig, self.ch
        out = rig.haptic.output.array.copy()
        block_kernel(0, self.b.copy(), self.bi.copy(), rig.state.copy(), rig.sensor.noise.copy(), out,
                     out.view(np.int64), np.zeros(participant_tick.STATE_SIZE), np.zeros((5, 1)), np.zeros(1),
                     ch.framework.array.copy(), np.zeros(1), ch.saturation_n.copy(), self.rows.copy(),
                     self.rows_i.copy(), self.poses.copy())


def _gather_rig(b: State, bi: IntRow, rig: SimRig, now: int, period_ns: int) -> None:
    """What a block's rig step reads of the Python objects (:func:`observe_kernel`, :func:`physics_kernel`), into its
    state, for a block from the tick at ``now`` (the times :meth:`pipeline.sim.rig.SimRig.steps_elsewhere` found set:
    cast)."""
    sens, robot = rig.sensor, rig.robot
    w, pose = sens.read_wrench(), robot.read_pose()
    bi[_NOW0], bi[_PERIOD], bi[_RIG_LAST] = now, period_ns, cast(int, rig.last_ns)
    bi[_ROBOT_ORIGIN], bi[_SENSOR_ORIGIN] = cast(int, robot.origin_ns), cast(int, sens.origin_ns)
    bi[_W_T], bi[_W_STATUS], bi[_POSE_T] = w.t_ns, w.status, pose.t_ns
    b[_TIP:_TIP + 3] = pose.position_m
    bi[_ERR], bi[_NI], bi[_NOISE_ROWS] = rig.haptic.error_code, sens.noise_row, len(sens.noise)
    one = rig.hand_one_axis
    bi[_ONE_AXIS] = -1 if one is None else one[0]
    b[_ONE_SIGN] = 0.0 if one is None else one[1]
    bi[_PUBLISHED] = bi[_CYCLED] = 0
    b[_SIM_TIME], b[_SURFACE] = rig.sim_time_s, rig.config.surface_z_m
    b[_AXIS:_AXIS + 3], b[_PUSH:_PUSH + 3] = rig.hand_axis, rig.push_base_n


def _give_back_rig(b: State, bi: IntRow, rig: SimRig, now: int, period_ns: int) -> int:
    """The rig, its sensor and its robot take what the block's rig steps, from the tick at ``now``, left; returns the
    clock reading of the last."""
    started = int(bi[_STARTED])
    last = now + (started - 1) * period_ns
    rig.ran_block(started, last, b.item(_SIM_TIME), b.item(_F),
                  _new_tuple(HandObservation, (b.item(_OBS), b.item(_OBS + 1), b.item(_OBS + 2), b.item(_OBS + 3),
                                               b.item(_OBS + 4))), b.item(_Y), int(bi[_ERR]))
    rig.sensor.ran_block(int(bi[_NI]), int(bi[_W_T]) if bi[_PUBLISHED] else None)
    if bi[_CYCLED]:
        rig.robot.cycled(int(bi[_POSE_T]))
    return last


def hold_still(rig: SimRig, clock: Clock, ticks: int, sums: list[float] | None = None,
               period_ns: int = 1_000_000) -> None:
    """Step the rig alone ``ticks`` times, ``period_ns`` apart on ``clock``, the hand holding the stylus where its
    :class:`pipeline.sim.hand.HoldStill` holds it, each tick's newest wrench added into ``sums`` (six, N and N·m):
    the simulated calibration's settling and averaging at each pose (:mod:`pipeline.sim.calibration`), as
    :meth:`pipeline.sim.rig.SimRig.advance` a tick at a time would, in compiled blocks on a virtual clock
    (:func:`hold_kernel`; tick by tick while the robot turns to the pose, or on another clock)."""
    warm_once(__name__ + ".hold", _compile_hold_once)
    b = np.zeros(_SIZE)  # (its own: rigs of studies run in threads of one process, a Dask worker's, each have one)
    bi = b.view(np.int64)
    acc = np.array(sums if sums is not None else (), dtype=np.float64)
    t = clock.now_ns()
    done = 0
    while done < ticks:
        if _hold_ready(rig, clock, t + period_ns):
            _gather_rig(b, bi, rig, t + period_ns, period_ns)
            out = rig.haptic.output
            hold_kernel(ticks - done, b, bi, rig.state, rig.sensor.noise, out.array, out.ints,
                        float(cast(HoldStill, rig.driver).y_m), acc)
            k, stop = int(bi[_DONE]), int(bi[_STOP])
            if k:
                _give_back_rig(b, bi, rig, t + period_ns, period_ns)
                done += k
                t += k * period_ns
                clock.sleep_until(t)
            if stop == _NOISE:  # (drawn where the tick would draw it)
                rig.sensor.refill_noise()
                continue
            if stop == _RAN_ALL:
                continue
        t += period_ns
        clock.sleep_until(t)
        rig.advance(clock.now_ns())
        if len(acc):
            w = rig.sensor.read_wrench()
            for i in range(6):
                acc[i] += w[1 + i]
        done += 1
    if sums is not None:
        sums[:] = acc.tolist()


def _hold_ready(rig: SimRig, clock: Clock, now: int) -> bool:
    """Whether the rig's tick at ``now`` may run in a block held still (a virtual clock, nothing due in Python)."""
    return (type(clock) is VirtualClock and type(rig.driver) is HoldStill and rig.steps_elsewhere and now < 2**53)


def _compile_hold_once() -> None:
    """Compile :func:`hold_kernel` (or load it from numba's cache) once a process, for no tick, on scratch states."""
    b = np.zeros(_SIZE)
    out = np.zeros(touch_output.STATE_SIZE)
    hold_kernel(0, b, b.view(np.int64), np.zeros(1), np.zeros((1, 13)), out, out.view(np.int64), 0.0, np.zeros(6))


def warm_kernels() -> None:
    """Compile a simulated study's kernels (or load them from numba's cache), once a process: the rig's, the
    participant's, Algorithm 1's, the arm's and the block's, on scratch objects.  What a parent that forks a process
    per participant calls before forking (:func:`study_app.headless.pool.run_parallel`): its children inherit the
    machine code instead of each loading it (~0.2 s of a core a participant)."""
    if is_warm(__name__):
        return
    rig = SimRig()
    rig.set_driver(SimulatedParticipant())
    framework = algorithm_1.HapticFramework(algorithm_1.FrameworkConfig(), device_peak_n=rig.haptic.peak_force_n)
    SimBlocks(HapticLoop(rig, framework, VirtualClock()), rig)
    warm_once(__name__ + ".hold", _compile_hold_once)
