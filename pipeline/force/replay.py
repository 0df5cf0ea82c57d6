"""Replay: a recorded session's inputs through Algorithm 1 again, tick by tick, as the live loop ran them.

The loop records, at 1 kHz, what it fed the framework (the raw F/T wrench, the
tick period, whether feedback was on and which faults were latched) and logs
everything else that changed the framework's state (:class:`pipeline.runtime.loop.StartRecording`):
the snapshot it started from, every pose it took, every change of the
bias-refinement permission, every reset and calibration, and what the rig
did to the safety stage outside the step: every change of the haptic
device's (thermally derated) force limit and every drop of the output to
zero (a tick later than the device's command watchdog, a fault latched from
outside the loop, the fail-safe of a dead loop).  :func:`replay` applies them
in the loop's own order -- commands and drops to zero, then the pose and the
device limit, then bias refinement, then
:meth:`pipeline.force.framework.HapticFramework.step` -- so with the
recorded configuration it reproduces the rendered force bit for bit, and with
another (a longer filter window, another f_scale or f_max) it answers what the
participant would have felt.  It is the live code path, not a model of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.core import exact
from pipeline.core.force_program import ForceProgram
from pipeline.force.framework import STEP_FIELDS, FrameworkConfig, HapticFramework
from pipeline.force.payload_compensator import PayloadCalibration

__all__ = ["REPLAY_LOG_KINDS", "ReplayInputs", "ReplayOutputs", "replay"]

_HYPOT = exact.hypot3  # the loop's |filtered| (pipeline.runtime.arm_channel.record_kernel)


@dataclass(frozen=True)
class ReplayInputs:
    """One recorded run of a session (a segment): per-tick inputs and the log.

    Attributes
    ----------
    tick
        The loop's tick number of each record.
    period_ns
        The tick's period (the framework's ``dt``), integer ns.
    raw_wrench
        The F/T sample the tick read, sensor frame, N and N·m (n × 6).
    haptic_on, faults
        The feedback switch and the latched faults of the tick.
    snapshot
        The log's ``snapshot`` payload: the framework's state before the first record
        and the bias-refinement permission.
    events
        The rest of the log, ``(tick, kind, payload)`` in the loop's order.
    """

    tick: npt.NDArray[np.int64]
    period_ns: npt.NDArray[np.int64]
    raw_wrench: npt.NDArray[np.float64]
    haptic_on: npt.NDArray[np.bool_]
    faults: npt.NDArray[np.int64]
    snapshot: dict[str, Any]
    events: Sequence[tuple[int, str, object]]


@dataclass(frozen=True)
class ReplayOutputs:
    """What the framework computed at each replayed tick.

    Attributes
    ----------
    stages
        n × 21, the columns of :data:`pipeline.force.framework.STEP_FIELDS` (compensated … rendered force).
    force_n
        The task force, |filtered compensated force|, N.
    gain
        The safety stage's ramp gain after the tick.
    """

    stages: npt.NDArray[np.float64]
    force_n: npt.NDArray[np.float64]
    gain: npt.NDArray[np.float64]

    def column(self, name: str) -> npt.NDArray[np.float64]:
        """One stage column by its :data:`pipeline.force.framework.STEP_FIELDS` name."""
        return self.stages[:, STEP_FIELDS.index(name)]

    def stage_force(self, stage: str) -> npt.NDArray[np.float64]:
        """One stage's force vectors, n × 3 (``stage``: ``"comp"``, ``"filt"``, … ``"render"``)."""
        i = STEP_FIELDS.index(f"{stage}_fx")
        return self.stages[:, i : i + 3]


#: The log entries :func:`replay` applies, as the loop writes them (``pipeline.runtime.loop``); any other is refused.
REPLAY_LOG_KINDS: tuple[str, ...] = ("pose", "refine", "reset", "calibration", "device_limit", "zero", "program")


def replay(inputs: ReplayInputs, config: FrameworkConfig | None = None) -> ReplayOutputs:
    """Run the recorded inputs through a framework restored from the snapshot.

    Parameters
    ----------
    inputs
        One segment of a recording.
    config
        None: the recorded configuration (bit-identical output); otherwise the
        framework's configuration to try instead.

    Returns
    -------
    ReplayOutputs

    Raises
    ------
    ValueError
        The log holds an entry this version does not know (not in :data:`REPLAY_LOG_KINDS`).
    """
    snap = inputs.snapshot
    fw = HapticFramework.restore(snap["framework"], config)
    refine = bool(snap["refine_bias"])
    n = len(inputs.tick)
    outs: list[tuple[float, ...]] = []
    gains: list[float] = []
    by_tick: dict[int, list[tuple[str, object]]] = {}
    for t, kind, payload in inputs.events:
        if kind not in REPLAY_LOG_KINDS:
            # a kind this version does not apply would make the replay silently differ from what was rendered
            raise ValueError(f"recording log entry {kind!r} at tick {int(t)}: this version of replay applies only "
                             f"{', '.join(REPLAY_LOG_KINDS)} (was the session recorded by a newer haptic-study?)")
        by_tick.setdefault(int(t), []).append((kind, payload))
    ticks = inputs.tick.tolist()
    dts = (inputs.period_ns * 1e-9).tolist()  # as the loop computes dt: int ns × 1e-9 (int64, the tick record's)
    raw = inputs.raw_wrench.tolist()
    enabled = (inputs.haptic_on & (inputs.faults == 0)).tolist()
    latched = (inputs.faults != 0).tolist()
    step = fw.step
    refine_bias = fw.refine_bias
    safety = fw.safety
    keep, keep_gain = outs.append, gains.append
    periods = inputs.period_ns.tolist()
    program: ForceProgram | None = None
    elapsed_ns = 0
    for k in range(n):
        evs = by_tick.get(ticks[k])
        if evs is not None:
            for kind, payload in evs:
                if kind == "pose":
                    fw.set_pose(tuple(payload[0]))  # type: ignore[index]  # a log payload is typed object; its kind says what it holds
                elif kind == "refine":
                    refine = bool(payload)
                elif kind == "reset":
                    fw.reset()
                elif kind == "calibration":
                    fw.set_calibration(PayloadCalibration.from_dict(payload))  # type: ignore[arg-type]  # as above
                elif kind == "device_limit":
                    fw.set_device_limit(float(payload))  # type: ignore[arg-type]  # as above
                elif kind == "zero":
                    safety.force_zero()
                elif kind == "program":  # a commanded force from this tick on (its time from 0 here)
                    program = None if payload is None else ForceProgram.from_json(payload)  # type: ignore[arg-type]  # as above
                    elapsed_ns = -periods[k]
        fx, fy, fz, tx, ty, tz = raw[k]
        if refine and not latched[k]:
            refine_bias(fx, fy, fz, tx, ty, tz)
        if program is None:
            keep(step(fx, fy, fz, enabled[k], dts[k]))
        else:  # the loop's clock advanced by each tick's period since the program's tick
            elapsed_ns += periods[k]
            keep(fw.step_commanded(fx, fy, fz, program.force_n(elapsed_ns), enabled[k], dts[k]))
        keep_gain(safety.gain)
    stages = np.array(outs, dtype=np.float64).reshape(n, len(STEP_FIELDS))
    # |filtered|, as the loop forms it: CPython's norm per record (numpy's hypot may round differently)
    force = np.fromiter((_HYPOT(o[3], o[4], o[5]) for o in outs), dtype=np.float64, count=n)
    return ReplayOutputs(stages, force, np.array(gains, dtype=np.float64))
