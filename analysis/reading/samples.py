"""Every recorded 1 kHz record as one labelled table, for pandas, R and SQL users, with its codebook.

:func:`samples_frame` is ``haptic-study export samples`` as a DataFrame: the recording's columns
(:func:`analysis.reading.recorded.recorded_samples`) with what a reader needs and the source code used to be
needed for -- the participant code, the trial phase by name beside its code, the latched faults by name beside the
bitmask, and a unit at the end of every name, spelled as the report's CSVs spell them (``_N`` newtons, ``_Nm``
newton-metres, ``_s``, ``_ms``, ``_m``; a fraction or flag has its unit in the codebook).
:func:`codebook_frame` describes every column: ``file, column, type, unit, description``, the same form as
the report's ``codebook.csv``.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from analysis.reading.load import _open
from analysis.reading.recorded import recorded_samples
from protocol.study.labels import FAULT_BITS, PHASE_NAMES, fault_names
from protocol.study.trial import PHASE_CODES, TrialPhase

__all__ = ["SAMPLES_COLUMNS", "codebook_frame", "samples_frame"]

_PHASES = ", ".join(f"{code} {name}" for code, name in sorted(PHASE_NAMES.items()))
_FAULTS = ", ".join(f"{bit} {name}" for bit, name in sorted(FAULT_BITS.items()))

#: Every column of the export, in order: (name, type, unit, description).  ``comp_*`` only for sessions
#: recorded before schema version 3 (whose compensated force was stored; a recording's is recomputed by replay).
SAMPLES_COLUMNS: tuple[tuple[str, str, str, str], ...] = (
    ("participant_code", "text", "", "pseudonymous participant code of the session"),
    ("session_id", "integer", "", "session in its database (sessions.session_id; haptic-study sessions lists them)"),
    ("arm", "text", "", ("the rig's arm whose records these are (exported with --arm on a rig of several arms; "
     "without it the task arm's, the trials' own)")),
    ("segment", "integer", "", "run of the session the record belongs to: 0, then one more per resume"),
    ("tick", "integer", "count", "the 1 kHz loop's tick number within its run"),
    ("session_time_s", "number", "s", "time since the session started (session clock)"),
    ("trial_number", "integer", "", ("trial within its session, numbered from 1 as the report and the GUI number "
     "them: the records from its cue to its last record (trials.first_tick to last_tick), exactly those its "
     "metrics are computed from; empty between trials, also for the up to ~50 records after a trial's last record "
     "that the loop still marked with it (the runner's mark of the pause reaches the loop one block late)")),
    ("t_since_cue_s", "number", "s", "time since the trial's cue; empty between trials"),
    ("phase", "text", "", ("the trial machine's phase: idle, cued (cue given, not yet in contact), active, pause; "
     "the records after a trial's last record that the loop still marked active are pause, as the machine was")),
    ("phase_code", "integer", "", f"the phase as a code ({_PHASES}), as recorded except as phase says"),
    ("force_N", "number", "N", ("task force: magnitude of the filtered, compensated contact force (what the trial "
     "was judged on)")),
    *((f"raw_f{a}_N", "number", "N", (f"raw F/T sensor force, {a} axis of the sensor frame (tool weight and bias "
       "included)")) for a in "xyz"),
    *((f"raw_t{a}_Nm", "number", "N·m", f"raw F/T sensor torque, {a} axis of the sensor frame") for a in "xyz"),
    *((f"render_f{a}_N", "number", "N", f"force commanded to the haptic device, {a} axis of the haptic frame")
      for a in "xyz"),
    ("gain", "number", "fraction (0–1)", "the safety stage's gain on the rendered force (ramps in and out)"),
    ("derate", "number", "fraction (0–1)", ("the fraction of the designed force the haptic device's thermal "
     "derating let through (1: not cut)")),
    ("haptic_on", "boolean", "", "force feedback switched on"),
    ("faults", "integer", "bitmask", f"latched watchdog faults as a bitmask ({_FAULTS}); 0 none"),
    ("fault_names", "text", "", "the latched faults by name, joined by |; none when none is latched"),
    *((f"stylus_{a}_m", "number", "m", f"stylus position, {a} axis") for a in "xyz"),
    ("sensor_age_ms", "number", "ms", "age of the F/T sample the tick used (watchdog limit 5 ms)"),
    ("pose_age_ms", "number", "ms", "age of the robot pose the tick used (watchdog limit 50 ms)"),
    ("latency_ms", "number", "ms", "time from the F/T sample's arrival to the force command it produced"),
    *((f"comp_f{a}_N", "number", "N", f"compensated force, {a} axis (stored by schema versions 1 and 2 only)")
      for a in "xyz"),
)

#: recorded name -> exported name
_RENAME = {"force_n": "force_N", "phase": "phase_code",
           **{f"raw_f{a}": f"raw_f{a}_N" for a in "xyz"}, **{f"raw_t{a}": f"raw_t{a}_Nm" for a in "xyz"},
           **{f"render_f{a}": f"render_f{a}_N" for a in "xyz"}, **{f"comp_f{a}": f"comp_f{a}_N" for a in "xyz"}}


def _codes_and_ends(database: str | os.PathLike[str], ids: list[int]) -> tuple[dict[int, str], pd.DataFrame]:
    """Each session's participant code, and each recorded trial's end (``session_id, segment, trial_number,
    last_tick``) of the sessions ``ids``."""
    db = _open(str(database))
    try:
        ends = [(sid, seg, idx + 1, last) for sid in ids for idx, (seg, last) in db.trial_ends(sid).items()]
        return db.session_codes(), pd.DataFrame(ends, columns=["session_id", "segment", "trial_number", "last_tick"])
    finally:
        db.close()


def _between_trials(out: pd.DataFrame, ends: pd.DataFrame) -> pd.DataFrame:
    """The records after a trial's last tick, which the loop still marked with it, labelled between trials.

    The runner's mark of the pause that follows a trial reaches the loop up to one block of records (~50 ms) after
    the trial's last record, so those records carry the trial's number and ``active``: they are not the trial's (its
    metrics end on its last tick) and are labelled as the trial machine was then -- no trial, ``pause``.
    """
    if out.empty or ends.empty or not {"segment", "tick", "trial_number"} <= set(out.columns):
        return out
    keys = out[["session_id", "segment", "trial_number"]].astype("Int64")
    last = keys.merge(ends.astype("Int64"), how="left", on=["session_id", "segment", "trial_number"])["last_tick"]
    after = (out["tick"].to_numpy() > last.to_numpy(dtype=float, na_value=np.inf))
    if after.any():
        out = out.copy()
        out.loc[after, "trial_number"] = pd.NA
        out.loc[after, "t_since_cue_s"] = np.nan
        out.loc[after, "phase"] = PHASE_CODES[TrialPhase.PAUSE]
    return out


def samples_frame(database: str | os.PathLike[str], session_id: int | None = None,
                  arm: str | None = None) -> pd.DataFrame:
    """The 1 kHz records of one session (or all), labelled: what ``haptic-study export samples`` writes.

    The records, and the parameters, are :func:`analysis.reading.recorded.recorded_samples`'; a named ``arm`` is a
    column too.

    Returns
    -------
    pandas.DataFrame
        One row per record, the columns of :data:`SAMPLES_COLUMNS` that the sessions have, in that order;
        sorted by session and time.

    Raises
    ------
    AnalysisError
        Not a study database, or no such session.
    """
    raw = recorded_samples(database, session_id, arm)
    ids = [int(x) for x in pd.unique(raw["session_id"])] if len(raw) else []
    codes, ends = _codes_and_ends(database, ids)
    out = _between_trials(raw, ends).rename(columns=_RENAME)
    out.insert(0, "participant_code", out["session_id"].map(lambda s: codes.get(int(s), "")).astype(str))
    if arm is not None:
        out.insert(2, "arm", arm)
    if "phase_code" in out.columns:
        phase = out["phase_code"]
        names = {int(c): PHASE_NAMES.get(int(c), f"unknown ({int(c)})") for c in pd.unique(phase.dropna())}
        out.insert(out.columns.get_loc("phase_code"), "phase", phase.map(names))
    if "faults" in out.columns:
        bits = out["faults"].to_numpy()
        names = {int(b): fault_names(int(b)) for b in np.unique(bits[~pd.isna(bits)])}
        out.insert(out.columns.get_loc("faults") + 1, "fault_names", out["faults"].map(names))
    order = [c for c, *_ in SAMPLES_COLUMNS if c in out.columns]
    labelled = out[order + [c for c in out.columns if c not in order]]
    labelled.attrs["damage"] = list(raw.attrs.get("damage", []))  # the damaged stretches left out, one line each
    return labelled


def codebook_frame(file: str, columns: list[str]) -> pd.DataFrame:
    """The codebook of an export: one row per column of ``file`` (``file, column, type, unit, description``)."""
    entries = {name: (kind, unit, text) for name, kind, unit, text in SAMPLES_COLUMNS}
    rows = [{"file": file, "column": c, "type": entries.get(c, ("", "", ""))[0],
             "unit": entries.get(c, ("", "", ""))[1],
             "description": entries.get(c, ("", "", ""))[2]} for c in columns]
    return pd.DataFrame(rows, columns=["file", "column", "type", "unit", "description"])
