"""The trial metrics, each defined once: what it is, how it is computed, how it is reported.

:data:`METRICS` is every metric defined; a study's are the ones its tasks produce (each task names its own,
:attr:`protocol.tasks.base.Task.metric_names`), in this order -- the order of the columns of every table and file
that lists metrics (the ``trials`` table's columns, ``trials.csv``, ``participants.csv``, the tests, power).  To add
a metric, define its function and its :class:`~protocol.metrics.metric.Metric` here, append it to :data:`METRICS`
and name it in the tasks that produce it: a study of those tasks gains its database column, and its CSV files,
codebook, report and power gain it, without another edit (docs/architecture.md, "Where to add …").

Definitions (the paper, §V-B, made exact where it is silent; the window is :class:`TrialWindow`'s):

* **success** -- the task's success rule held within the trial window (the force-regulation task: the hold
  completed); **TCT** -- the time from the cue to the end of the window on success;
* **RMSE** and **Max AE** -- ``√mean((F − F*)²)`` and ``max |F − F*|`` over the finite errors of the error window
  (from the cue, the approach before contact at F = 0 included; or from first contact);
* **time in band** -- samples on target × the sample period; **peak force** -- the largest task force of the
  trial window;
* **error impulse** -- ``∫|F − F*| dt`` over the error window, the same samples as RMSE and Max AE (the trapezoid
  rule on their times; a non-finite sample is left out and bridged): a secondary measure, tested outside the
  primary family;
* **rise time** and **RMSE after reach** -- the two phases of the speed–accuracy trade, on parts of the trial that
  do not overlap (docs/science.md §6.1): the speed of getting the force to the target, from first contact to the
  first sample at or above the band's lower edge (the band reached); and the accuracy from there, RMSE over the
  fixed :data:`REACH_WINDOW_S` that follows.  Analysis measures: computed from the recording, no column in a study
  database.
* **lag** and **gain** (force tracking's: a target that moves) -- over the moving part of the trial window (from the
  first sample whose target differs from the first one; the lead-in's steady target and the approach left out),
  the lag is the shift of the force that maximises its cross-correlation with the target (the correlation
  coefficient over each shift's overlapping samples), within
  ±:data:`MAX_LAG_S` (positive: the force follows the target), the gain the least-squares slope of the force on
  the target (1: the right size; below 1: the excursions fall short).  Both are NaN where the target does not move
  or a non-finite force leaves too few samples.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from protocol.metrics.metric import Metric, MetricValue, Role, TrialWindow

__all__ = [
    "ABS_IMPULSE",
    "GAIN",
    "LAG",
    "MAX_AE",
    "MAX_LAG_S",
    "METRICS",
    "PEAK_FORCE",
    "REACH_RMSE",
    "REACH_WINDOW_S",
    "RISE_TIME",
    "RMSE",
    "SUCCESS",
    "TCT",
    "TIME_IN_BAND",
    "TRADE_PHASES",
]

#: Forces to 0.1 mN, far finer than the F/T sensor resolves in one sample (means over 1 kHz trials resolve more).
_FORCE_DECIMALS = 4
#: Times to the 1 ms sample period.
_TIME_DECIMALS = 3
#: The accuracy window after band entry, s: the paper's 1 s hold, the same length for every trial, so a trial's
#: accuracy is not taken over more or less time because it was slower or faster (as RMSE from the cue is).
REACH_WINDOW_S = 1.0


def _success(w: TrialWindow) -> MetricValue:
    return w.completed


def _tct_s(w: TrialWindow) -> MetricValue:
    return w.end_s if w.completed else None


def _rmse_n(w: TrialWindow) -> MetricValue:
    e = w.error_n
    return float(np.sqrt(np.mean(e * e))) if len(e) else math.nan


def _max_ae_n(w: TrialWindow) -> MetricValue:
    e = w.error_n
    return float(np.max(np.abs(e))) if len(e) else math.nan


def _time_in_band_s(w: TrialWindow) -> MetricValue:
    return float(np.count_nonzero(w.on_target)) * w.sample_period_s


def _abs_impulse_n_s(w: TrialWindow) -> MetricValue:
    # ∫|F − F*| dt by the trapezoid rule on the samples' own times: exact for the piecewise-linear trace the samples
    # describe, and right on a clock whose periods vary (the rectangle sum, samples × 1 ms, would assume 1 kHz)
    e = np.abs(w.error_n)
    return float(np.sum((e[1:] + e[:-1]) * np.diff(w.error_t_s)) / 2.0) if len(e) else math.nan


def _rise_time_s(w: TrialWindow) -> MetricValue:
    # first contact to reaching the band: the force's rise, the approach through the air (cue to contact) left out;
    # reaching is at or above the band's lower edge, so a rise that shoots through the band between two samples
    # is as fast as it was (not timed to its return from above); at least 0 (a band below the contact threshold)
    if w.reached_s is None or w.contact_s is None:
        return None
    return max(0.0, w.reached_s - w.contact_s)


def _reach_rmse_n(w: TrialWindow) -> MetricValue:
    # the fixed window from reaching the band: undefined when the trial ended before the window did (a failure that
    # reached the band in its last second; a success's hold starts at or after the reach and lasts 1 s, so it has it)
    if w.reached_s is None:
        return None
    t0 = round(w.reached_s * 1e9)
    stop = t0 + round(REACH_WINDOW_S * 1e9)
    if len(w.t_ns) == 0 or int(w.t_ns[-1]) < stop:
        return None
    part = slice(int(np.searchsorted(w.t_ns, t0)), int(np.searchsorted(w.t_ns, stop, side="right")))
    e = w.force_n[part] - w.target_n[part]
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e * e))) if len(e) else None


#: The largest lag searched, s: beyond a human visuomotor delay (0.15–0.35 s) with room for a slow hand.
MAX_LAG_S = 1.0


def _moving(w: TrialWindow) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """The target and the force over the moving part, demeaned; None where the target does not move."""
    moved = np.flatnonzero(w.target_n != w.target_n[0]) if len(w.target_n) else np.array([], dtype=np.int64)
    if len(moved) == 0:
        return None
    target, force = w.target_n[moved[0]:], w.force_n[moved[0]:]
    finite = np.isfinite(force)
    if np.count_nonzero(finite) < 10 or np.ptp(target[finite]) == 0.0:
        return None
    # a non-finite force is bridged by the mean (it adds nothing to the correlation) where the lag needs the grid
    f = np.where(finite, force, np.mean(force[finite]))
    return target - np.mean(target), f - np.mean(f)


def _lag_s(w: TrialWindow) -> MetricValue:
    moving = _moving(w)
    if moving is None:
        return math.nan
    target, force = moving
    n, k_max = len(target), min(len(target) - 2, int(round(MAX_LAG_S / w.sample_period_s)))
    size = 1 << (2 * n - 1).bit_length()  # zero-padded FFT: the linear (not circular) cross-correlation
    sxy = np.fft.irfft(np.fft.rfft(force, size) * np.conj(np.fft.rfft(target, size)), size)
    lags = np.arange(-k_max, k_max + 1)
    # at shift k the pairs (force[i + k], target[i]) that overlap, each side's sums from cumulative sums: the
    # correlation coefficient of each shift's own overlap (a raw sum would favour the longer overlaps near 0)
    cf, cf2 = np.concatenate(([0.0], np.cumsum(force))), np.concatenate(([0.0], np.cumsum(force * force)))
    ct, ct2 = np.concatenate(([0.0], np.cumsum(target))), np.concatenate(([0.0], np.cumsum(target * target)))
    f_lo, f_hi = np.maximum(lags, 0), n + np.minimum(lags, 0)  # force[f_lo:f_hi] meets target[t_lo:t_hi]
    t_lo, t_hi = np.maximum(-lags, 0), n - np.maximum(lags, 0)
    m = (n - np.abs(lags)).astype(np.float64)
    sf, sf2, st, st2 = cf[f_hi] - cf[f_lo], cf2[f_hi] - cf2[f_lo], ct[t_hi] - ct[t_lo], ct2[t_hi] - ct2[t_lo]
    cov = sxy[lags] - sf * st / m
    with np.errstate(invalid="ignore", divide="ignore"):
        r = cov / np.sqrt(np.maximum(sf2 - sf * sf / m, 0.0) * np.maximum(st2 - st * st / m, 0.0))
    if not np.isfinite(r).any():
        return math.nan
    return float(lags[int(np.nanargmax(r))] * w.sample_period_s)


def _gain(w: TrialWindow) -> MetricValue:
    moving = _moving(w)
    if moving is None:
        return math.nan
    target, force = moving
    return float(np.dot(target, force) / np.dot(target, target))


def _peak_force_n(w: TrialWindow) -> MetricValue:
    f = w.force_n
    return float(np.nanmax(f)) if len(f) and np.isfinite(f).any() else math.nan


SUCCESS = Metric(
    "success", "", "success rate", "true when outcome is success", _success, "higher", Role.PRIMARY, 4,
    boolean=True, figure="success_rate", mean_description="successful trials / analysed trials",
    count_description="successful trials", count_label="successes", values=(0.0, 1.0))
TCT = Metric(
    "tct_s", "s", "TCT (s)", "task completion time: cue to the end of the successful hold; empty unless success",
    _tct_s, "lower", Role.PRIMARY, _TIME_DECIMALS, success_only=True, figure="tct",
    mean_description="mean TCT over the trials in n_tct (successful trials only, or with failures censored at the "
                     "cap: see the report's methods); empty when no trial counts")
RMSE = Metric(
    "rmse_n", "N", "RMSE (N)", "root-mean-square error of the task force against F* over the error window",
    _rmse_n, "lower", Role.PRIMARY, _FORCE_DECIMALS, windowed=True, figure="errors")
MAX_AE = Metric(
    "max_ae_n", "N", "Max AE (N)", "largest absolute error of the task force against F* over the error window",
    _max_ae_n, "lower", Role.PRIMARY, _FORCE_DECIMALS, windowed=True, figure="errors")
TIME_IN_BAND = Metric(
    "time_in_band_s", "s", "time in band (s)", "in-band samples × 1 ms over the trial window", _time_in_band_s,
    "higher", Role.DESCRIPTIVE, _TIME_DECIMALS)
PEAK_FORCE = Metric(
    "peak_force_n", "N", "peak force (N)", "largest task force over the error window", _peak_force_n, "lower",
    Role.DESCRIPTIVE, _FORCE_DECIMALS)
ABS_IMPULSE = Metric(
    "abs_impulse_n_s", "N·s", "error impulse (N·s)",
    "time integral of the absolute error of the task force against F* over the error window, ∫|F − F*| dt "
    "(trapezoid rule on the samples' times; from the cue to the trial end, or from first contact)",
    _abs_impulse_n_s, "lower", Role.SECONDARY, _FORCE_DECIMALS, windowed=True, figure="errors")

RISE_TIME = Metric(
    "rise_time_s", "s", "rise time (s)",
    "the force's rise: from first contact (task force above the contact threshold) to the first sample at or above "
    "the band's lower edge; empty without contact or without reaching the band", _rise_time_s, "lower",
    Role.DESCRIPTIVE, _TIME_DECIMALS,
    mean_description="mean rise time over the trials that reached the band", in_database=False)
REACH_RMSE = Metric(
    "reach_rmse_n", "N", "RMSE after reach (N)",
    f"root-mean-square error of the task force against F* over the {REACH_WINDOW_S:g} s from the first sample at or "
    "above the band's lower edge (a window of its own, after the rise time's); empty when the force never reached "
    f"the band or the trial ended less than {REACH_WINDOW_S:g} s after it did", _reach_rmse_n, "lower",
    Role.DESCRIPTIVE, _FORCE_DECIMALS,
    mean_description=f"mean RMSE over the {REACH_WINDOW_S:g} s after reaching the band, over the trials that have it",
    in_database=False)

#: The speed–accuracy trade's measures, (speed, accuracy): on parts of the trial apart (docs/science.md §6.1).
TRADE_PHASES: tuple[Metric, Metric] = (RISE_TIME, REACH_RMSE)

LAG = Metric(
    "lag_s", "s", "lag (s)", "shift of the task force that maximises its cross-correlation with the moving target "
    "(positive: the force follows), over the moving part of the trial", _lag_s, "lower", Role.SECONDARY,
    _TIME_DECIMALS, values=(-MAX_LAG_S, MAX_LAG_S), figure="tracking")
GAIN = Metric(
    "gain", "", "gain", "least-squares slope of the task force on the moving target, over the moving part of the "
    "trial (1: excursions of the right size)", _gain, "one", Role.SECONDARY, 4, values=(-math.inf, math.inf),
    figure="tracking")

#: Every metric, in the order of every table's columns (a study's are those of its tasks, in this order).  The
#: primary ones are the outcome measures, the family of Holm's correction: the paper's four (a study of force
#: regulation), or those of the study's tasks (force tracking's RMSE and Max AE; its lag and gain are secondary,
#: each tested with its own p), so the paper's numbers do not move when a metric or a task is added.
METRICS: tuple[Metric, ...] = (SUCCESS, TCT, RMSE, MAX_AE, TIME_IN_BAND, PEAK_FORCE, ABS_IMPULSE, RISE_TIME,
                               REACH_RMSE, LAG, GAIN)
