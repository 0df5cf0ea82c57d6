"""What the study record says beyond the trials: incomplete sessions, deviations, and which code ran what.

* :func:`incomplete_sessions` -- every experiment session that did not complete, with the reason in words
  ("P07, session 14: aborted by the experimenter after 10 of 20 trials") and whether it is analysed
  (``report --include-incomplete``) or left out (the default);
* :func:`damaged_trials` -- every trial left out because its records touch a damaged block of the recording,
  with where ("P01, session 1, trial 4: d.db: session 1, recorded run 0, 3.000–3.999 s (block 3): ...");
* :func:`aborted_reruns` -- of the aborted trials of the analysed sessions, how many were run again later in
  their session (an incomplete session may end before it re-runs them);
* :func:`deviations` -- every event of a deviation kind (:data:`analysis.load.DEVIATION_EVENTS`): a generic
  list, so a new kind of recorded deviation (an override, a skipped step) reaches the report by being stored
  as an event of kind ``deviation``;
* :func:`provenance` -- the package version, git commit and uncommitted-changes flag of every session (and
  of every resumed part of one), and the warnings a reviewer needs: sessions run by different code, code
  with uncommitted changes, code whose commit is not known.
"""

from __future__ import annotations

import json
import os

import pandas as pd

from analysis.load import DEVIATION_EVENTS, StudyData
from protocol.labels import plural

#: A session whose commit is not stored: run from an installed wheel, or recorded before commits were stored.
COMMIT_UNKNOWN = "not known (installed from a wheel, or recorded before commits were stored)"

__all__ = ["COMMIT_UNKNOWN", "aborted_reruns", "code_label", "damaged_trials", "deviations", "incomplete_sessions",
           "provenance"]


def incomplete_sessions(study: StudyData) -> pd.DataFrame:
    """Every experiment session that did not complete, with why, in words.

    Returns
    -------
    pandas.DataFrame
        ``database, participant_code, session_id, status, n_finished, n_designed, n_aborted, analysed, reason``;
        ``n_finished`` counts the trials that ended as designed (success or timeout), ``n_designed`` the
        trials of the session's design (its schedule less the re-runs).
    """
    s = study.sessions
    inc = s[(s["kind"] == "experiment") & (s["status"] != "completed")]
    t = study.trials
    rows = []
    for r in inc.itertuples():
        mine = t[(t["database"] == r.database) & (t["session_id"] == r.session_id)]
        finished = int((mine["outcome"] != "aborted").sum())
        aborted = int((mine["outcome"] == "aborted").sum())
        designed = "?" if pd.isna(r.n_designed) else str(int(r.n_designed))
        if r.status == "aborted":
            why = f"aborted by the experimenter after {finished} of {designed} trials"
            detail = str(r.end_reason or "").strip()
            if detail:
                why += f" ({detail})"
        else:
            why = (f"interrupted after {finished} of {designed} trials and not resumed (haptic-study run --resume "
                   f"{r.participant_code} continues it)")
        rows.append({"database": os.path.basename(str(r.database)), "participant_code": r.participant_code,
                     "session_id": int(r.session_id), "status": r.status, "n_finished": finished,
                     "n_designed": r.n_designed, "n_aborted": aborted, "analysed": bool(r.analysed),
                     "reason": f"{r.participant_code}, session {int(r.session_id)}: {why}"})
    return pd.DataFrame(rows, columns=["database", "participant_code", "session_id", "status", "n_finished",
                                       "n_designed", "n_aborted", "analysed", "reason"])


def damaged_trials(study: StudyData) -> pd.DataFrame:
    """The trials left out because their records touch a damaged block of the recording (``"recording damaged"``).

    Returns
    -------
    pandas.DataFrame
        ``database, participant_code, session_id, trial_number, damage, reason``, by database, session and trial:
        ``trial_number`` counts from 1, ``damage`` is the damaged stretch (:attr:`StudyData.damage`, the database
        by its file name) and ``reason`` the whole line ("P01, session 1, trial 4: recording damaged (...)").
    """
    t = study.trials[study.trials["excluded"] == "recording damaged"].sort_values(
        ["database", "session_id", "trial_index"], kind="stable")
    rows = []
    for r in t.itertuples():
        where = str(r.damage)
        db = str(r.database)
        if where.startswith(f"{db}: "):  # the line names the database by its path; the report by its file name
            where = f"{os.path.basename(db)}: {where[len(db) + 2:]}"
        number = int(r.trial_index) + 1
        rows.append({"database": os.path.basename(db), "participant_code": r.participant_code,
                     "session_id": int(r.session_id), "trial_number": number, "damage": where,
                     "reason": f"{r.participant_code}, session {int(r.session_id)}, trial {number}: recording damaged "
                               f"({where})"})
    return pd.DataFrame(rows, columns=["database", "participant_code", "session_id", "trial_number", "damage",
                                       "reason"])


