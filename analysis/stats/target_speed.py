"""Tracking error against the target's speed, within participants: the speed–accuracy trade of a moving target.

A study whose target moves (force tracking: a profile per target, ``[task.targets.LABEL]``) asks how much harder a
faster target is to follow, and whether haptics change that.  Each target's **speed** is the mean of |dF*/dt| over
the part of the trial where its target moves (N/s; a sine of amplitude A at f Hz: 4·A·f), asked of the session's
task (:meth:`protocol.tasks.base.Task.target_n`), so any task whose target moves has it; a target that holds has
none.  Per participant and haptic mode, the tracking error of each target is the mean RMSE of its trials, and the
trade is the least-squares slope of that error on the targets' speeds (RMSE per N/s of speed, in s): one value per
participant per mode, compared ON against OFF by the paired Wilcoxon signed-rank test
(:func:`analysis.stats.wilcoxon.paired_wilcoxon`, with its own p: outside Holm's family).  No p-value here pools
trials as if independent.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from analysis.stats.holm import results_frame
from analysis.stats.wilcoxon import WilcoxonResult, paired_wilcoxon
from protocol.tasks.base import Task, TrialTarget

__all__ = ["SLOPE", "TargetSpeedTrade", "target_speed", "target_speed_trade"]

#: The trade's measure: the slope of a participant's mean RMSE on the targets' speeds, per mode (s).
SLOPE = "rmse_per_speed_s"
#: The grid the target is sampled on to find its speed, s (the loop's 1 ms).
_STEP_S = 0.001


def target_speed(task: Task, target: TrialTarget, max_trial_s: float) -> float:
    """The mean |dF*/dt| of a trial's target where it moves, from the cue to the trial cap, N/s (0: it holds)."""
    t = np.arange(0.0, max_trial_s + _STEP_S / 2, _STEP_S)
    rate = np.abs(np.diff(task.target_n(target, t))) / _STEP_S
    moving = np.flatnonzero(rate > 1e-9)
    return float(np.mean(rate[moving[0]:moving[-1] + 1])) if len(moving) else 0.0


class TargetSpeedTrade:
    """The trade of one study: per target, participant and mode the mean RMSE at the target's speed
    (:attr:`by_target`), each participant's slope per mode (:attr:`slopes`) and their test ON vs OFF
    (:attr:`test`, :attr:`result`)."""

    def __init__(self, by_target: pd.DataFrame, slopes: pd.DataFrame, result: WilcoxonResult) -> None:
        self.by_target, self.slopes, self.result = by_target, slopes, result
        self.test = results_frame([result], family=())

    @property
    def n_speeds(self) -> int:
        """How many distinct target speeds the study's targets have."""
        return int(self.by_target["target_speed_n_per_s"].nunique())


def _speeds(trials: pd.DataFrame, task_of: Callable[[str, int], Task]) -> np.ndarray:
    """Each trial's target speed (one computation per session task and target)."""
    seen: dict[tuple[int, str, float, float], float] = {}
    out = np.empty(len(trials))
    for i, row in enumerate(trials[["database", "session_id", "target_label", "target_force_n", "haptic_mode",
                                    "max_trial_s"]].itertuples(index=False)):
        task = task_of(str(row.database), int(row.session_id))
        key = (id(task), str(row.target_label), float(row.target_force_n), float(row.max_trial_s))
        if key not in seen:
            seen[key] = target_speed(task, TrialTarget(str(row.target_label), float(row.target_force_n),
                                                       str(row.haptic_mode)), float(row.max_trial_s))
        out[i] = seen[key]
    return out


def target_speed_trade(trials: pd.DataFrame, task_of: Callable[[str, int], Task], *, zero_method: str = "wilcox",
                       confidence: float = 0.95) -> TargetSpeedTrade | None:
    """The trade of tracking error against target speed, or None: no RMSE, or fewer than two distinct speeds.

    Parameters
    ----------
    trials
        The analysed trials (:attr:`analysis.reading.metrics.TrialTable.trials`) with each session's trial cap
        (``max_trial_s``, as :attr:`analysis.reading.load.StudyData.included` has it).
    task_of
        Each session's task by database and session id (:meth:`analysis.reading.load.StudyData.task_of`).
    zero_method, confidence
        As the report's tests.
    """
    if "rmse_n" not in trials.columns or trials.empty:
        return None
    t = trials.assign(target_speed_n_per_s=_speeds(trials, task_of))
    if t["target_speed_n_per_s"].nunique() < 2 or not (t["target_speed_n_per_s"] > 0).any():
        return None
    keys = ["participant_code", "haptic_mode", "target_label"]
    by_target = (t.groupby(keys, sort=True)
                 .agg(target_speed_n_per_s=("target_speed_n_per_s", "first"), rmse_n=("rmse_n", "mean"),
                      n_trials=("rmse_n", "size")).reset_index())
    rows = []
    for (code, mode), g in by_target.groupby(["participant_code", "haptic_mode"], sort=True):
        ok = g[np.isfinite(g["rmse_n"])]
        x, y = ok["target_speed_n_per_s"].to_numpy(float), ok["rmse_n"].to_numpy(float)
        slope = intercept = np.nan
        if len(x) >= 2 and np.ptp(x) > 0:
            slope, intercept = (float(v) for v in np.polyfit(x, y, 1))
        rows.append({"participant_code": code, "haptic_mode": mode, "n_targets": len(x), SLOPE: slope,
                     "intercept_n": intercept})
    slopes = pd.DataFrame(rows, columns=["participant_code", "haptic_mode", "n_targets", SLOPE, "intercept_n"])
    wide = slopes.pivot(index="participant_code", columns="haptic_mode", values=SLOPE).reindex(
        columns=["off", "on"])
    result = paired_wilcoxon(wide["off"].to_numpy(float), wide["on"].to_numpy(float), metric=SLOPE,
                             zero_method=zero_method, confidence=confidence)
    return TargetSpeedTrade(by_target, slopes, result)
