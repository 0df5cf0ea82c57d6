"""What the study record says beyond the trials: incomplete sessions, deviations, and which code ran what.

* :func:`incomplete_sessions` -- every experiment session that did not complete, with the reason in words
  ("P07, session 14: aborted by the experimenter after 10 of 20 trials") and whether it is analysed
  (``report --include-incomplete``) or left out (the default);
* :func:`damaged_trials` -- every trial left out because its records touch a damaged block of the recording,
  with where ("P01, session 1, trial 4: d.db: session 1, recorded run 0, 3.000–3.999 s (block 3): ...");
* :func:`resumed_sessions` -- every resume of an interrupted session: when the run before it stopped, which trial
  the interruption cut, when the session went on, and the real-time break where the record says it;
* :func:`aborted_reruns` -- of the aborted trials of the analysed sessions, how many were run again later in
  their session (an incomplete session may end before it re-runs them);
* :func:`deviations` -- every event of a deviation kind (:data:`analysis.reading.load.DEVIATION_EVENTS`): a generic
  list, so a new kind of recorded deviation (an override, a skipped step) reaches the report by being stored
  as an event of kind ``deviation``;
* :func:`provenance` -- the package version, git commit and uncommitted-changes flag of every session (and
  of every resumed part of one), and the warnings a reviewer needs: sessions run by different code, code
  with uncommitted changes, code whose commit is not known;
* :func:`condition_warnings` -- analysed sessions that ran under different trial rules, targets or pipeline
  settings (databases of two protocols merged into one report): pooled, a difference may be the conditions'.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os

import pandas as pd

from analysis.reading.load import DEVIATION_EVENTS, StudyData
from protocol.study.labels import plural

#: A session whose commit is not stored: run from an installed wheel, or recorded before commits were stored.
COMMIT_UNKNOWN = "not known (installed from a wheel, or recorded before commits were stored)"

__all__ = ["COMMIT_UNKNOWN", "aborted_reruns", "code_label", "condition_warnings", "damaged_trials", "deviations",
           "incomplete_sessions", "provenance", "resumed_sessions", "session_activity", "status_words"]

#: The columns of :func:`resumed_sessions`.
RESUMED_COLUMNS = ("database", "participant_code", "session_id", "kind", "run", "n_runs", "interrupted_at_s",
                   "resumed_at_s", "cut_trial", "break_s", "reason")


def status_words(status: object, writer: object = "") -> str:
    """A session's status as ``haptic-study sessions`` says it: a stored ``running`` is ``interrupted`` (nothing
    runs it: resumable) or ``in progress`` (a live writer holds it); completed and aborted as stored."""
    if status != "running":
        return str(status)
    return "in progress" if isinstance(writer, str) and writer else "interrupted"


def session_activity(study: StudyData) -> pd.DataFrame:
    """What each session ran, by ``(database, session_id)``: ``n_trials`` (trials stored, aborted included),
    ``n_success``, ``trial_time_s`` (the trials' summed length, cue to end) and ``live_force_aid`` (a training session
    run with the live force gauge and band on the participant's screen)."""
    t = study.trials
    per = t.assign(length_s=t["ended_at_s"] - t["started_at_s"], ok=t["outcome"] == "success").groupby(
        ["database", "session_id"]).agg(n_trials=("trial_id", "size"), n_success=("ok", "sum"),
                                        trial_time_s=("length_s", "sum"))
    s = study.sessions[["database", "session_id", "kind"]].join(per, on=["database", "session_id"])
    s["n_trials"] = s["n_trials"].fillna(0).astype("int64")
    s["n_success"] = s["n_success"].fillna(0).astype("int64")
    aid = study.sessions.get("training_live_aid", pd.Series(False, index=study.sessions.index)).astype(bool)
    s["live_force_aid"] = (s["kind"] == "training") & aid
    return s.drop(columns="kind")


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
        elif getattr(r, "writer", ""):  # its lease is live: another process runs it now
            why = (f"in progress ({r.writer}), {finished} of {designed} trials done so far: still being run, not "
                   "interrupted; report again once it has ended")
        else:
            why = (f"interrupted after {finished} of {designed} trials and not resumed (haptic-study run --resume "
                   f"{r.participant_code} continues it)")
        rows.append({"database": os.path.basename(str(r.database)), "participant_code": r.participant_code,
                     "session_id": int(r.session_id), "status": status_words(r.status, getattr(r, "writer", "")),
                     "n_finished": finished,
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


def _wall_break_s(session: pd.Series, runs: pd.DataFrame) -> float:
    """The real time a session spent between its runs, s: its wall-clock span less its session-clock span -- on
    the real clock (the real rig, or the simulated rig in the GUI), whose session clock runs in real time and steps
    over a break; NaN on the virtual clock (the headless runner's) or when the session has not ended."""
    clock = session.get("clock") or ("real" if session["rig"] == "real" else "")  # (not stored: the rig says)
    if clock != "real" or not isinstance(session["ended_at"], str) or runs["last_record_s"].isna().all():
        return math.nan
    try:
        wall = (dt.datetime.fromisoformat(session["ended_at"])
                - dt.datetime.fromisoformat(str(session["started_at"]))).total_seconds()
    except ValueError:
        return math.nan
    return max(0.0, wall - float(runs["last_record_s"].max()))


def _cut(trials: pd.DataFrame, after_s: float, before_s: float) -> tuple[object, str]:
    """The trial an interruption cut (stored as aborted, cause interrupted, ending between the runs): its number
    and what became of it, or (None, words) when the run stopped between trials."""
    hit = trials[(trials["abort_cause"] == "interrupted") & (trials["ended_at_s"] > after_s)
                 & (trials["ended_at_s"] <= before_s)]
    if hit.empty:
        return None, "no trial was under way (the run stopped between trials)"
    r = hit.iloc[0]
    number = int(r["trial_index"]) + 1
    rerun = (trials["repeat_of"] == r["trial_index"]).any()
    return number, (f"it cut trial {number} (cue at {float(r['started_at_s']):.3f} s), stored as aborted "
                    f"(interrupted) and {'re-run later in the session' if rerun else 'not re-run'}")


def resumed_sessions(study: StudyData) -> pd.DataFrame:
    """Every resume of an interrupted session (its ``resume`` events), one row each, by database and session.

    Returns
    -------
    pandas.DataFrame
        :data:`RESUMED_COLUMNS`: ``run`` is the run the resume began (2 for the first), ``n_runs`` the session's
        runs; ``interrupted_at_s`` the session clock of the previous run's last record (NaN when not recorded),
        ``resumed_at_s`` of the resume; ``cut_trial`` the number of the trial the interruption cut (None when the
        run stopped between trials); ``break_s`` the real time between the runs, summed over a session's resumes
        (NaN where not derivable: the simulated rig's clock is virtual); ``reason`` all of it in words.
    """
    ev = study.events
    if ev.empty:
        return pd.DataFrame(columns=list(RESUMED_COLUMNS))
    rows = []
    resumes = ev[ev["kind"] == "resume"].sort_values(["database", "session_id", "t_s"], kind="stable")
    for (db, sid), g in resumes.groupby(["database", "session_id"], sort=False):
        session = study.sessions[(study.sessions["database"] == db) & (study.sessions["session_id"] == sid)].iloc[0]
        runs = study.runs[(study.runs["database"] == db) & (study.runs["session_id"] == sid)] if len(study.runs) \
            else pd.DataFrame(columns=["segment", "started_at_s", "last_record_s"])
        trials = study.trials[(study.trials["database"] == db) & (study.trials["session_id"] == sid)]
        wall = _wall_break_s(session, runs)
        brk = (f"the real-time break between the runs was {wall / 60:.1f} min{' in all' if len(g) > 1 else ''} "
               "(the session's wall-clock span less its session-clock span)" if math.isfinite(wall) else
               "the real-time break between the runs is not derivable (no wall-clock time of a run's start is "
               "stored" + (", and the session clock was virtual)" if session.get("clock") == "virtual" else ")"))
        previous = -math.inf
        for k, r in enumerate(g.itertuples(), start=2):
            before = runs[runs["started_at_s"] < float(r.t_s)]["last_record_s"].dropna()
            stopped = float(before.max()) if len(before) else math.nan
            number, cut = _cut(trials, previous, float(r.t_s))
            previous = float(r.t_s)
            stop = f"after {stopped:.3f} s of session time" if math.isfinite(stopped) else "(last record not stored)"
            rows.append({
                "database": os.path.basename(str(db)), "participant_code": session["participant_code"],
                "session_id": int(sid), "kind": session["kind"], "run": k, "n_runs": int(session["n_runs"]),
                "interrupted_at_s": stopped, "resumed_at_s": float(r.t_s), "cut_trial": number, "break_s": wall,
                "reason": (f"{session['participant_code']}, {session['kind']} session {int(sid)}: run {k - 1} was "
                           f"interrupted {stop}; {cut}; the session was resumed as run {k} of "
                           f"{int(session['n_runs'])} at {float(r.t_s):.3f} s; {brk}")})
    out = pd.DataFrame(rows, columns=list(RESUMED_COLUMNS))
    out["cut_trial"] = out["cut_trial"].astype("Int64")  # a resume between trials cut none: empty, not NaN
    return out


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


def _targets_by_session(study: StudyData) -> pd.Series:
    """Each analysed session's targets as the trials name them (``GENTLE 0.6 N, FIRM 1.2 N``), by ``(db, id)``."""
    # by force, then label: two targets of one force (a slow and a fast tracked profile) in one order for every
    # session, not in the order its schedule met them
    t = study.trials.drop_duplicates(["database", "session_id", "target_label"]).sort_values(
        ["target_force_n", "target_label"], kind="stable")
    return t.groupby(["database", "session_id"], sort=False).apply(
        lambda g: ", ".join(f"{lab} {f:g} N" for lab, f in zip(g["target_label"], g["target_force_n"], strict=True)),
        include_groups=False)


def _databases(sessions: pd.DataFrame) -> str:
    return ", ".join(sorted({os.path.basename(str(d)) for d in sessions["database"]}))


def condition_warnings(study: StudyData) -> list[str]:
    """A warning for each condition the analysed experiment sessions did not share.

    Each database's sessions run one protocol and one pipeline (``run`` refuses another), but ``report`` merges
    databases: one of another protocol (another band, hold or trial cap: success and TCT mean something else;
    other targets) or of other pipeline settings (``run --set``) would be pooled into one test without a word
    beyond the methods' "8 s / 6 s".

    Returns
    -------
    list of str
        One sentence per condition that differs (trial rules, targets, pipeline settings), naming each value with
        how many sessions in which databases ran it, and one naming participant numbers held by more than one
        participant; empty when every analysed session ran the same.
    """
    s = study.sessions[study.sessions["analysed"].astype(bool)].copy()
    if s.empty:
        return []
    targets = _targets_by_session(study)  # once: it groups every trial of the study
    s["targets"] = [targets.get((db, sid), "") for db, sid in zip(s["database"], s["session_id"], strict=True)]
    s["rules"] = [f"{study.task_of(db, sid).rule_words()}, cap {cap:g} s" for db, sid, cap in
                  zip(s["database"], s["session_id"], s["max_trial_s"], strict=True)]
    settings = s.get("pipeline_settings", pd.Series("", index=s.index))
    s["settings"] = [str(v) if isinstance(v, str) and v else "the paper's" for v in settings]
    out = []
    for column, what in (("rules", "trial rules"), ("targets", "targets"), ("settings", "pipeline settings")):
        groups = s.groupby(column, sort=False)
        if len(groups) < 2:
            continue
        each = "; ".join(f"{value}: {plural(len(g), 'session')} ({_databases(g)})" for value, g in groups)
        out.append(f"The analysed sessions ran under different {what} ({each}): the tests pool them, so a "
                   "difference may come from the conditions, not the feedback; analyse each condition apart "
                   "(one report per database) before pooling.")
    twice = s.groupby("participant_number", sort=True).filter(lambda g: g["participant_code"].nunique() > 1)
    if len(twice):
        each = "; ".join(f"{int(n)}: " + ", ".join(f"{r.participant_code} ({os.path.basename(str(r.database))})"
                                                    for r in g.drop_duplicates("participant_code").itertuples())
                         for n, g in twice.groupby("participant_number", sort=True))
        out.append(f"Participant numbers repeat across the analysed sessions ({each}): a participant's number sets "
                   "their counterbalancing position and, with the seed, their schedule, so these participants may "
                   "have met the same order, where the design gives each participant a number of their own "
                   "(merged databases that each numbered from 1?).")
    return out