def aborted_reruns(study: StudyData) -> tuple[int, int]:
    """(aborted trials of the analysed sessions, those of them run again later in their session)."""
    t = study.trials[study.trials["excluded"] == "aborted trial"]
    if t.empty:
        return 0, 0
    rep = study.trials[study.trials["repeat_of"].notna()]
    repeats = set(zip(rep["database"], rep["session_id"], rep["repeat_of"].astype(int), strict=True))
    rerun = sum((db, sid, int(idx)) in repeats
                for db, sid, idx in zip(t["database"], t["session_id"], t["trial_index"], strict=True))
    return len(t), int(rerun)


def deviations(study: StudyData) -> pd.DataFrame:
    """Every recorded deviation from the protocol: ``database, participant_code, session_id, kind, t_s, detail``."""
    ev = study.events
    cols = ["database", "participant_code", "session_id", "kind", "t_s", "detail"]
    if ev.empty:
        return pd.DataFrame(columns=cols)
    ev = ev[ev["kind"].isin(DEVIATION_EVENTS)]
    who = study.sessions[["database", "session_id", "participant_code"]]
    out = ev.merge(who, on=["database", "session_id"], how="left")
    out["database"] = out["database"].map(os.path.basename)
    return out[cols].reset_index(drop=True)


def code_label(version: object, commit: object, dirty: object) -> str:
    """``0.1.0, commit 1a2b3c4d5e6f`` (``, with uncommitted changes``), or the version and :data:`COMMIT_UNKNOWN`."""
    if not isinstance(commit, str) or not commit:
        return f"{version}, commit {COMMIT_UNKNOWN}"
    return f"{version}, commit {commit[:12]}{', with uncommitted changes' if dirty is True else ''}"


def _resumed_code(study: StudyData) -> pd.DataFrame:
    """The code of every resumed part of a session (``software`` events): database, session_id, code."""
    ev = study.events
    if ev.empty:
        return pd.DataFrame(columns=["database", "session_id", "code"])
    rows = []
    for r in ev[ev["kind"] == "software"].itertuples():
        try:
            d = json.loads(str(r.detail))
            rows.append({"database": r.database, "session_id": r.session_id,
                         "code": code_label(d.get("version"), d.get("commit"), d.get("dirty"))})
        except (ValueError, AttributeError):
            continue
    return pd.DataFrame(rows, columns=["database", "session_id", "code"])


def provenance(study: StudyData) -> tuple[pd.DataFrame, list[str]]:
    """Which code ran the study's sessions, and what a reviewer must be warned of.

    Returns
    -------
    table : pandas.DataFrame
        One row per distinct code (``code``: version, commit, uncommitted changes) with ``sessions`` (their ids,
        by database) and ``n_sessions``; a resumed part of a session run by other code counts for that code too.
    warnings : list of str
        Sessions of one study run by different code; code with uncommitted changes; commits not known.
    """
    s = study.sessions
    code = pd.Series([code_label(v, c, (None if pd.isna(d) else bool(d))) for v, c, d in
                      zip(s["software_version"], s["software_commit"], s["software_dirty"], strict=True)],
                     index=s.index)
    parts = pd.concat([pd.DataFrame({"database": s["database"], "session_id": s["session_id"], "code": code}),
                       _resumed_code(study)], ignore_index=True).drop_duplicates()
    rows = []
    for label, g in parts.groupby("code", sort=False):
        ids = ", ".join(f"{os.path.basename(str(db))}: {', '.join(str(int(i)) for i in sorted(set(h['session_id'])))}"
                        for db, h in g.groupby("database", sort=False))
        rows.append({"code": label, "n_sessions": int(g["session_id"].size), "sessions": ids})
    table = pd.DataFrame(rows, columns=["code", "n_sessions", "sessions"])
    warn = []
    if len(table) > 1:
        warn.append("The sessions of this study ran different code (" + "; ".join(
            f"{r.code}: {plural(r.n_sessions, 'session')}" for r in table.itertuples()) + "): a difference "
            "between sessions may come from the software, not the participants; check what changed between them.")
    dirty = int(code.str.endswith("with uncommitted changes").sum())
    if dirty:
        warn.append(f"{plural(dirty, 'session')} ran from a checkout with uncommitted changes: the code that ran "
                    f"{'it' if dirty == 1 else 'them'} is not exactly known from the commit.")
    unknown = int(code.str.endswith(COMMIT_UNKNOWN).sum())
    if unknown and unknown < len(code):
        warn.append(f"{plural(unknown, 'session')}: commit {COMMIT_UNKNOWN}; only the package version says which "
                    "code ran them.")
    return table, warn
