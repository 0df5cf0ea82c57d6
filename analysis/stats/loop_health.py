"""The study's record of its own delivery: trials not counted (by cause) and the 1 kHz loop's health per trial.

The paper claims a 1 kHz, low-latency pipeline; each trial row (schema
version 2) carries what the loop did during it -- tick period p50/p99/max,
ticks over 2 ms, the oldest F/T sample and robot pose it used, and the latency
from a sample's arrival to the force command (see :mod:`protocol.runner.session`).
This module checks them against :data:`LOOP_BOUNDS` and counts the trials
that were aborted, by cause, so a reviewer can see on the data whether the
condition each trial was designed for was delivered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.reading.load import StudyData
from protocol.storage import ABORT_CAUSES, HEALTH_COLUMNS

__all__ = ["ABORT_CAUSE_TEXT", "LOOP_BOUNDS", "LoopBound", "abort_counts", "health_summary", "health_table"]


@dataclass(frozen=True, slots=True)
class LoopBound:
    """An upper bound on one loop-health column of a trial: a number, or a limit the session stored."""

    column: str
    limit: float | str
    why: str

    def describe(self) -> str:
        """The bound in words."""
        if isinstance(self.limit, str):
            return f"{self.why} ≤ the session's watchdog limit"
        return f"{self.why} ≤ {self.limit:g}{'' if self.column == 'periods_over_2ms' else ' ms'}"


#: What a trial's loop must stay within: no tick over 2 ms (the paper's 1 kHz), samples and poses no older than
#: the watchdog limits the session ran with (stored in its configuration), and a sample's force sent within two ticks.
LOOP_BOUNDS: tuple[LoopBound, ...] = (
    LoopBound("periods_over_2ms", 0, "ticks over 2 ms"),
    LoopBound("period_max_ms", 2.0, "longest tick period"),
    LoopBound("sensor_age_max_ms", "watchdog_sensor_max_age_ms", "oldest F/T sample"),
    LoopBound("pose_age_max_ms", "watchdog_pose_max_age_ms", "oldest robot pose"),
    LoopBound("latency_max_ms", 2.0, "sample-to-command latency"),
)
#: How each abort cause reads in the report.
ABORT_CAUSE_TEXT: dict[str, str] = {
    "experimenter": "aborted by the experimenter",
    "fault": "a fault latched (sensor, pose, haptic device, or the loop itself stalled)",
    "feedback": "feedback not as designed (switch, gain, or the device's thermal derating)",
    "gap": "loop records missing",
    "interrupted": "the program ended during the trial",
    "participant_screen": "the participant screen closed during the trial (the cue was not seen)",
    "": "cause not recorded (schema version 1)",
}


def health_table(study: StudyData) -> pd.DataFrame:
    """One row per experiment trial (aborted ones included) with its loop health and where it left the bounds.

    Columns: ``participant_code``, ``participant_number``, ``session_id``, ``trial_index``, ``outcome``,
    ``abort_cause``, the health columns, ``within_bounds`` (None when the trial has no health record)
    and ``outside_bounds`` (which bounds, in words).
    """
    t = study.trials[study.trials["session_kind"] == "experiment"]
    limits = study.sessions[["database", "session_id", "watchdog_sensor_max_age_ms", "watchdog_pose_max_age_ms"]]
    t = t.merge(limits, on=["database", "session_id"], how="left", validate="many_to_one")
    out = t[["database", "participant_code", "participant_number", "session_id", "trial_index", "outcome",
             "abort_cause", *HEALTH_COLUMNS]].copy()
    out["abort_cause"] = out["abort_cause"].where(out["outcome"] == "aborted")
    recorded = out[list(HEALTH_COLUMNS)].notna().all(axis=1).to_numpy()
    notes: list[str] = []
    within: list[bool | None] = []
    for ok_row, row, session in zip(recorded, out.itertuples(index=False), t.itertuples(index=False), strict=True):
        if not ok_row:
            within.append(None)
            notes.append("")
            continue
        over = []
        for b in LOOP_BOUNDS:
            limit = float(getattr(session, b.limit)) if isinstance(b.limit, str) else b.limit
            value = float(getattr(row, b.column))
            if value > limit:  # (a session without a stored limit compares with NaN: never over)
                over.append(f"{b.why} {_fmt(value)} > {_fmt(limit)}")
        within.append(not over)
        notes.append("; ".join(over))
    out["within_bounds"] = pd.array(within, dtype="boolean")
    out["outside_bounds"] = notes
    return out.reset_index(drop=True)


def _fmt(v: float) -> str:
    return f"{v:g}" if float(v).is_integer() else f"{v:.3g}"


def abort_counts(study: StudyData) -> pd.DataFrame:
    """Aborted experiment trials per cause (every cause listed, zeros included): ``abort_cause``, ``n_trials``."""
    t = study.trials[(study.trials["session_kind"] == "experiment") & (study.trials["outcome"] == "aborted")]
    causes = t["abort_cause"].fillna("").astype(str)
    counts = causes.value_counts()
    order = list(ABORT_CAUSES) + ([""] if "" in counts.index else [])
    return pd.DataFrame({"abort_cause": order, "n_trials": [int(counts.get(c, 0)) for c in order]})


def health_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per participant: the loop over all their experiment trials (worst case for maxima, medians for p50s)."""
    rec = table[table["within_bounds"].notna()]
    if rec.empty:
        return pd.DataFrame(columns=["participant_code", "participant_number", "n_trials", "n_outside_bounds",
                                     *HEALTH_COLUMNS])
    g = rec.groupby(["participant_code", "participant_number"], sort=False)
    out = g.agg(
        n_trials=("trial_index", "size"),
        n_outside_bounds=("within_bounds", lambda s: int((~s.astype(bool)).sum())),
        period_p50_ms=("period_p50_ms", "median"),
        period_p99_ms=("period_p99_ms", "max"),
        period_max_ms=("period_max_ms", "max"),
        periods_over_2ms=("periods_over_2ms", "sum"),
        sensor_age_max_ms=("sensor_age_max_ms", "max"),
        pose_age_max_ms=("pose_age_max_ms", "max"),
        latency_p50_ms=("latency_p50_ms", "median"),
        latency_max_ms=("latency_max_ms", "max"),
    ).reset_index()
    out["periods_over_2ms"] = out["periods_over_2ms"].astype(np.int64)
    return out
