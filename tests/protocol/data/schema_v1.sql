-- haptic-study database schema, version 1 (PRAGMA user_version = 1).
-- The application applies this file to an empty database; a database whose
-- user_version is newer than the software's is refused.  Rows are insert-only
-- except that a session's end columns are filled once.
--
-- Conventions: snake_case, units in column names; times on the session clock are
-- seconds since the session started (*_at_s); wall-clock stamps are ISO 8601 UTC
-- text (*_at).  A trial's samples are keyed by trial_id = session_id * 1000000
-- + trial_index, allocated when the trial starts, so samples can be committed
-- (every ≤ 100 ms) before the trial's summary row exists (committed atomically
-- when the trial ends).

CREATE TABLE IF NOT EXISTS participants (
    participant_id INTEGER PRIMARY KEY,
    code           TEXT NOT NULL UNIQUE,        -- pseudonymous code only, no personal data
    created_at     TEXT NOT NULL
);

CREATE TABLE IF NOT EXISTS sessions (
    session_id         INTEGER PRIMARY KEY,
    participant_id     INTEGER NOT NULL REFERENCES participants(participant_id),
    kind               TEXT NOT NULL CHECK (kind IN ('training', 'experiment')),
    seed               INTEGER NOT NULL,
    participant_number INTEGER NOT NULL,        -- position in the study (counterbalancing)
    protocol_json      TEXT NOT NULL,           -- the validated protocol, as run
    schedule_json      TEXT NOT NULL,           -- the whole trial order, stored before trial 1
    status             TEXT NOT NULL CHECK (status IN ('running', 'completed', 'aborted')),
    started_at         TEXT NOT NULL,
    ended_at           TEXT,
    end_reason         TEXT,
    software_version   TEXT NOT NULL,
    rig                TEXT NOT NULL,           -- 'sim' or 'real'
    config_json        TEXT NOT NULL,           -- hardware / simulation and pipeline configuration
    calibration_json   TEXT                     -- payload/bias calibration used
);

CREATE TABLE IF NOT EXISTS trials (
    trial_id        INTEGER PRIMARY KEY,        -- session_id * 1000000 + trial_index
    session_id      INTEGER NOT NULL REFERENCES sessions(session_id),
    trial_index     INTEGER NOT NULL,
    target_label    TEXT NOT NULL,              -- 'GENTLE' / 'FIRM' in the paper's protocol
    target_force_n  REAL NOT NULL,
    haptic_mode     TEXT NOT NULL CHECK (haptic_mode IN ('on', 'off')),
    outcome         TEXT NOT NULL CHECK (outcome IN ('success', 'timeout', 'aborted')),
    started_at_s    REAL NOT NULL,              -- cue, session clock
    ended_at_s      REAL NOT NULL,              -- trial end, session clock
    tct_s           REAL,                       -- NULL unless success
    rmse_n          REAL,
    max_ae_n        REAL,
    time_in_band_s  REAL,
    peak_force_n    REAL,
    n_samples       INTEGER,
    abort_reason    TEXT,
    repeat_of       INTEGER,                    -- trial_index of the aborted trial this one re-runs
    UNIQUE (session_id, trial_index),
    CHECK (tct_s IS NULL OR outcome = 'success')
);

CREATE TABLE IF NOT EXISTS samples (
    trial_id  INTEGER NOT NULL,                 -- see trials.trial_id
    t_s       REAL NOT NULL,                    -- since the trial's cue
    force_n   REAL,                             -- the task force: |filtered compensated force|
    raw_fx    REAL, raw_fy REAL, raw_fz REAL,
    raw_tx    REAL, raw_ty REAL, raw_tz REAL,
    comp_fx   REAL, comp_fy REAL, comp_fz REAL,
    render_fx REAL, render_fy REAL, render_fz REAL   -- what was sent to the haptic device
);
CREATE INDEX IF NOT EXISTS samples_by_trial ON samples (trial_id, t_s);

CREATE TABLE IF NOT EXISTS events (
    session_id INTEGER NOT NULL REFERENCES sessions(session_id),
    t_s        REAL NOT NULL,                   -- session clock
    kind       TEXT NOT NULL,
    detail     TEXT
);
CREATE INDEX IF NOT EXISTS events_by_session ON events (session_id, t_s);
