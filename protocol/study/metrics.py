"""The force-regulation task's trial window: its band, its hold, and the metrics computed over its samples.

The live trial machine (:mod:`protocol.study.trial`) and the offline analysis (``analysis``) both call
:func:`trial_metrics`, which applies the task's rule to a trial's samples and hands the window to the metric
registry (:mod:`protocol.metrics`), so the numbers in the study database and in the report cannot disagree.

Definitions (the paper, §V-B, made exact where it is silent; each metric's own is in
:mod:`protocol.metrics.definitions`):

* **task force** ``F`` -- the magnitude of the filtered, compensated contact
  force (the ``force_n`` column of every sample);
* **band** -- ``|F − F*| ≤ tol·F*``, inclusive of its nominal edges (a relative
  slack of 1e-9 absorbs the decimal representation of e.g. 0.66 = 1.1·0.6);
* **hold** -- starts at the first in-band sample after an out-of-band one and
  completes at the first sample at least ``hold_s`` later with every sample
  in between in band; leaving the band restarts it;
* **success** -- the hold completes within the trial window; **TCT** is the
  time from the cue to that sample (the end of the 1 s hold);
* **trial window** -- from the cue (t = 0) to the trial end: the completing
  sample on success, otherwise ``max_trial_s`` (12 s), both inclusive;
* **error window** -- the samples RMSE, Max AE (and every metric taken over the error window) see: the trial
  window, *including* the approach before contact (F = 0); analysis may instead start at first contact
  (:data:`CONTACT_THRESHOLD_N`).

Decisions use integer-nanosecond sample timestamps, so they are exact however
late the caller processes the samples.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from protocol.metrics import METRICS, Metric, MetricValue, TrialWindow, compute

__all__ = [
    "BAND_SLACK",
    "CONTACT_THRESHOLD_N",
    "HoldDetector",
    "TrialMetrics",
    "band_halfwidth_n",
    "hold_completion_index",
    "in_band",
    "trial_metrics",
]

#: Relative slack that makes the nominal band edges inclusive despite rounding.
BAND_SLACK = 1e-9
#: Task force above which the tool counts as in contact (first-contact windows), N.
CONTACT_THRESHOLD_N = 0.05


def band_halfwidth_n(target_force_n: float, tolerance_fraction: float) -> float:
    """Half-width of the success band, N (``tol·F*``, plus the edge slack)."""
    return tolerance_fraction * target_force_n * (1.0 + BAND_SLACK)


def in_band(force_n: float, target_force_n: float, tolerance_fraction: float) -> bool:
    """True when ``|F − F*| ≤ tol·F*`` (edges included)."""
    return abs(force_n - target_force_n) <= band_halfwidth_n(target_force_n, tolerance_fraction)


class HoldDetector:
    """Streaming form of the hold criterion: feed samples in time order, learn when the hold completes.

    Parameters
    ----------
    target_force_n, tolerance_fraction
        The band.
    hold_ns
        Required continuous time in band, ns (1 s = 1_000_000_000).
    """

    __slots__ = ("_half", "_hold_ns", "_target", "completed_ns", "hold_start_ns")

    def __init__(self, target_force_n: float, tolerance_fraction: float, hold_ns: int) -> None:
        self._target = float(target_force_n)
        self._half = band_halfwidth_n(target_force_n, tolerance_fraction)
        self._hold_ns = int(hold_ns)
        #: Timestamp of the first sample of the current hold (None when out of band).
        self.hold_start_ns: int | None = None
        #: Timestamp of the sample that completed the hold (None until then).
        self.completed_ns: int | None = None

    def feed(self, t_ns: int, force_n: float) -> bool:
        """Process one sample; True at the sample that completes the hold (once)."""
        if self.completed_ns is not None:
            return False
        if abs(force_n - self._target) <= self._half:  # NaN compares False: out of band
            start = self.hold_start_ns
            if start is None:
                self.hold_start_ns = start = t_ns
            if t_ns - start >= self._hold_ns:
                self.completed_ns = t_ns
                return True
        else:
            self.hold_start_ns = None
        return False


def hold_completion_index(
    t_ns: npt.NDArray[np.int64],
    force_n: npt.NDArray[np.float64],
    target_force_n: float,
    tolerance_fraction: float,
    hold_ns: int,
) -> int | None:
    """Index of the sample that completes the hold, or None: :class:`HoldDetector` over a whole trace.

    The same criterion as the streaming detector (a test proves them equal on
    random traces), vectorised for offline analysis of millions of samples:
    every in-band sample knows the start of its in-band run, and the hold
    completes at the first in-band sample whose run began ``hold_ns`` or more
    before it.

    Parameters
    ----------
    t_ns
        Sample times, integer ns, non-decreasing.
    force_n
        Task force at those times, N (NaN is out of band).
    target_force_n, tolerance_fraction, hold_ns
        The band and the required hold.

    Returns
    -------
    int or None
    """
    n = len(t_ns)
    if n == 0:
        return None
    inb = np.abs(force_n - target_force_n) <= band_halfwidth_n(target_force_n, tolerance_fraction)
    starts = inb.copy()
    starts[1:] &= ~inb[:-1]
    # index of the latest run start at or before each sample (-1 before the first run)
    run_start = np.maximum.accumulate(np.where(starts, np.arange(n), -1))
    ok = inb & (t_ns - t_ns[np.maximum(run_start, 0)] >= hold_ns)
    hit = int(np.argmax(ok))
    return hit if ok[hit] else None


@dataclass(frozen=True, slots=True)
class TrialMetrics:
    """A trial's metrics (:attr:`values`, by name: ``metrics["rmse_n"]``) and the facts of its window.

    Attributes
    ----------
    values
        Each metric's value (:mod:`protocol.metrics`), by name, in the registry's order.
    success
        The task's verdict: the hold completed within the trial window.
    n_samples
        Samples in the trial window.
    end_s
        The trial end, s since the cue.
    first_contact_s
        The first sample above :data:`CONTACT_THRESHOLD_N`, s since the cue (None: no contact).
    """

    values: Mapping[str, MetricValue]
    success: bool
    n_samples: int
    end_s: float
    first_contact_s: float | None

    def __getitem__(self, name: str) -> MetricValue:
        return self.values[name]


def trial_metrics(
    t_ns: npt.ArrayLike,
    force_n: npt.ArrayLike,
    target_force_n: float,
    *,
    tolerance_fraction: float = 0.10,
    hold_s: float = 1.0,
    max_trial_s: float = 12.0,
    window: str = "cue",
    sample_period_s: float = 0.001,
    metrics: Sequence[Metric] = METRICS,
) -> TrialMetrics:
    """Compute a trial's metrics from its samples.

    Parameters
    ----------
    t_ns
        Sample times since the cue, integer ns (t = 0 at the cue).  Samples
        after the trial end are ignored.
    force_n
        Task force at those times, N.
    target_force_n
        F*, N.
    tolerance_fraction, hold_s, max_trial_s
        The success criterion and the trial cap.
    window
        ``"cue"`` (default): the error window (RMSE, Max AE, ...) from the cue to the trial end;
        ``"first_contact"``: from the first sample above
        :data:`CONTACT_THRESHOLD_N` (NaN when there was no contact).
    sample_period_s
        For time in band.
    metrics
        The metrics to compute (default: every metric of :mod:`protocol.metrics`).

    Returns
    -------
    TrialMetrics
    """
    if window not in ("cue", "first_contact"):
        raise ValueError(f"window = {window!r}: allowed values are 'cue' and 'first_contact'")
    t = np.asarray(t_ns, dtype=np.int64)
    f = np.asarray(force_n, dtype=np.float64)
    if t.shape != f.shape or t.ndim != 1:
        raise ValueError(f"t_ns and force_n must be 1-D of equal length, got {t.shape} and {f.shape}")
    cap_ns = int(round(max_trial_s * 1e9))
    keep = (t >= 0) & (t <= cap_ns)
    t, f = t[keep], f[keep]
    done = hold_completion_index(t, f, target_force_n, tolerance_fraction, int(round(hold_s * 1e9)))
    success = done is not None
    end = done + 1 if done is not None else len(t)
    completed_ns = int(t[done]) if done is not None else None
    t, f = t[:end], f[:end]
    # ns / 1e9 (not ns * 1e-9) is the double nearest the exact time: 2009 ms → 2.009, not 2.0090000000000003
    end_s = completed_ns / 1e9 if completed_ns is not None else max_trial_s
    contact = np.flatnonzero(f > CONTACT_THRESHOLD_N)
    first_contact_s = float(t[contact[0]] / 1e9) if len(contact) else None
    target = np.full(len(f), float(target_force_n))
    # the error window: from the cue, or from first contact (none without contact); a non-finite force left out
    start = 0 if window == "cue" else (int(contact[0]) if len(contact) else len(f))
    err = f[start:] - target[start:]
    finite = np.isfinite(err)
    half = band_halfwidth_n(target_force_n, tolerance_fraction)
    reached = np.flatnonzero(f >= target_force_n - half)  # into the band, or through it between two samples
    trial = TrialWindow(t_ns=t, force_n=f, target_n=target, on_target=np.abs(f - target_force_n) <= half,
                        completed=success, end_s=float(end_s), error_n=err[finite],
                        error_t_s=t[start:][finite] / 1e9, sample_period_s=sample_period_s, contact_s=first_contact_s,
                        reached_s=float(t[reached[0]] / 1e9) if len(reached) else None)
    return TrialMetrics(compute(trial, metrics), success, len(f), float(end_s), first_contact_s)
