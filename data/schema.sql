-- haptic-study database schema, version 4 (PRAGMA user_version = 4).
-- The application applies this file to an empty database; a database whose
-- user_version is newer than the software's is refused; a version-1, -2 or -3
-- database is read as it is, and upgraded in place (after a
-- backup copy is written beside it) only by a command that writes to it
-- (protocol/storage.py).  Version 3 records whole sessions at full rate in
-- compressed blocks (recordings, session_blocks; protocol/recording.py);
-- the samples table holds what versions 1 and 2 recorded (trial windows).
-- Rows are insert-only except that a session's end columns are filled once,
-- a session's schedule is rewritten when an aborted trial is re-queued, the
-- leases table holds who writes to what right now, and a participant who
-- withdraws has every row of theirs removed (haptic-study withdraw; the
-- withdrawals table keeps the record of it).
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

-- version 4: which code ran each session: software_commit, the git commit of the checkout, and software_dirty, 1 if
-- it had uncommitted changes (both NULL where not known, e.g. installed from a wheel without a commit).
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
    calibration_json   TEXT,                    -- payload/bias calibration used
    software_commit    TEXT,                    -- version 4, see above
    software_dirty     INTEGER CHECK (software_dirty IS NULL OR software_dirty IN (0, 1))
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
    -- version 2: why an aborted trial was aborted, and how the 1 kHz loop ran during the trial
    abort_cause     TEXT CHECK (abort_cause IS NULL OR abort_cause IN
                                ('experimenter', 'fault', 'feedback', 'gap', 'interrupted', 'participant_screen')),
    period_p50_ms     REAL,                     -- loop tick period over the trial's samples
    period_p99_ms     REAL,
    period_max_ms     REAL,
    periods_over_2ms  INTEGER,                  -- count of ticks whose period exceeded 2 ms
    sensor_age_max_ms REAL,                     -- oldest F/T sample the loop used (watchdog limit 5 ms)
    pose_age_max_ms   REAL,                     -- oldest robot pose the loop used (watchdog limit 50 ms)
    latency_p50_ms    REAL,                     -- F/T sample arrival -> force command sent
    latency_max_ms    REAL,
    -- version 3: where the trial's records are in the session's recording (NULL: in samples, or none)
    segment     INTEGER,                        -- recordings.segment
    first_tick  INTEGER,                        -- the loop ticks of its first (the cue) and last record
    last_tick   INTEGER,
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
-- unique: one trial never holds two samples of one time (a second writer would be refused here too)
CREATE UNIQUE INDEX IF NOT EXISTS samples_by_trial ON samples (trial_id, t_s);

CREATE TABLE IF NOT EXISTS events (
    session_id INTEGER NOT NULL REFERENCES sessions(session_id),
    t_s        REAL NOT NULL,                   -- session clock
    kind       TEXT NOT NULL,
    detail     TEXT
);
CREATE INDEX IF NOT EXISTS events_by_session ON events (session_id, t_s);

-- version 2: one writer per session.  A row says which process writes to a
-- scope ('study': a headless `run` over the whole database; 'session N': one
-- session).  A lease whose process is gone (same host: the pid no longer runs
-- the process that took it; another host: no heartbeat for 30 s) is taken over.
CREATE TABLE IF NOT EXISTS leases (
    scope         TEXT PRIMARY KEY,
    owner         TEXT NOT NULL,                -- random token of the command holding it
    pid           INTEGER NOT NULL,
    host          TEXT NOT NULL,
    process_start TEXT NOT NULL,                -- boot id and start time of pid (tells a reused pid apart)
    command       TEXT NOT NULL,                -- what holds it, for a refusal message
    acquired_at   TEXT NOT NULL,
    heartbeat_at  TEXT NOT NULL
);

