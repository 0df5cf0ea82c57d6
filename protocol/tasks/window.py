"""A trial's window as its task judged it, and the metrics over it: the part every task's offline form shares.

A task's offline form (:meth:`protocol.tasks.base.Task.judge`) finds where its rule completed; this module does the
rest, the same for every task: the trial window (from the cue, t = 0, to the trial end: the completing sample on
success, else the trial cap, both included), first contact, the error window, and the registry's metrics of the
task over them (:func:`protocol.metrics.compute`), so the numbers in the study database and in the report cannot
disagree.

* **error window** -- the samples RMSE, Max AE (and every metric taken over the error window) see: the trial
  window, *including* the approach before contact (F = 0); analysis may instead start at first contact
  (:data:`CONTACT_THRESHOLD_N`).
* **first contact** and **reaching the target** -- where the force's rise starts (the first sample above
  :data:`CONTACT_THRESHOLD_N`) and where it first gets to the task's success region from below (the task's
  ``reached`` rule: the force-regulation task's band's lower edge): the speed–accuracy trade's phases are measured
  on either side of the second (:data:`protocol.metrics.TRADE_PHASES`).

Decisions use integer-nanosecond sample timestamps, so they are exact however late the caller processes the samples.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from protocol.metrics import Metric, MetricValue, TrialWindow, compute

__all__ = ["CONTACT_THRESHOLD_N", "ERROR_WINDOWS", "TrialMetrics", "capped", "judged"]

#: Task force above which the tool counts as in contact (first-contact windows), N.
CONTACT_THRESHOLD_N = 0.05
#: The error windows: from the cue (default) or from first contact.
ERROR_WINDOWS = ("cue", "first_contact")


@dataclass(frozen=True, slots=True)
class TrialMetrics:
    """A trial's metrics (:attr:`values`, by name: ``metrics["rmse_n"]``) and the facts of its window.

    Attributes
    ----------
    values
        Each metric's value (:mod:`protocol.metrics`), by name, in the registry's order: the task's metrics.
    success
        The task's verdict: its rule completed within the trial window.
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


def capped(t_ns: npt.ArrayLike, force_n: npt.ArrayLike, max_trial_s: float,
           window: str) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """A trial's samples from the cue (t = 0) to its cap, both included: the samples its rule is judged on.

    Raises
    ------
    ValueError
        An error window other than :data:`ERROR_WINDOWS`, or times and forces not 1-D of one length.
    """
    if window not in ERROR_WINDOWS:
        raise ValueError(f"window = {window!r}: allowed values are 'cue' and 'first_contact'")
    t = np.asarray(t_ns, dtype=np.int64)
    f = np.asarray(force_n, dtype=np.float64)
    if t.shape != f.shape or t.ndim != 1:
        raise ValueError(f"t_ns and force_n must be 1-D of equal length, got {t.shape} and {f.shape}")
    cap_ns = int(round(max_trial_s * 1e9))
    keep = (t >= 0) & (t <= cap_ns)
    return t[keep], f[keep]


def judged(
    t: npt.NDArray[np.int64],
    f: npt.NDArray[np.float64],
    done: int | None,
    *,
    target_n: Callable[[npt.NDArray[np.int64]], npt.NDArray[np.float64]],
    on_target: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.bool_]],
    max_trial_s: float,
    window: str,
    sample_period_s: float,
    metrics: Sequence[Metric],
    reached: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.bool_]] | None = None,
) -> TrialMetrics:
    """The metrics of a trial whose rule completed at sample ``done`` (None: it did not) of ``t``, ``f``.

    Parameters
    ----------
    t, f
        The trial's samples to its cap (:func:`capped`).
    done
        Index of the sample that completed the task's rule (the trial ends there), or None (it ends at the cap).
    target_n, on_target
        The task's target at the window's sample times (ns since the cue), and whether each force of the window is
        within its success region.
    max_trial_s, window, sample_period_s, metrics
        The cap, the error window (:data:`ERROR_WINDOWS`), the nominal sample period and the task's metrics.
    reached
        Whether each force of the window has got to the task's success region from below (in it, or through it
        between two samples); None: the task has no such edge, and the window's ``reached_s`` is None.
    """
    success = done is not None
    end = done + 1 if done is not None else len(t)
    completed_ns = int(t[done]) if done is not None else None
    t, f = t[:end], f[:end]
    # ns / 1e9 (not ns * 1e-9) is the double nearest the exact time: 2009 ms → 2.009, not 2.0090000000000003
    end_s = completed_ns / 1e9 if completed_ns is not None else max_trial_s
    contact = np.flatnonzero(f > CONTACT_THRESHOLD_N)
    first_contact_s = float(t[contact[0]] / 1e9) if len(contact) else None
    target = target_n(t)
    # the error window: from the cue, or from first contact (none without contact); a non-finite force left out
    start = 0 if window == "cue" else (int(contact[0]) if len(contact) else len(f))
    err = f[start:] - target[start:]
    finite = np.isfinite(err)
    hit = np.flatnonzero(reached(f)) if reached is not None else np.empty(0, dtype=np.intp)
    trial = TrialWindow(t_ns=t, force_n=f, target_n=target, on_target=on_target(f), completed=success,
                        end_s=float(end_s), error_n=err[finite], error_t_s=t[start:][finite] / 1e9,
                        sample_period_s=sample_period_s, contact_s=first_contact_s,
                        reached_s=float(t[hit[0]] / 1e9) if len(hit) else None)
    return TrialMetrics(compute(trial, metrics), success, len(f), float(end_s), first_contact_s)
