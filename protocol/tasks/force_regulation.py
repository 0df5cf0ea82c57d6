"""The paper's task, force regulation: reach a target force and hold it within a band.

Definitions (the paper, §V-B, made exact where it is silent; each metric's own is in
:mod:`protocol.metrics.definitions`, the window's in :mod:`protocol.tasks.window`):

* **task force** ``F`` -- the magnitude of the filtered, compensated contact
  force (the ``force_n`` column of every sample);
* **target** ``F*`` -- the trial's target force, constant over the trial (the protocol's ``[[targets]]``);
* **band** -- ``|F − F*| ≤ tol·F*``, inclusive of its nominal edges (a relative
  slack of 1e-9 absorbs the decimal representation of e.g. 0.66 = 1.1·0.6);
* **hold** -- starts at the first in-band sample after an out-of-band one and
  completes at the first sample at least ``hold_s`` later with every sample
  in between in band; leaving the band restarts it;
* **success** -- the hold completes within the trial window; **TCT** is the
  time from the cue to that sample (the end of the 1 s hold).

Its two parameters are the protocol file's ``trial.tolerance_fraction`` and ``trial.hold_s`` (where every protocol
file has had them: a file without a ``[task]`` table is this task).  The live trial machine feeds
:class:`HoldDetector` sample by sample; the offline form, :func:`trial_metrics`, finds the same sample on a whole
trace (:func:`hold_completion_index`; a test proves them equal on random traces).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from pipeline.core.aim import TrialAim
from pipeline.settings.tomlfields import Fields
from protocol.metrics import select
from protocol.tasks.base import (
    Parameter,
    Task,
    TaskTables,
    Timing,
    TrialCondition,
    TrialScreen,
    TrialTarget,
    constant_band,
    listed,
)
from protocol.tasks.window import TrialMetrics, capped, judged

__all__ = [
    "BAND_SLACK",
    "METRIC_NAMES",
    "ForceRegulation",
    "HoldDetector",
    "band_halfwidth_n",
    "hold_completion_index",
    "in_band",
    "trial_metrics",
]

#: Relative slack that makes the nominal band edges inclusive despite rounding.
BAND_SLACK = 1e-9
#: The metrics the task produces (:mod:`protocol.metrics`): the paper's four, time in band, peak force, the impulse,
#: and the speed–accuracy trade's phases (rise time to the band, RMSE after reaching it: analysis measures).
METRIC_NAMES = ("success", "tct_s", "rmse_n", "max_ae_n", "time_in_band_s", "peak_force_n", "abs_impulse_n_s",
                "rise_time_s", "reach_rmse_n")
_METRICS = select(METRIC_NAMES)


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

    The same criterion as the streaming detector, vectorised for offline analysis of millions of samples:
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
) -> TrialMetrics:
    """Judge a force-regulation trial from its samples and compute its metrics (:meth:`ForceRegulation.judge` with
    the task's parameters and the trial's target given as numbers).

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
        :data:`protocol.tasks.window.CONTACT_THRESHOLD_N` (NaN when there was no contact).
    sample_period_s
        For time in band.
    """
    task = ForceRegulation(tolerance_fraction=tolerance_fraction, hold_s=hold_s)
    return task.judge(t_ns, force_n, TrialTarget("", target_force_n, ""), max_trial_s=max_trial_s, window=window,
                      sample_period_s=sample_period_s)


@dataclass(frozen=True, slots=True)
class ForceRegulation(Task):
    """Reach the trial's target force F* and hold it within ±``tolerance_fraction``·F* for ``hold_s``.

    Attributes
    ----------
    tolerance_fraction
        Half-width of the band as a fraction of F* (``trial.tolerance_fraction``, 0.10 in the paper).
    hold_s
        Time the force must stay in the band (``trial.hold_s``, 1 s in the paper).
    """

    tolerance_fraction: float = 0.10
    hold_s: float = 1.0

    kind: ClassVar[str] = "force_regulation"
    title: ClassVar[str] = "force regulation"
    metric_names: ClassVar[tuple[str, ...]] = METRIC_NAMES
    trial_fields: ClassVar[frozenset[str]] = frozenset({"tolerance_fraction", "hold_s"})
    described: ClassVar[tuple[Parameter, ...]] = (
        Parameter("tolerance_fraction", "half-width of the target band as a fraction of F*", "fraction (0–1)",
                  "tolerance", decimals=4),
        Parameter("hold_s", "time the force must stay in the band for success", "s", "hold (s)", decimals=3),
    )

    # -- its parameters ------------------------------------------------------------------------------------------
    @classmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> ForceRegulation:
        # the paper's two parameters stay in [trial], where every protocol file has them
        return cls(
            tolerance_fraction=f.number("trial.tolerance_fraction", trial.get("tolerance_fraction", 0.10),
                                        lo=0.0, hi=0.5),
            hold_s=f.number("trial.hold_s", trial.get("hold_s", 1.0), lo=0.0, hi=60.0),
        )

    def tables(self) -> TaskTables:
        return {}, {"tolerance_fraction": self.tolerance_fraction, "hold_s": self.hold_s}

    def check_timing(self, f: Fields, timing: Timing) -> None:
        """* ``trial.hold_s`` < ``trial.max_trial_s``, and with haptics ON in the design the trial must also hold
          the feedback's ramp-in: an ON trial shorter than ramp-in + hold could only succeed (or be counted) at a
          gain below 1 -- feedback weaker than designed.
        * ``training.seconds_per_target_per_mode``: the training session runs, stores and on resume re-reads the
          protocol with its trials capped at this value, so it must fit a hold (and the ramp-in) too.
        """
        hold, ramp_in = self.hold_s, timing.ramps.ramp_in_s
        if hold >= timing.max_trial_s:
            raise f.fail("trial.hold_s", hold, f"must be shorter than trial.max_trial_s = {timing.max_trial_s:g}")
        if not hold < timing.training_s:
            raise f.fail("training.seconds_per_target_per_mode", timing.training_s,
                         f"must be longer than trial.hold_s = {hold:g} (each training trial lasts this long "
                         f"and must leave time to complete a hold)")
        for field, cap in (("trial.max_trial_s", timing.max_trial_s),
                           ("training.seconds_per_target_per_mode", timing.training_s)):
            if timing.haptics_on and cap < ramp_in + hold:
                raise f.fail(field, cap, f"must be at least trial.hold_s = {hold:g} + the feedback's "
                             f"{ramp_in:g} s ramp-in (safety.ramp_in_s) = {ramp_in + hold:g} s "
                             "when design.modes has 'on': a shorter haptics-ON trial would be judged at a feedback "
                             "gain below 1")

    # -- its target and its rule ---------------------------------------------------------------------------------
    def band_n(self, trial: TrialCondition) -> tuple[float, float]:
        """The band around the trial's F*, N, edges as judged (the slack included)."""
        f = trial.target_force_n
        half = band_halfwidth_n(f, self.tolerance_fraction)
        return f - half, f + half

    def target_n(self, trial: TrialCondition, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.full(len(t_s), float(trial.target_force_n))

    def rule(self, trial: TrialCondition) -> HoldDetector:
        return HoldDetector(trial.target_force_n, self.tolerance_fraction, int(round(self.hold_s * 1e9)))

    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        """The hold's completion on the whole trace (:func:`hold_completion_index`), the window and its metrics."""
        t, f = capped(t_ns, force_n, max_trial_s, window)
        target = float(trial.target_force_n)
        done = hold_completion_index(t, f, target, self.tolerance_fraction, int(round(self.hold_s * 1e9)))
        half = band_halfwidth_n(target, self.tolerance_fraction)

        def on_target(force: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
            return np.abs(force - target) <= half

        def reached(force: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
            return force >= target - half  # into the band, or through it between two samples

        return judged(t, f, done, target_n=lambda times: np.full(len(times), target), on_target=on_target,
                      max_trial_s=max_trial_s, window=window, sample_period_s=sample_period_s, metrics=_METRICS,
                      reached=reached)

    # -- what it shows and tells ---------------------------------------------------------------------------------
    def cue_text(self, trial: TrialCondition) -> str:
        return f"{trial.target_label} {trial.target_force_n:g} N"

    def screen(self, trial: TrialCondition) -> TrialScreen:
        lo, hi = band = self.band_n(trial)
        f, tol = trial.target_force_n, self.tolerance_fraction
        return TrialScreen(
            cue_word=trial.target_label, band=constant_band(*band),
            band_label=f"{trial.target_label}: target {f:g} N ± {round(100 * tol, 1):g} % ({lo:.3g}–{hi:.3g} N)",
            band_legend=f"target band {f:g} N ± {tol:.0%}",
        )

    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        # the live gauge shows the target band: with it the force is seen; a training trial has its own stream
        return TrialAim.constant(trial.target_force_n, trial.haptic_mode == "on", gauge=aid, practice=aid)

    # -- its words in the report ---------------------------------------------------------------------------------
    def rule_words(self) -> str:
        return f"band ±{self.tolerance_fraction:.0%}, hold {self.hold_s:g} s"

    @classmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        mine = [t for t in tasks if isinstance(t, ForceRegulation)]
        tol = listed([100 * t.tolerance_fraction for t in mine], " %")
        return (f"A sample is in the band when |F − F*| ≤ {tol} of F* (edges included, relative slack "
                f"{BAND_SLACK:g}). A trial succeeds when the force stays in the band continuously for "
                f"{listed([t.hold_s for t in mine], ' s')} (leaving the band restarts the hold) within "
                f"{listed(caps, ' s')} of the cue; TCT is the time from the cue to the end of that hold.")