-- version 3: whole sessions at full rate.  A run of a session (its first, then one per resume) is a segment,
-- with the haptic framework's state at its first record (replay starts from it); its records are cut into
-- blocks of about one second, each column one compressed array (protocol/recording.py).
CREATE TABLE IF NOT EXISTS recordings (
    session_id    INTEGER NOT NULL REFERENCES sessions(session_id),
    segment       INTEGER NOT NULL,
    started_at_s  REAL NOT NULL,                -- session clock of its first record
    t0_ns         INTEGER NOT NULL,             -- loop time of that record: session time = started_at_s + (t_ns - t0_ns) / 1e9
    snapshot_json TEXT NOT NULL,                -- the framework's state before its first record, and the loop's
    scales_json   TEXT NOT NULL,                -- counts per unit of the raw wrench columns (the codec's hint)
    -- the run's blocks written whole so far, updated with each (a deleted last block is missing); not NULL: every
    -- block's and chunk's crc32 covers its place (arm, session, run, block, chunk, ticks, records) then its data
    -- (protocol/recording/integrity.py place_crc32).  NULL: a run recorded before the count (crc32 of data only);
    -- a writer adds the column to an older file
    n_blocks      INTEGER,
    PRIMARY KEY (session_id, segment)
);

CREATE TABLE IF NOT EXISTS session_blocks (
    session_id  INTEGER NOT NULL,
    segment     INTEGER NOT NULL,
    block       INTEGER NOT NULL,               -- 0, 1, ... within the segment
    first_tick  INTEGER NOT NULL,               -- loop ticks of its first and last record
    last_tick   INTEGER NOT NULL,
    n_records   INTEGER NOT NULL,
    t_first_s   REAL NOT NULL,                  -- session clock of its first and last record
    t_last_s    REAL NOT NULL,
    data        BLOB NOT NULL,                  -- the records' columns, the poses and the replay log
    crc32       INTEGER,                        -- version 4: zlib.crc32 of data (NULL: written before version 4), of its
                                                -- place then its data in a run that counts its blocks (n_blocks)
    PRIMARY KEY (session_id, segment, block),
    FOREIGN KEY (session_id, segment) REFERENCES recordings (session_id, segment)
);

-- Version 4: what the open block of a segment being recorded gained at each commit (the records' own bytes,
-- protocol/recording/codec.py); replaced by its session_blocks row, in the same transaction, when the block fills
-- or the segment ends.  Rows left here are a killed run's last block; readers join them.
CREATE TABLE IF NOT EXISTS session_chunks (
    session_id  INTEGER NOT NULL,
    segment     INTEGER NOT NULL,
    block       INTEGER NOT NULL,               -- the open block they belong to
    chunk       INTEGER NOT NULL,               -- 0, 1, ... within the block, in the order written
    first_tick  INTEGER NOT NULL,
    last_tick   INTEGER NOT NULL,
    n_records   INTEGER NOT NULL,
    t_first_s   REAL NOT NULL,
    t_last_s    REAL NOT NULL,
    data        BLOB NOT NULL,
    crc32       INTEGER NOT NULL,               -- zlib.crc32 of data
    PRIMARY KEY (session_id, segment, block, chunk),
    FOREIGN KEY (session_id, segment) REFERENCES recordings (session_id, segment)
);

-- Version 4, a rig of several arms: the other arms' recordings (the task arm's are recordings, session_blocks and
-- session_chunks, as on a one-arm rig).  The same columns as those three tables, with the arm's name
-- (sessions.config_json lists the arms); the same segment numbers as the session's runs.
CREATE TABLE IF NOT EXISTS arm_recordings (
    session_id    INTEGER NOT NULL REFERENCES sessions(session_id),
    arm           TEXT NOT NULL,
    segment       INTEGER NOT NULL,
    started_at_s  REAL NOT NULL,
    t0_ns         INTEGER NOT NULL,
    snapshot_json TEXT NOT NULL,
    scales_json   TEXT NOT NULL,
    n_blocks      INTEGER,                      -- as recordings.n_blocks
    PRIMARY KEY (session_id, arm, segment)
);
CREATE TABLE IF NOT EXISTS arm_blocks (
    session_id  INTEGER NOT NULL,
    arm         TEXT NOT NULL,
    segment     INTEGER NOT NULL,
    block       INTEGER NOT NULL,
    first_tick  INTEGER NOT NULL,
    last_tick   INTEGER NOT NULL,
    n_records   INTEGER NOT NULL,
    t_first_s   REAL NOT NULL,
    t_last_s    REAL NOT NULL,
    data        BLOB NOT NULL,
    crc32       INTEGER,
    PRIMARY KEY (session_id, arm, segment, block),
    FOREIGN KEY (session_id, arm, segment) REFERENCES arm_recordings (session_id, arm, segment)
);
CREATE TABLE IF NOT EXISTS arm_chunks (
    session_id  INTEGER NOT NULL,
    arm         TEXT NOT NULL,
    segment     INTEGER NOT NULL,
    block       INTEGER NOT NULL,
    chunk       INTEGER NOT NULL,
    first_tick  INTEGER NOT NULL,
    last_tick   INTEGER NOT NULL,
    n_records   INTEGER NOT NULL,
    t_first_s   REAL NOT NULL,
    t_last_s    REAL NOT NULL,
    data        BLOB NOT NULL,
    crc32       INTEGER NOT NULL,
    PRIMARY KEY (session_id, arm, segment, block, chunk),
    FOREIGN KEY (session_id, arm, segment) REFERENCES arm_recordings (session_id, arm, segment)
);

