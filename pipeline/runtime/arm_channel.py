"""One arm's pipeline inside the 1 kHz loop: its devices, its Algorithm 1, its watchdog state, its ring.

A rig has one or more arms (:func:`pipeline.devices.rig.rig_arms`); the loop
(:class:`pipeline.runtime.loop.HapticLoop`) holds one :class:`ArmChannel` per
arm and runs the same tick body, :meth:`ArmChannel.tick`, for each in the same
tick: the arm's own F/T sample and robot pose, its watchdog (faults latched per
arm), its :class:`pipeline.force.framework.HapticFramework` (safety, slew and
ramp-in per arm), its haptic device's command, and one record in the arm's own
ring (the tick-record dtype of :mod:`pipeline.core.tick_record`).

What one arm's fault does to the others is the loop's policy
(:data:`pipeline.settings.hardware.FAULT_POLICIES`): with ``both`` the other
arms latch ``Fault.OTHER_ARM`` and ramp to zero too; with ``independent`` they
keep rendering.  Every event a channel emits carries its arm's name.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np

from pipeline.core import exact, record_writer
from pipeline.core.clock import Clock
from pipeline.core.compiled import State, fingerprint, is_warm, kernel, warm_once
from pipeline.core.force_program import ForceProgram
from pipeline.core.record_writer import IntRow, write_record
from pipeline.core.tick_record import RECORD_FIELDS, TICK_DTYPE
from pipeline.devices.interfaces import Fault, HapticState, PoseSample, WrenchSample
from pipeline.devices.rig import RigArm
from pipeline.devices.touch_output import DEFAULT_COMMAND_TIMEOUT_S
from pipeline.force import filters, frames, safety, scaling
from pipeline.force import framework as algorithm_1
from pipeline.force.framework import HapticFramework
from pipeline.runtime.loop_messages import LoopEvent
from pipeline.runtime.watchdog import WatchdogConfig, derating_detail, derating_ended_detail, fault_detail

if TYPE_CHECKING:
    from pipeline.runtime.ring import RingBuffer

__all__ = ["LATENCY_AT", "RECORD_KERNEL_TYPES", "RIG_WIDE_FAULTS", "ArmChannel", "LoopSide", "conditions_kernel",
           "own_faults", "record_kernel", "warm_kernels"]


class LoopSide(Protocol):
    """What a channel reads of the loop that runs it (:class:`pipeline.runtime.loop.HapticLoop`)."""

    watchdog: WatchdogConfig
    clock: Clock
    t0_ns: int
    tick_count: int
    trial_index: int
    phase: int
    haptic_on: bool
    refine_bias: bool
    recording: bool

    def emit(self, ev: LoopEvent) -> None:
        """Record and pass on an event."""
        ...

    def arm_faulted(self, ch: ArmChannel, new: int, now: int) -> None:
        """An arm latched new faults (the fault policy acts on the others)."""
        ...

_NAN3 = (math.nan, math.nan, math.nan)


_LATENCY = RECORD_FIELDS.index("latency_ns")  # written after the command is handed over (see ArmChannel.tick)
#: Where the record's latency is (written once the command is handed over).
LATENCY_AT = _LATENCY
_INTEGER = tuple(TICK_DTYPE[n] == np.int64 for n in RECORD_FIELDS)
# the watchdog's conditions as plain ints (an IntFlag's | runs in Python; a kernel takes ints)
_SENSOR_STALE, _SENSOR_STATUS, _NON_FINITE = int(Fault.SENSOR_STALE), int(Fault.SENSOR_STATUS), int(Fault.NON_FINITE)
_SENSOR_SATURATION, _POSE_STALE = int(Fault.SENSOR_SATURATION), int(Fault.POSE_STALE)


@kernel
def conditions_kernel(sat: State, sensor_max_age_ns: int, pose_max_age_ns: int, now: int, w_t_ns: int, fx: float,
                      fy: float, fz: float, tx: float, ty: float, tz: float, status: int,
                      pose_t_ns: int) -> tuple[int, int, int]:
    """The watchdog's conditions this tick from the sample and the pose's time: a stale sample or pose, a bad status
    word, a non-finite or saturated value (``sat``: the six saturation limits); returns them (``Fault`` bits) with
    the sample's and the pose's ages (ns)."""
    cond = 0
    sensor_age_ns = now - w_t_ns
    if sensor_age_ns > sensor_max_age_ns:
        cond |= _SENSOR_STALE
    if status != 0:
        cond |= _SENSOR_STATUS
    if (fx - fx) + (fy - fy) + (fz - fz) + (tx - tx) + (ty - ty) + (tz - tz) != 0.0:
        cond |= _NON_FINITE
    elif not (-sat[0] <= fx <= sat[0] and -sat[1] <= fy <= sat[1] and -sat[2] <= fz <= sat[2]
              and -sat[3] <= tx <= sat[3] and -sat[4] <= ty <= sat[4] and -sat[5] <= tz <= sat[5]):
        cond |= _SENSOR_SATURATION  # (|v| > s as -s <= v <= s failing: v is finite here)
    pose_age_ns = now - pose_t_ns
    if pose_age_ns > pose_max_age_ns:
        cond |= _POSE_STALE
    return cond, sensor_age_ns, pose_age_ns


def _compile(callees: int) -> Callable[..., tuple[float, float, float]]:
    """:func:`record_kernel` closed over the :func:`pipeline.core.compiled.fingerprint` of the modules it calls (numba
    keys its cache on a kernel's own file and closure)."""

    @kernel
    def record_kernel(fw: State, rf: State, ri: IntRow, raw_fx: float, raw_fy: float, raw_fz: float, raw_tx: float,
                      raw_ty: float, raw_tz: float, command_n: float, commanded: bool, enabled: bool, dt_s: float,
                      derate_check: bool, limit_n: float, static_limit_n: float, tick: int, t_ns: int,
                      period_ns: int, sensor_age_ns: int, pose_age_ns: int, faults: int, haptic_on: int,
                      trial_index: int, phase: int, stylus_x_m: float, stylus_y_m: float, stylus_z_m: float,
                      tip_x_m: float, tip_y_m: float, tip_z_m: float, true_fx: float, true_fy: float,
                      true_fz: float) -> tuple[float, float, float]:
        """An arm's tick after its watchdog: Algorithm 1 (:func:`pipeline.force.framework.step_kernel`), the derating
        measure, and the record written into the row ``rf``/``ri`` by name (its latency is the caller's, once the
        command is handed over).  Returns the force to command."""
        _ = callees  # (read, so that it is in the closure numba's cache is keyed on)
        # the stages by their names in pipeline.core.tick_record.STEP_FIELDS (the step's one definition of its output)
        (comp_fx, comp_fy, comp_fz, filt_fx, filt_fy, filt_fz, tip_fx, tip_fy, tip_fz, base_fx, base_fy, base_fz,
         haptic_fx, haptic_fy, haptic_fz, scaled_fx, scaled_fy, scaled_fz, render_fx, render_fy, render_fz,
         ) = algorithm_1.step_kernel(fw, raw_fx, raw_fy, raw_fz, command_n, commanded, enabled, dt_s)
        derate = 1.0
        if derate_check and enabled:
            # the fraction of the designed force (scaled, within the safety stage's own limit) the derated limit
            # lets through (asked only while the thermal limit is below the safety stage's own)
            want = exact.hypot3(scaled_fx, scaled_fy, scaled_fz)
            if want > limit_n:
                derate = limit_n / (want if want < static_limit_n else static_limit_n)
        latency_ns = 0
        gain = fw[algorithm_1.GAIN_AT]
        force_n = exact.hypot3(filt_fx, filt_fy, filt_fz)
        t_s = t_ns * 1e-9
        # the record: every field by its name, in pipeline.core.tick_record.RECORD_FIELDS' order
        write_record(
            rf, ri, tick, t_ns, period_ns, raw_fx, raw_fy, raw_fz, raw_tx, raw_ty, raw_tz, sensor_age_ns,
            pose_age_ns, latency_ns, faults, haptic_on, trial_index, phase, gain, render_fx, render_fy, render_fz,
            force_n, stylus_x_m, stylus_y_m, stylus_z_m, derate, t_s, comp_fx, comp_fy, comp_fz, filt_fx, filt_fy,
            filt_fz, tip_fx, tip_fy, tip_fz, base_fx, base_fy, base_fz, haptic_fx, haptic_fy, haptic_fz, scaled_fx,
            scaled_fy, scaled_fz, tip_x_m, tip_y_m, tip_z_m, true_fx, true_fy, true_fz,
        )
        return render_fx, render_fy, render_fz

    return record_kernel


#: An arm's tick after its watchdog, compiled (:meth:`ArmChannel.tick`).
record_kernel = _compile(fingerprint(exact, frames, filters, safety, scaling, algorithm_1, record_writer))


class ArmChannel:
    """One arm's state in the loop (see the module's docstring).

    Parameters
    ----------
    arm
        The arm's devices and hooks.
    framework
        The arm's force path.
    ring
        Where the arm's records go, or None.
    loop
        The loop that runs it (its clock, tick counter, marks, feedback switch and event path are shared).
    """

    def __init__(self, arm: RigArm, framework: HapticFramework, ring: RingBuffer | None, loop: LoopSide) -> None:
        self.name = arm.name
        self.arm = arm
        self.sensor = arm.sensor
        self.robot = arm.robot
        self.haptic = arm.haptic
        self.framework = framework
        self.ring = ring
        self.loop = loop
        wd: WatchdogConfig = loop.watchdog
        self.faults = 0  # latched
        self.active_faults = 0  # this tick's conditions
        self._gone_reported = 0  # latched faults whose condition was reported gone
        self._pose_t_ns: int | None = None
        self._sensor_age_ns = int(wd.sensor_max_age_s * 1e9)
        self._pose_age_ns = int(wd.pose_max_age_s * 1e9)
        #: The saturation limits (N, N·m), as the watchdog's kernel reads them.
        self.saturation_n = np.array([wd.saturation_fraction * r for r in arm.sensor.range_n], dtype=np.float64)
        # this arm's record of the tick, written by record_kernel (a float64 row and its int64 view: one memory)
        self._row_f: State = np.zeros(len(RECORD_FIELDS))
        self._row_i: IntRow = self._row_f.view(np.int64)
        self._row_bytes = self._row_f.view(np.uint8).data
        self._recorded = False
        #: What replay of this arm needs beyond its records, while recording (see ``StartRecording``).
        self.replay_log: deque[tuple[int, str, object]] = deque()
        self._truth = arm.true_contact_force
        self._on_faults = arm.on_faults
        timeout_s = getattr(arm.haptic, "command_timeout_s", None)
        #: The device drops a command older than this (its own watchdog).
        self.command_timeout_ns = int((timeout_s if timeout_s is not None else DEFAULT_COMMAND_TIMEOUT_S) * 1e9)
        self._peak_n = float(arm.haptic.peak_force_n)
        self._device_limit_n = math.inf  # the device's derated force limit as last seen
        self._derating = False
        self._derate_check = False  # the thermal limit is below the safety stage's own: measure what it cuts
        #: The commanded force rendered instead of the sensor's (None: Algorithm 1's) and the clock reading of the
        #: tick that applied it (:class:`pipeline.runtime.loop_messages.CommandForce`).
        self.program: ForceProgram | None = None
        self.program_t0_ns = 0
        warm_kernels(self.framework.array)

    # -- one tick -----------------------------------------------------------------------------
    def tick(self, now: int, period_ns: int, dt_s: float) -> None:
        """Run this arm's part of the tick at ``now``: read, watchdog, Algorithm 1, command, record.

        After the watchdog the tick is one compiled call, :func:`record_kernel`, which builds the record by name: each
        of its values is the kernel's local variable (or parameter) named as its field, passed to
        :func:`pipeline.core.record_writer.write_record` in :data:`pipeline.core.tick_record.RECORD_FIELDS`' order
        (``tests/pipeline/test_tick_record.py`` reads both and holds them to that), so a field is added by computing
        a local of its name; no value is placed by counting.
        """
        loop = self.loop
        w = self.sensor.read_wrench()
        pose = self.robot.read_pose()
        hs = self.haptic.read_state()
        fw = self.framework

        # -- watchdog --
        # the sample unpacked whole, once (pipeline.devices.interfaces.WrenchSample): no w[:7] tuple, no lookups by name
        w_t_ns, raw_fx, raw_fy, raw_fz, raw_tx, raw_ty, raw_tz, w_status, _, _ = w
        cond, sensor_age_ns, pose_age_ns = conditions_kernel(
            self.saturation_n, self._sensor_age_ns, self._pose_age_ns, now, w_t_ns, raw_fx, raw_fy, raw_fz, raw_tx,
            raw_ty, raw_tz, w_status, pose.t_ns)
        if pose.t_ns != self._pose_t_ns:  # a new robot pose (125 Hz)
            cond |= self._take_pose(pose)
        if hs.error_code or hs.force_limit_n != self._device_limit_n:  # (rare: two compares a tick otherwise)
            cond |= self._device_changed(now, hs)
        faults = self.faults  # latched
        if cond != self.active_faults or cond & ~faults:  # (fault-free steady state: both false)
            faults = self._conditions_changed(cond, now, w, pose, hs, sensor_age_ns, pose_age_ns)

        if loop.refine_bias and not faults:
            fw.refine_bias(raw_fx, raw_fy, raw_fz, raw_tx, raw_ty, raw_tz)

        on = loop.haptic_on
        enabled = on and not faults
        program = self.program
        g = fw.safety
        true_fx, true_fy, true_fz = self._truth() or _NAN3
        tip_x_m, tip_y_m, tip_z_m = pose.position_m
        stylus_x_m, stylus_y_m, stylus_z_m = hs.position_m
        # the stages, the derating measure and the record (every field by its name: record_kernel), compiled
        render_fx, render_fy, render_fz = record_kernel(
            fw.array, self._row_f, self._row_i, raw_fx, raw_fy, raw_fz, raw_tx, raw_ty, raw_tz,
            0.0 if program is None else program.force_n(now - self.program_t0_ns), program is not None, enabled,
            dt_s, self._derate_check, g.limit_n, g.static_limit_n, loop.tick_count, now - loop.t0_ns, period_ns,
            sensor_age_ns, pose_age_ns, faults, 1 if on else 0, loop.trial_index, loop.phase, stylus_x_m,
            stylus_y_m, stylus_z_m, tip_x_m, tip_y_m, tip_z_m, true_fx, true_fy, true_fz)
        # stamped with this tick's time: should the tick have frozen half-way, the device drops the old force
        self.haptic.command_force(render_fx, render_fy, render_fz, now)
        # sample arrival to command hand-over on the loop's clock (on a virtual clock: the sample's age)
        self._row_i[_LATENCY] = loop.clock.now_ns() - w_t_ns
        self._recorded = True
        if self.ring is not None:
            self.ring.write_row(self._row_bytes)

    def _take_pose(self, pose: PoseSample) -> int:
        """Hand a new robot pose to the framework; a non-finite one is refused: ``Fault.NON_FINITE``, else 0."""
        rot = pose.rot_base_tip
        # one sum, not a generator per value (125 times a second): a NaN or an inf anywhere makes it NaN or inf;
        # finite values cannot overflow it (rotation entries are within ±1, positions metres)
        total = sum(rot) + sum(pose.position_m)
        if total - total == 0.0:
            self._pose_t_ns = pose.t_ns
            self.framework.set_pose(rot)
            if self.loop.recording:
                self.log("pose", (rot, pose.position_m, pose.t_ns))
            return 0
        return Fault.NON_FINITE

    def _conditions_changed(
        self, cond: int, now: int, w: WrenchSample, pose: PoseSample, hs: HapticState, sensor_age: int, pose_age: int,
    ) -> int:
        """This tick's fault conditions differ from the last tick's: latch the new ones, report the gone ones.

        Returns the latched set.
        """
        prev = self.active_faults
        self.active_faults = cond
        latched = self.faults
        new = cond & ~latched
        loop = self.loop
        if new:
            # a plain int, not a Fault: IntFlag's ~ and & run in Python (~1 µs per tick)
            latched = int(latched | new)
            self.faults = latched
            self._gone_reported &= ~new
            self.faults_changed(now)
            self.emit(now - loop.t0_ns, "fault", fault_detail(new, w, pose, hs, sensor_age, pose_age, loop.watchdog,
                                                              tuple(self.saturation_n.tolist())))
            loop.arm_faulted(self, new, now)
        if cond != prev:
            gone = latched & prev & ~cond & ~self._gone_reported
            if gone:
                self._gone_reported |= gone
                self.emit(now - loop.t0_ns, "fault_cleared",
                          f"{Fault(gone).describe()}: the condition is gone (latched until a reset)")
        return latched

    def _device_changed(self, now: int, hs: HapticState) -> int:
        """The haptic device reports an error or a new force limit: take the limit (derating); ``Fault.HAPTIC_DEVICE``
        while it reports an error, else 0."""
        if hs.force_limit_n != self._device_limit_n:
            self._device_limit(now, hs)
        return Fault.HAPTIC_DEVICE if hs.error_code else 0

    def _device_limit(self, now: int, hs: HapticState) -> None:
        """The device changed the force it may render (thermal derating): clamp to it; report derating."""
        lim = float(hs.force_limit_n)
        self._device_limit_n = lim
        safety = self.framework.set_device_limit(lim)
        if self.loop.recording:
            self.log("device_limit", lim)
        self._derate_check = safety.limit_n < safety.static_limit_n
        frac = float(hs.heat_fraction)
        t = now - self.loop.t0_ns
        if not self._derating and lim < self._peak_n:
            self._derating = True
            cont = float(getattr(self.haptic, "continuous_force_n", math.nan))
            self.emit(t, "derating", derating_detail(frac, self._peak_n, cont))
        elif self._derating and lim >= self._peak_n:
            self._derating = False
            self.emit(t, "derating_ended", derating_ended_detail(frac, lim))

    # -- a simulated rig's compiled block of ticks (pipeline.sim.block) -------------------------------
    @property
    def pose_time_ns(self) -> int | None:
        """The time of the robot pose last taken (None before the first)."""
        return self._pose_t_ns

    @property
    def max_ages_ns(self) -> tuple[int, int]:
        """The watchdog's largest sample and pose ages, ns."""
        return self._sensor_age_ns, self._pose_age_ns

    @property
    def device_limit_n(self) -> float:
        """The device's derated force limit as last seen, N."""
        return self._device_limit_n

    @property
    def derate_check(self) -> bool:
        """Whether the thermal limit is below the safety stage's own (the derating measure is taken)."""
        return self._derate_check

    def ran_block(self, rows: State, ticks: int, pose_time_ns: int, poses: State, n_poses: int,
                  rot: Sequence[float]) -> None:
        """``ticks`` of this arm's ticks ran in a compiled block (:mod:`pipeline.sim.block`): their records
        (``rows``, in the ring's layout) into the ring, the last as the newest; the pose taken last; the poses
        taken (``poses``: tick, x, y, z, t_ns), at orientation ``rot``, into the replay log."""
        if ticks:
            if self.ring is not None:
                self.ring.write_rows(rows[:ticks])
            self._row_f[:] = rows[ticks - 1]
            self._recorded = True
        self._pose_t_ns = pose_time_ns
        for tick, x, y, z, t_ns in poses[:n_poses].tolist():
            self.replay_log.append((int(tick), "pose", (rot, (x, y, z), int(t_ns))))

    # -- faults, resets and the record (rare paths) ----------------------------------------------
    def latch(self, fault: int, now: int) -> bool:
        """Latch ``fault`` (bits); True if any was new (the rig was told)."""
        if self.faults & fault == fault:
            return False
        self.faults = int(self.faults | fault)
        self.faults_changed(now)
        return True

    def reset_persisting(self) -> int:
        """What a reset cannot clear on this arm: conditions still present (and a device that does not re-arm)."""
        # the operator stop and device errors are cleared by the reset itself
        persisting = self.active_faults & ~(Fault.OPERATOR_STOP | Fault.HAPTIC_DEVICE)
        if self.faults & Fault.HAPTIC_DEVICE and not self.haptic.rearm():
            persisting |= Fault.HAPTIC_DEVICE
        return int(persisting)

    def reset(self, persisting: int, now: int) -> None:
        """Clear the latched faults but ``persisting``; report the reset."""
        before = self.faults
        self.faults = persisting
        self._gone_reported &= persisting
        if before and not persisting:
            self.framework.reset()
            if self.loop.recording:
                self.log("reset", None)
        if persisting != before:
            self.faults_changed(now)
        self.emit(now - self.loop.t0_ns, "faults_reset", Fault(before).describe())

    def force_zero(self, why: str) -> None:
        """Drop the output to zero outside the framework's step (logged for replay as ``"zero"``)."""
        self.framework.safety.force_zero()
        if self.loop.recording:
            self.log("zero", why)

    def faults_changed(self, now: int) -> None:
        """Tell the arm's rig hook the latched set changed (it stops a teleoperated robot); only on a change."""
        hook = self._on_faults
        if hook is None:
            return
        try:
            hook(Fault(self.faults))
        except Exception as exc:  # the loop must keep ramping the force down; report it
            self.emit(now - self.loop.t0_ns, "fault", f"the rig could not act on the faults: {exc!r}")

    def emit(self, t_ns: int, kind: str, detail: str, faults: int | None = None) -> LoopEvent:
        """Report an event of this arm through the loop's event path."""
        ev = LoopEvent(t_ns, kind, self.faults if faults is None else faults, detail, self.name)
        self.loop.emit(ev)
        return ev

    def command(self, program: ForceProgram | None, now: int) -> None:
        """Render ``program`` from this tick on (None: the sensor's force again); logged for replay."""
        self.program, self.program_t0_ns = program, now
        if self.loop.recording:
            self.log("program", None if program is None else program.to_json())

    def log(self, what: str, value: object) -> None:
        """Append to the arm's replay log, at the loop's current tick."""
        self.replay_log.append((self.loop.tick_count, what, value))

    def snapshot(self, token: int) -> None:
        """Start the arm's replayable record: the framework's state now."""
        self.log("snapshot", {"token": token, "framework": self.framework.snapshot(),
                              "refine_bias": self.loop.refine_bias})

    def zero_device(self) -> Exception | None:
        """Command zero force now (any thread); the exception if the device refused."""
        try:
            self.haptic.command_force(0.0, 0.0, 0.0)
        except Exception as exc:  # the device's own watchdog drops the force anyway
            return exc
        return None

    @property
    def last_record(self) -> tuple[float | int, ...] | None:
        """The arm's newest record (a tuple in the record's field order, its integers as ints)."""
        if not self._recorded:
            return None
        # one copy (a C call: a tick cannot run half-way through it), both views of the same tick's row; read during a
        # tick, the tick's own latency_ns is 0 (it is written once the command is handed over)
        row = self._row_f.copy()
        f, i = row.tolist(), row.view(np.int64).tolist()
        return tuple(i[k] if integer else f[k] for k, integer in enumerate(_INTEGER))


def own_faults(faults: int) -> int:
    """The faults that are this arm's own, not the policy's copy of another arm's."""
    return faults & ~Fault.OTHER_ARM


#: Faults every arm latches by itself (the loop's or the experimenter's): they do not propagate between arms.
RIG_WIDE_FAULTS = int(Fault.OPERATOR_STOP | Fault.ENGINE_DETACHED | Fault.LOOP_STALLED)


#: record_kernel's argument types, as warm_kernels compiles it (by position: numba reads values, not annotations):
#: the forces, positions and times in seconds float64, the switches bool, the counts and nanoseconds int64.
RECORD_KERNEL_TYPES = ("float64",) * 6 + ("float64", "bool", "bool", "float64", "bool", "float64", "float64") + (
    "int64",) * 9 + ("float64",) * 9


def warm_kernels(framework_array: State | None = None) -> None:
    """Compile :func:`record_kernel` (or load it from numba's cache) once a process, on a scratch copy of a framework's
    array (None: a default framework's), then forbid it any other compilation: a value of another type from a device
    (an int where a float is read) is converted to the compiled types, never compiled for in a tick of the running
    loop.  A channel's construction calls it; so does a parent that forks a process per participant."""
    if is_warm(__name__):
        return
    fw = (framework_array if framework_array is not None
          else HapticFramework(algorithm_1.FrameworkConfig(), device_peak_n=3.3).array).copy()
    row = np.zeros(len(RECORD_FIELDS))

    def compile_them() -> None:
        record_kernel(fw, row, row.view(np.int64), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False, True, 0.001, False, 3.0,
                      3.0, 0, 0, 1_000_000, 0, 0, 0, 0, -1, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        conditions_kernel(np.ones(6), 5_000_000, 50_000_000, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)
        cast(Any, record_kernel).disable_compile()  # (a numba dispatcher's)
        cast(Any, conditions_kernel).disable_compile()

    warm_once(__name__, compile_them)
