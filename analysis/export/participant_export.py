"""Everything stored about one participant, in open formats: the answer to a subject-access request.

``haptic-study export participant`` writes, into a new folder (the output policy of :mod:`foundation.outdir`)::

    participant.csv     their participants row (the pseudonymous code, when it was first stored)
    covariates.csv      what the protocol collected about them (its [[covariates]]), given when they were registered
    sessions.csv        their sessions (the settings of each are in sessions.json)
    sessions.json       each session's protocol, schedule, rig and pipeline configuration, calibration, and each
                        recorded run's starting state
    stored_trials.csv   their trials as stored live, every column
    trials.csv          their trials as the report analyses them (the report's trials.csv, their rows only)
    events.csv          every event of their sessions (phases, cues, faults, experimenter actions)
    notes.csv           the experimenter's notes on their sessions and trials
    answers.csv         their answers to the protocol's questionnaires (NASA-TLX, Likert items)
    samples.csv         every recorded 1 kHz record of their sessions (analysis.samples_frame)
    poses.csv           the robot poses the pipeline took (125 Hz), per recorded run
    recording_log.csv   the recording's log: commands and events the pipeline applied, by tick
    recordings.csv      their recorded runs; blocks.csv the recorded blocks (where, how many records, checksum);
                        chunks.csv the last block of a run that was killed, as its commits wrote it
    arm_samples.csv     a rig of several arms: the other arms' 1 kHz records (as samples.csv, with the arm);
                        arm_recordings.csv, arm_blocks.csv, arm_chunks.csv their runs and blocks (only when stored)
    lsl_samples.csv     sessions on the Lab Streaming Layer: the external streams' samples, each with its LSL
                        timestamp and its session-clock time; lsl_streams.csv what each stream is, lsl_runs.csv each
                        run's clock link (only when stored; docs/lsl.md)
    leases.csv          writers' leases on their sessions (normally none: a lease lives while a session runs)
    codebook.csv        every column of every table: what it holds, its unit and type

With ``fmt="parquet"`` the tables are Parquet files instead of CSV (the codebook stays CSV).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.reading import codebook
from analysis.reading.errors import AnalysisError
from analysis.reading.load import load_study
from analysis.reading.metrics import MetricOptions, compute_trials
from analysis.reading.samples import SAMPLES_COLUMNS, samples_frame
from analysis.report.report_tables import TRIALS_CSV_COLUMNS, trials_csv
from protocol.storage import StorageError, StudyReader
from protocol.storage.participant_data import ParticipantRows

__all__ = ["FILES", "PARTICIPANT_MARKER", "ParticipantExport", "participant_export", "write_participant_export"]

#: The marker of an ``export participant`` folder (:mod:`foundation.outdir`).
PARTICIPANT_MARKER = ".haptic-study-participant"
#: Session columns that hold JSON: they go to sessions.json, parsed.
_SESSION_JSON = {"protocol_json": "protocol", "schedule_json": "schedule", "config_json": "config",
                 "calibration_json": "calibration"}
_RECORDING_JSON = {"snapshot_json": "snapshot", "scales_json": "scales"}

#: What the columns of the exported tables hold, where :mod:`analysis.reading.codebook` (the report's) does not say it
#: for the same name: (file, column) first, then the column in any file.  ``tests`` check none is left out.
_DESCRIBED: dict[str, tuple[str, str, str]] = {  # column -> (description, unit, type)
    "participant_id": ("the participant's row number in the database", "", "integer"),
    "code": ("pseudonymous participant code", "", "text"),
    "created_at": ("when the participant was first stored, ISO 8601 UTC", "", "text"),
    "calibration_json": ("see sessions.json", "", "text"),
    "software_commit": ("git commit of the checkout that ran the session; empty where not known", "", "text"),
    "software_dirty": ("1 if that checkout had uncommitted changes; empty where not known", "", "integer"),
    "trial_id": ("the trial's key in the database: session_id × 1,000,000 + trial_index", "", "integer"),
    "trial_index": ("trial within its session, numbered from 0 (trial_number − 1)", "", "integer"),
    "target_force_n": ("target force F*", "N", "number"),
    "started_at_s": ("session-clock time of the cue (trials) or of the recorded run's first record", "s", "number"),
    "ended_at_s": ("session-clock time of the trial's end", "s", "number"),
    "rmse_n": ("root-mean-square error of the task force against F*, as computed live", "N", "number"),
    "max_ae_n": ("largest absolute error of the task force against F*, as computed live", "N", "number"),
    "peak_force_n": ("largest task force over the trial, as computed live", "N", "number"),
    "n_samples": ("1 kHz records in the trial's window", "count", "integer"),
    "abort_reason": ("why an aborted trial did not count, with the value that tripped it", "", "text"),
    "repeat_of": ("trial_index of the aborted trial this one re-runs", "", "integer"),
    "segment": ("recorded run of the session (0 for its first, one more per resume)", "", "integer"),
    "first_tick": ("loop tick of the first record (the trial's cue, or the block's first)", "", "integer"),
    "last_tick": ("loop tick of the last record", "", "integer"),
    "t_s": ("session-clock time", "s", "number"),
    "detail": ("what happened, in words", "", "text"),
    "t0_ns": ("loop time of the run's first record: session time = started_at_s + (t_ns − t0_ns) / 1e9", "ns",
              "integer"),
    "block": ("block within the recorded run, numbered from 0", "", "integer"),
    "chunk": ("chunk of the block, in the order its commits wrote them, numbered from 0", "", "integer"),
    "arm": ("the rig's arm the records are of (a rig of several arms; the task arm's are samples.csv)", "", "text"),
    "n_records": ("1 kHz records the block holds", "count", "integer"),
    "t_first_s": ("session-clock time of the block's first record", "s", "number"),
    "t_last_s": ("session-clock time of the block's last record", "s", "number"),
    "crc32": ("CRC-32 of the block's place (arm, session, run, block, chunk, ticks, records) then its bytes in a run "
              "that counts its blocks, else of its bytes (empty: written before schema version 4)", "", "integer"),
    "n_blocks": ("blocks the run wrote whole (empty: a run recorded before the count, whose checksums cover the "
                 "blocks' bytes only)", "count", "integer"),
    "scope": ("what the lease covers ('session N')", "", "text"),
    "owner": ("random token of the command holding the lease", "", "text"),
    "pid": ("process holding the lease", "", "integer"),
    "host": ("computer of that process", "", "text"),
    "process_start": ("boot id and start time of that process", "", "text"),
    "command": ("command line of that process", "", "text"),
    "acquired_at": ("when the lease was taken, ISO 8601 UTC", "", "text"),
    "heartbeat_at": ("the lease's last heartbeat, ISO 8601 UTC", "", "text"),
    "tick": ("loop tick (one per 1 kHz cycle of the haptic loop)", "", "integer"),
    "session_time_s": ("session-clock time of the record", "s", "number"),
    "t_since_cue_s": ("time since the trial's cue (empty between trials)", "s", "number"),
    "phase": ("trial phase code of the record (protocol.study.trial.PHASE_CODES)", "", "integer"),
    "force_n": ("task force: magnitude of the filtered, compensated contact force", "N", "number"),
    "gain": ("safety stage's gain on the rendered force (0–1; ramps in and out)", "fraction (0–1)", "number"),
    "derate": ("fraction of the designed force the haptic device's thermal derating let through (1: not cut)",
               "fraction (0–1)", "number"),
    "haptic_on": ("haptic feedback switched on", "", "boolean"),
    "faults": ("watchdog fault flags latched (bit mask; 0: none)", "", "integer"),
    "sensor_age_ms": ("age of the F/T sample the loop used", "ms", "number"),
    "pose_age_ms": ("age of the robot pose the loop used", "ms", "number"),
    "latency_ms": ("time from the F/T sample's arrival to the force command", "ms", "number"),
    "pose_t_ns": ("loop time the robot pose was measured", "ns", "integer"),
    "x_m": ("robot tool position x, base frame", "m", "number"),
    "y_m": ("robot tool position y, base frame", "m", "number"),
    "z_m": ("robot tool position z, base frame", "m", "number"),
    "payload": ("what was applied, as JSON", "", "text"),
    "file": ("file of the export folder", "", "text"),
    "name": ("the covariate's name, as the protocol declares it", "", "text"),
    "value": ("its value: a category's level, or a number as written", "", "text"),
    "text": ("the note, as the experimenter wrote it", "", "text"),
    "deviation": ("1: the experimenter marked the note a deviation from the protocol", "", "integer"),
    "written_at": ("when the note was written, ISO 8601 UTC", "", "text"),
    "questionnaire": ("the questionnaire's name, as the protocol declares it", "", "text"),
    "item": ("the question: a NASA-TLX subscale or pair (mental|physical), a Likert item's id", "", "text"),
    "rating": ("the rating given (NASA-TLX 0–100, a Likert item on its scale)", "", "number"),
    "choice": ("a NASA-TLX pair: the subscale chosen as contributing more to the workload", "", "text"),
    "answered_at_s": ("session-clock time the answers were stored", "s", "number"),
    "records_to_lsl_s": ("the run's clock link: a record's LSL time = t_ns × 1e-9 + this", "s", "number"),
    "uncertainty_s": ("bound of the clock link's measurement (half the narrowest bracket of the readings)", "s",
                      "number"),
    "outlets": ("the LSL outlets the run published (name, type, source_id), as JSON", "", "text"),
    "selector": ("how the protocol named the stream: name = '…' or type = '…'", "", "text"),
    "source_id": ("the stream's LSL source id", "", "text"),
    "hostname": ("the computer the stream came from", "", "text"),
    "channel_count": ("channels of the stream", "count", "integer"),
    "nominal_srate": ("the stream's nominal rate (0: irregular)", "Hz", "number"),
    "channel_format": ("the stream's value type (float32, double64, string, ...)", "", "text"),
    "info_xml": ("the stream's full LSL description, as XML", "", "text"),
    "lsl_t_s": ("the sample's LSL timestamp, on its source's clock", "s", "number"),
    "time_correction_s": ("the source's clock to ours, measured when the sample was taken (LSL time_correction)", "s",
                          "number"),
    "session_t_s": ("the sample's session-clock time: started_at_s + (lsl_t_s + time_correction_s − "
                    "records_to_lsl_s) − t0_ns / 1e9", "s", "number"),
    "values": ("the sample's channels, as a JSON list", "", "text"),
}
for _axis in ("x", "y", "z"):
    _DESCRIBED[f"stylus_{_axis}_m"] = (f"haptic stylus position {_axis}", "m", "number")
    _DESCRIBED[f"raw_f{_axis}"] = (f"raw sensor force {_axis}, sensor frame, tool weight and bias included", "N",
                                   "number")
    _DESCRIBED[f"raw_t{_axis}"] = (f"raw sensor torque about {_axis}, sensor frame", "N·m", "number")
    _DESCRIBED[f"comp_f{_axis}"] = (f"compensated force {_axis} (recorded before schema version 3)", "N", "number")
    _DESCRIBED[f"render_f{_axis}"] = (f"force {_axis} sent to the haptic device, haptic frame", "N", "number")
for _i in range(9):
    _DESCRIBED[f"r{_i}"] = (f"robot tool rotation matrix, element {_i // 3 + 1},{_i % 3 + 1} (row-major)", "",
                            "number")
_FILE_DESCRIBED = {("events.csv", "kind"): ("what happened: phase, cue, fault, reset, session_start, ...", "", "text"),
                   ("covariates.csv", "kind"): ("the covariate's kind: category, integer or float", "", "text"),
                   ("notes.csv", "t_s"): ("session-clock time the note was written (empty: added after the session)",
                                          "s", "number"),
                   ("notes.csv", "trial_index"): ("the trial the note is about, numbered from 0 (empty: the session)",
                                                  "", "integer"),
                   ("answers.csv", "block"): ("the block the questionnaire followed: its haptic mode (on, off), or "
                                              "session", "", "text"),
                   ("recording_log.csv", "kind"): ("what the pipeline applied at that tick", "", "text"),
                   ("lsl_streams.csv", "stream"): ("the stream's place in the protocol's lsl.record list", "",
                                                   "integer"),
                   ("lsl_streams.csv", "name"): ("the stream's LSL name", "", "text"),
                   ("lsl_streams.csv", "type"): ("the stream's LSL content type (EEG, EMG, Markers, ...)", "", "text"),
                   ("lsl_samples.csv", "stream"): ("the stream's LSL name", "", "text")}


#: What each file of an export holds (written into sessions.json, so the folder explains itself).
FILES = {
    "participant": "their participants row: the pseudonymous code and when it was first stored",
    "covariates": "what the protocol collected about them (its [[covariates]]), given when they were registered",
    "sessions": "their sessions (the settings of each are in sessions.json)",
    "sessions.json": "each session's protocol, schedule, rig and pipeline configuration, calibration, and each "
                     "recorded run's starting state",
    "stored_trials": "their trials as stored live, every column",
    "trials": "their trials as the report analyses them (the report's trials.csv, their rows only)",
    "events": "every event of their sessions (phases, cues, faults, experimenter actions)",
    "notes": "the experimenter's notes on their sessions and trials",
    "answers": "their answers to the protocol's questionnaires (NASA-TLX, Likert items)",
    "samples": "every recorded 1 kHz record of their sessions",
    "poses": "the robot poses the pipeline took (125 Hz), per recorded run",
    "recording_log": "the recording's log: what the pipeline applied, by loop tick",
    "recordings": "their sessions' recorded runs",
    "blocks": "the recorded blocks: where, how many records, checksum",
    "chunks": "the last block of a run that was killed, in the chunks its commits wrote: where, how many records, "
              "checksum",
    "arm_samples": "a rig of several arms: every recorded 1 kHz record of the other arms than the task arm",
    "arm_recordings": "a rig of several arms: the other arms' recorded runs",
    "arm_blocks": "a rig of several arms: the other arms' recorded blocks",
    "arm_chunks": "a rig of several arms: the other arms' last blocks of a run that was killed, in their chunks",
    "lsl_runs": "sessions on the Lab Streaming Layer: each recorded run's clock link to LSL and its outlets",
    "lsl_streams": "the external LSL streams recorded with their sessions (EMG, eye tracking, ...): what each is",
    "lsl_samples": "every sample of those streams, with its LSL timestamp and its session-clock time",
    "leases": "writers' leases on their sessions (normally none)",
    "codebook.csv": "every column of every table: what it holds, its unit and type",
}


@dataclass(frozen=True, slots=True)
class ParticipantExport:
    """One participant's data, ready to write: tables by file stem, the sessions' settings, damage lines."""

    code: str
    tables: dict[str, pd.DataFrame]
    settings: dict[str, Any]
    damage: list[str]


def _frame(rows: ParticipantRows, table: str, drop: tuple[str, ...] = ()) -> pd.DataFrame:
    t = rows.tables.get(table)
    if t is None:
        return pd.DataFrame()
    frame = pd.DataFrame(list(t.rows), columns=list(t.columns))
    return frame.drop(columns=[c for c in drop if c in frame.columns])


def _parsed(text: object) -> Any:
    if text is None:
        return None
    try:
        return json.loads(str(text))
    except ValueError:
        return str(text)  # stored as it is: still theirs to see


def _settings(rows: ParticipantRows, database: str) -> dict[str, Any]:
    from foundation.version import software_version

    sessions = _frame(rows, "sessions")
    recs = _frame(rows, "recordings")
    out = []
    for s in sessions.to_dict("records"):
        entry = {k: v for k, v in s.items() if k not in _SESSION_JSON}
        entry.update({name: _parsed(s.get(col)) for col, name in _SESSION_JSON.items()})
        mine = recs[recs["session_id"] == s["session_id"]] if len(recs) else recs
        entry["recordings"] = [{**{k: v for k, v in r.items() if k not in _RECORDING_JSON},
                                **{name: _parsed(r.get(col)) for col, name in _RECORDING_JSON.items()}}
                               for r in mine.to_dict("records")]
        out.append(entry)
    return {"participant": rows.code, "database": os.path.basename(database),
            "exported_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "exported_by": f"haptic-study {software_version()}", "files": FILES, "sessions": out}


def _other_arms(path: str, rows: ParticipantRows) -> dict[str, pd.DataFrame]:
    """A rig of several arms: the other arms' records and recordings ({} when none is stored)."""
    recs = _frame(rows, "arm_recordings", tuple(_RECORDING_JSON))
    if recs.empty:
        return {}
    samples = [samples_frame(path, int(sid), str(arm))
               for sid, arm in recs[["session_id", "arm"]].drop_duplicates().itertuples(index=False)]
    return {"arm_samples": pd.concat(samples, ignore_index=True), "arm_recordings": recs,
            "arm_blocks": _frame(rows, "arm_blocks"), "arm_chunks": _frame(rows, "arm_chunks")}