-- version 4: a participant who withdrew (haptic-study withdraw).  Every row of theirs was removed and the file
-- rewritten; this row keeps only the pseudonymous code, when, the reason given and how many rows of each kind were
-- removed -- no measurement.  A withdrawn code is never given a session again.
CREATE TABLE IF NOT EXISTS withdrawals (
    code             TEXT PRIMARY KEY,          -- the participant's pseudonymous code
    withdrawn_at     TEXT NOT NULL,
    reason           TEXT NOT NULL,
    removed_sessions INTEGER NOT NULL,          -- rows removed: sessions, trials, events
    removed_trials   INTEGER NOT NULL,
    removed_events   INTEGER NOT NULL,
    removed_blocks   INTEGER NOT NULL,          -- recorded blocks, and the 1 kHz records they held
    removed_records  INTEGER NOT NULL,
    removed_samples  INTEGER NOT NULL,          -- samples rows (what versions 1 and 2 recorded)
    rewritten        INTEGER,                   -- 1 once the file's rewrite finished, 0 until then (withdraw again
                                                -- finishes it; check says so); NULL: recorded before this column
    removed_lsl_streams INTEGER,                -- external LSL streams recorded with their sessions (lsl_streams
    removed_lsl_chunks  INTEGER                 -- rows) and their samples' chunks (lsl_chunks rows); NULL: recorded
                                                -- before these columns
);

-- Version 4, added later (issue 44; a writer adds these tables to a file made before them).
-- What a protocol's [[covariates]] collected about a participant (protocol/study/covariates.py), given when they were
-- registered and stored with their first session, never changed; pseudonymous values only (a group, a number of
-- years, an age band), removed with the participant when they withdraw.
CREATE TABLE IF NOT EXISTS covariates (
    participant_id INTEGER NOT NULL REFERENCES participants(participant_id),
    name           TEXT NOT NULL,               -- the protocol's covariates[].name
    kind           TEXT NOT NULL CHECK (kind IN ('category', 'integer', 'float')),
    value          TEXT NOT NULL,               -- a category's level, or the number as written (int / float text)
    PRIMARY KEY (participant_id, name)
);

-- The experimenter's notes on a session or one of its trials: written during the session (t_s on the session clock)
-- or added afterwards (haptic-study note: t_s NULL).  Appended only, never changed.
CREATE TABLE IF NOT EXISTS notes (
    session_id  INTEGER NOT NULL REFERENCES sessions(session_id),
    t_s         REAL,                           -- session clock when written; NULL: added after the session
    trial_index INTEGER,                        -- the trial it is about (trials.trial_index); NULL: the session
    text        TEXT NOT NULL,
    deviation   INTEGER NOT NULL CHECK (deviation IN (0, 1)),  -- 1: marked a deviation (the report lists it)
    written_at  TEXT NOT NULL                   -- wall clock, ISO 8601 UTC
);

-- A questionnaire's answers (protocol/study/questionnaires.py), given on the participant screen (or by the simulated
-- participant's rule) between two trials, stored in one transaction.
CREATE TABLE IF NOT EXISTS questionnaire_answers (
    session_id    INTEGER NOT NULL REFERENCES sessions(session_id),
    questionnaire TEXT NOT NULL,                -- the protocol's questionnaires[].name
    block         TEXT NOT NULL,                -- the haptic mode of the block it followed ('on', 'off'), or 'session'
    item          TEXT NOT NULL,                -- a NASA-TLX subscale or pair ('mental|physical'), a Likert item's id
    rating        REAL,                         -- a rating: NASA-TLX 0-100 in steps of 5, a Likert item on its scale
    choice        TEXT,                         -- a NASA-TLX pair: the subscale chosen
    answered_at_s REAL NOT NULL,                -- session clock
    CHECK ((rating IS NULL) != (choice IS NULL)),
    PRIMARY KEY (session_id, questionnaire, block, item)
);
