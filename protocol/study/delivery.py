"""What the loop delivered to the running trial: its records, their health, and where it left its condition.

**A trial counts only if it ran under its designed condition.**  The runner
(:class:`protocol.runner.session.SessionRunner`) checks every record of the running
trial (:meth:`TrialWindow.deviation`) and aborts the trial (cause in
brackets) at the first one where

* the loop's watchdog has a fault latched (``fault``);
* feedback was not what the design says: the loop's haptics flag differs from
  the trial's mode, the feedback gain is below 1 in a haptics-ON trial after
  its ramp-in, or above 0 in a haptics-OFF trial, or the haptic device's
  thermal derating cut the rendered force below the designed one in a
  haptics-ON trial (the record's ``derate`` < 1) (``feedback``);
* records are missing: two consecutive records further apart than the
  watchdog's sensor-age limit, or records the runner could not read (``gap``).

Each trial row also carries the loop's health over the trial's records
(:class:`protocol.study.records.LoopHealth`): tick period p50/p99/max, ticks over
2 ms, the oldest F/T sample and robot pose used, and the latency from a
sample's arrival to the force command it produced (p50/max).  An aborted
trial's records end with the one that aborted it (a stalled tick's period, a
stale sample's age are in its health).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.devices.interfaces import Fault
from pipeline.force.config import SafetyConfig
from pipeline.runtime.watchdog import WatchdogConfig, ms_beyond
from protocol.study.design import HapticMode, TrialSpec
from protocol.study.records import AbortCause, LoopHealth, trial_health
from protocol.study.trial import TrialFinished

__all__ = ["DeliveryLimits", "Deviation", "TrialWindow"]

#: Record columns the loop-health summary of a trial reads.
_HEALTH_SRC = ("period_ns", "sensor_age_ns", "pose_age_ns", "latency_ns")


def _ns(seconds: float) -> int:
    return int(round(seconds * 1e9))


#: The safety stage's and the watchdog's defaults: the one definition of the ramps and of the sensor-age limit.
_SAFETY = SafetyConfig()
_WATCHDOG = WatchdogConfig()


@dataclass(frozen=True, slots=True)
class DeliveryLimits:
    """What the loop must deliver for a trial to count (taken from the loop's own configuration).

    Attributes
    ----------
    feedback_ramp_in_s
        The safety stage's ramp-in after feedback is switched on (its gain is 1 after it).
    feedback_ramp_out_s
        The ramp-down after feedback is switched off (its gain is 0 after it).
    max_gap_s
        Longest allowed time between two consecutive records of a trial (the
        watchdog's sensor-age limit: a longer gap is a stretch in which the
        force was not rendered from fresh data).
    grace_s
        Allowance on the ramps for a late tick.
    """

    feedback_ramp_in_s: float = _SAFETY.ramp_in_s
    feedback_ramp_out_s: float = _SAFETY.fault_ramp_s
    max_gap_s: float = _WATCHDOG.sensor_max_age_s
    grace_s: float = 0.01


@dataclass(frozen=True, slots=True)
class Deviation:
    """The first record (``index`` in its block) at which the running trial left its designed condition."""

    index: int
    cause: AbortCause
    reason: str


#: (record index in the block, priority within a record, cause, reason) of each check that found something
_Found = tuple[int, int, AbortCause, str]


def _fault(marked: np.ndarray, faults: np.ndarray, fault_detail: str) -> list[_Found]:
    bad = np.flatnonzero(faults != 0)
    if not len(bad):
        return []
    k = int(bad[0])
    what = fault_detail or Fault(int(faults[k])).describe()
    return [(int(marked[k]), 0, AbortCause.FAULT, f"fault: {what}")]


def _gap(marked: np.ndarray, t: np.ndarray, prev_ns: int | None, limits: DeliveryLimits) -> list[_Found]:
    prev = np.concatenate(([prev_ns if prev_ns is not None else t[0]], t[:-1]))
    gaps = np.flatnonzero((t - prev) > _ns(limits.max_gap_s))
    if not len(gaps):
        return []
    k = int(gaps[0])
    return [(int(marked[k]), 1, AbortCause.GAP,
             f"gap: no loop record for {ms_beyond((t[k] - prev[k]) * 1e-6, limits.max_gap_s * 1e3)} ms "
             f"(limit {limits.max_gap_s * 1e3:g} ms)")]


def _feedback(rows: np.ndarray, marked: np.ndarray, rel_ns: np.ndarray, spec: TrialSpec,
              limits: DeliveryLimits) -> list[_Found]:
    found: list[_Found] = []
    on = spec.haptic_mode is HapticMode.ON
    wrong = np.flatnonzero(rows["haptic_on"][marked] != (1 if on else 0))
    if len(wrong):
        found.append((int(marked[int(wrong[0])]), 2, AbortCause.FEEDBACK,
                      f"feedback: haptics were {'off' if on else 'on'} in a haptics-{spec.haptic_mode.upper()} trial"))
    gain = rows["gain"][marked]
    if not on:
        high = np.flatnonzero((gain > 0.0) & (rel_ns > _ns(limits.feedback_ramp_out_s + limits.grace_s)))
        if len(high):
            k = int(high[0])
            found.append((int(marked[k]), 2, AbortCause.FEEDBACK,
                          f"feedback: gain {gain[k]:.3f} above 0 in a haptics-OFF trial"))
        return found
    low = np.flatnonzero((gain < 1.0) & (rel_ns > _ns(limits.feedback_ramp_in_s + limits.grace_s)))
    if len(low):
        k = int(low[0])
        found.append((int(marked[k]), 2, AbortCause.FEEDBACK,
                      f"feedback: gain {gain[k]:.3f} below 1 after the {limits.feedback_ramp_in_s:g} s ramp-in "
                      "of a haptics-ON trial"))
    derate = rows["derate"][marked]
    cut = np.flatnonzero(derate < 1.0)
    if len(cut):
        k = int(cut[0])
        # rounded down: a cut to 99.996 % must not read "100 %"
        pct = math.floor(float(derate[k]) * 1e4) / 1e2
        found.append((int(marked[k]), 2, AbortCause.FEEDBACK,
                      f"feedback: the haptic device's thermal derating rendered {pct:.2f} % of the "
                      "designed force in a haptics-ON trial"))
    return found


class TrialWindow:
    """The running trial's records as they arrive: the ticks of its first and last, and their loop health."""

    def __init__(self) -> None:
        #: Loop ticks of the trial's first (its cue) and newest record; None before it has any.
        self.ticks: tuple[int, int] | None = None
        #: Loop time of the newest record checked and found as designed (the next gap is measured from it).
        self.last_ns: int | None = None
        self._health: list[np.ndarray] = []

    def note(self, sel: np.ndarray) -> None:
        """These records are the running trial's: extend its window, keep their loop health."""
        ticks = sel["tick"]
        first = int(ticks[0]) if self.ticks is None else self.ticks[0]
        self.ticks = (first, int(ticks[-1]))
        # one float64 array, not a list of row lists: no garbage-collector-tracked objects per sample
        # (a live session's collector passes would otherwise scan ~1000 such lists, GIL held, loop waiting)
        self._health.append(np.column_stack([np.asarray(sel[c], dtype=np.float64) for c in _HEALTH_SRC]))

    def note_trial(self, rows: np.ndarray, t_ns: np.ndarray, trial_index: int, cue_ns: int | None,
                   ended: TrialFinished | None) -> None:
        """Note which of a block's records are the trial's: from its cue to its end, if it ended in this block."""
        if cue_ns is None:
            if ended is None:
                return
            cue_ns = ended.cue_ns
        mask = (rows["trial_index"] == trial_index) & (t_ns >= cue_ns)
        if ended is not None:
            mask &= t_ns <= ended.end_ns
        idx = np.flatnonzero(mask)
        if len(idx) == 0:
            return
        first, last = int(idx[0]), int(idx[-1])
        # the trial's records are one run of the block (marked, in time order): a slice, not a boolean index --
        # NumPy copies a structured array's masked rows field by field (~12 µs a 50-record block against ~1 µs)
        self.note(rows[first : last + 1] if last - first + 1 == len(idx) else rows[mask])

    def take(self) -> tuple[tuple[int, int] | None, LoopHealth]:
        """The finished trial's record ticks and loop health; the window is empty again."""
        block = np.concatenate(self._health) if self._health else np.empty((0, len(_HEALTH_SRC)))
        ticks = self.ticks
        self.ticks, self.last_ns, self._health = None, None, []
        return ticks, trial_health(*(block.T * 1e-9))  # seconds at the edge: the stored health columns are ms

    def deviation(self, rows: np.ndarray, spec: TrialSpec, cue_ns: int | None, limits: DeliveryLimits,
                  fault_detail: str) -> Deviation | None:
        """The first of these records at which the trial left its designed condition (None: all as designed).

        Parameters
        ----------
        rows
            A block of loop records; only those marked with the trial are checked.
        spec
            The running trial.
        cue_ns
            Its time origin (None before the trial machine saw it: its first marked record here).
        limits
            What the loop must deliver.
        fault_detail
            The newest fault event's detail (names a latched fault's cause).
        """
        marked = np.flatnonzero(rows["trial_index"] == spec.index)
        if len(marked) == 0:
            return None
        t = rows["t_ns"][marked]
        cue = cue_ns if cue_ns is not None else int(t[0])
        found = (_fault(marked, rows["faults"][marked], fault_detail) + _gap(marked, t, self.last_ns, limits)
                 + _feedback(rows, marked, t - cue, spec, limits))
        if not found:
            self.last_ns = int(t[-1])
            return None
        i, _, cause, reason = min(found)
        return Deviation(i, cause, reason)