def _recording_extras(database: str, session_ids: tuple[int, ...]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(poses, log) of their recorded runs; damaged blocks are left out (samples_frame names them)."""
    from protocol.storage.recordings import read_segment, segments_of

    db = StudyReader(database, check=False)
    poses, logs = [], []
    try:
        for sid in session_ids:
            for seg, _, _ in (segments_of(db, sid) if db.schema_version >= 3 else []):
                d = read_segment(db, sid, seg, skip_damaged=True)
                p = pd.DataFrame({k: np.asarray(v) for k, v in d.poses.items()})
                poses.append(p.assign(session_id=sid, segment=seg))
                logs.append(pd.DataFrame(
                    [(sid, seg, int(t), str(k), json.dumps(payload, default=str)) for t, k, payload in d.events],
                    columns=["session_id", "segment", "tick", "kind", "payload"]))
    finally:
        db.close()
    pose_cols = ["session_id", "segment", "tick", "pose_t_ns", *(f"r{i}" for i in range(9)), "x_m", "y_m", "z_m"]
    pose = pd.concat(poses, ignore_index=True) if poses else pd.DataFrame(columns=pose_cols)
    log = (pd.concat(logs, ignore_index=True) if logs else
           pd.DataFrame(columns=["session_id", "segment", "tick", "kind", "payload"]))
    return pose[[c for c in pose_cols if c in pose.columns]], log


def _analysed(database: str, code: str, options: MetricOptions) -> pd.DataFrame:
    """Their trials as the report analyses them (the report's trials.csv, their rows), or an empty table."""
    try:
        study = load_study([database])
    except AnalysisError:  # nothing the report could analyse (no experiment trial in the study)
        return pd.DataFrame(columns=list(TRIALS_CSV_COLUMNS))
    trials = study.trials[study.trials["participant_code"] == code]
    mine = replace(study, trials=trials, sessions=study.sessions[study.sessions["participant_code"] == code])
    if mine.included.empty:
        return pd.DataFrame(columns=list(TRIALS_CSV_COLUMNS))
    t = compute_trials(mine, options, workers=1).trials.sort_values(["session_id", "trial_index"], kind="stable")
    return trials_csv(t, options.error_window)


def participant_export(database: str | os.PathLike[str], code: str,
                       options: MetricOptions | None = None) -> ParticipantExport:
    """Read everything stored about participant ``code`` (read-only).

    Raises
    ------
    AnalysisError
        Not a study database, or no such participant (one who withdrew is named as such).
    """
    path = str(database)
    try:
        db = StudyReader(path, check=True)
    except StorageError as exc:
        raise AnalysisError(str(exc)) from None
    try:
        rows = db.participant_data(code)  # p01 for a stored P01: refused, naming it
        gone = db.withdrawal(code) if rows is None else None
        codes = db.participant_codes(limit=11)
    except StorageError as exc:
        raise AnalysisError(str(exc)) from None
    finally:
        db.close()
    if gone is not None:
        raise AnalysisError(f"--participant {code}: withdrew on {gone.withdrawn_at[:10]} and their data were erased "
                            f"from {path}; nothing of theirs is stored")
    if rows is None:
        listed = ", ".join(codes[:10]) + (", …" if len(codes) > 10 else "")
        raise AnalysisError(f"--participant {code}: no such participant in {path} (participants: {listed or 'none'})")
    parts = [samples_frame(path, sid) for sid in rows.session_ids]
    samples = (pd.concat(parts, ignore_index=True) if parts else pd.DataFrame())
    damage = [line for p in parts for line in p.attrs.get("damage", [])]
    poses, log = _recording_extras(path, rows.session_ids)
    tables: dict[str, pd.DataFrame] = {
        "participant": _frame(rows, "participants"),
        "sessions": _frame(rows, "sessions", tuple(_SESSION_JSON)),
        "stored_trials": _frame(rows, "trials"),
        "trials": _analysed(path, code, options or MetricOptions()),
        "events": _frame(rows, "events"),
        **({"covariates": _frame(rows, "covariates")} if "covariates" in rows.tables else {}),
        **({"notes": _frame(rows, "notes")} if "notes" in rows.tables else {}),
        **({"answers": _frame(rows, "questionnaire_answers")} if "questionnaire_answers" in rows.tables else {}),
        "samples": samples,
        "poses": poses,
        "recording_log": log,
        "recordings": _frame(rows, "recordings", tuple(_RECORDING_JSON)),
        "blocks": _frame(rows, "session_blocks"),
        "chunks": _frame(rows, "session_chunks"),
        **_other_arms(path, rows),
        **{name: _frame(rows, name) for name in ("lsl_runs", "lsl_streams", "lsl_samples") if name in rows.tables},
        "leases": _frame(rows, "leases"),
    }
    return ParticipantExport(code, tables, _settings(rows, path), damage)


#: column -> (description, unit, type) of the labelled 1 kHz records (analysis.reading.samples, one definition)
_SAMPLE_COLUMNS = {name: (text, unit, kind) for name, kind, unit, text in SAMPLES_COLUMNS}


def _describe(file: str, column: str) -> tuple[str, str, str]:
    """(description, unit, type) of an exported column: ours, else the report's codebook entry for the name."""
    file = Path(file).stem + ".csv"  # a Parquet table is described as its CSV twin
    if (file, column) in _FILE_DESCRIBED:
        return _FILE_DESCRIBED[(file, column)]
    if file in ("samples.csv", "arm_samples.csv") and column in _SAMPLE_COLUMNS:  # labelled as `export samples` says
        return _SAMPLE_COLUMNS[column]
    c = (codebook.lookup(file, column) if file == "trials.csv" else None)
    if c is not None:
        return c.description, c.unit, c.type
    if column in _DESCRIBED:
        return _DESCRIBED[column]
    for f in ("trials.csv", "loop_health.csv", "sessions.csv"):
        c = codebook.lookup(f, codebook.exported_name(column))
        if c is not None:
            return c.description, c.unit, c.type
    return "", "", ""


def export_codebook(columns: dict[str, list[str]]) -> pd.DataFrame:
    """codebook.csv of an export: one row per (file, column), itself included."""
    columns = {**columns, "codebook.csv": ["file", "column", "type", "unit", "description"]}
    rows = []
    for file, names in columns.items():
        for name in names:
            desc, unit, kind = (_describe(file, name) if file != "codebook.csv" else
                                codebook.codebook_frame({"codebook.csv": [name]}).iloc[0][["description", "unit",
                                                                                            "type"]].tolist())
            rows.append({"file": file, "column": name, "type": kind, "unit": unit, "description": desc})
    return pd.DataFrame(rows, columns=["file", "column", "type", "unit", "description"])


def write_participant_export(export: ParticipantExport, out_dir: str | os.PathLike[str], *, fmt: str = "csv",
                             inputs: tuple[str, ...] = (), force: bool = False) -> list[str]:
    """Write ``export`` into ``out_dir`` by the output policy (:func:`foundation.outdir.write_output_folder`).

    Returns the files written.  Raises :class:`foundation.outdir.OutputError` (one line) when the folder must not
    be written or writing failed.
    """
    from foundation.outdir import write_output_folder

    suffix = ".parquet" if fmt == "parquet" else ".csv"

    def fill(tmp: Path) -> None:
        columns = {}
        for stem, frame in export.tables.items():
            name = stem + suffix
            if fmt == "parquet":
                frame.to_parquet(tmp / name, index=False)
            else:
                frame.to_csv(tmp / name, index=False)  # floats as repr: they read back exactly
            columns[name] = list(frame.columns)
        export_codebook(columns).to_csv(tmp / "codebook.csv", index=False)
        (tmp / "sessions.json").write_text(json.dumps(export.settings, indent=1, default=str), encoding="utf-8")

    need = sum(int(f.shape[0] * max(1, f.shape[1])) for f in export.tables.values()) * (6 if fmt == "csv" else 2)
    return write_output_folder(out_dir, fill, command="export participant", marker=PARTICIPANT_MARKER,
                               inputs=inputs, force=force, need_bytes=need)

