"""The messages of a session: start, resume, pause, abort (GUI → engine); what the session does (engine → GUI).

Run by :class:`study_app.engine.sessions.EngineSessions`; shown by :mod:`study_app.models.session` and the setup
form.  Times called ``t_s`` are sample times of the loop records (see :mod:`study_app.engine.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from protocol.study.questionnaires import Questionnaire
from protocol.study.records import TrialRecord
from protocol.tasks.base import Task

__all__ = [
    "AbortSession",
    "AbortTrial",
    "AnswerQuestionnaire",
    "AnswerTrial",
    "ListSessions",
    "Note",
    "NoteStored",
    "ParticipantScreenState",
    "Pause",
    "PhaseEntered",
    "QuestionnaireAnswered",
    "QuestionnaireShown",
    "Resume",
    "ResumeSession",
    "ScoreCardShown",
    "SessionEnded",
    "SessionStarted",
    "SessionsListed",
    "SkipQuestionnaire",
    "StartChecking",
    "StartSession",
    "TrialEnded",
    "TrialStarted",
]


# -- commands (GUI → engine) --------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class StartSession:
    """Create a session in the database (schedule and calibration stored first) and run it.

    On the real rig a session starts only with the calibration chain on record for the mounted tool and
    the compensated force at rest below 0.1 N; ``override_reason`` (non-empty) starts it anyway, and the
    reason is stored with the session.  The study's rules (:mod:`protocol.runner.study_rules`: one seed per
    study, training before the experiment) are the engine's to enforce; ``training_override`` (non-empty)
    starts an experiment without the completed training the protocol requires, and is stored as a
    ``deviation`` event.
    """

    db_path: str
    code: str
    kind: str  # "training" | "experiment"
    protocol_path: str | None
    seed: int
    participant_number: int
    override_reason: str = ""
    training_override: str = ""
    #: Who the participant is, by covariate name (the protocol's ``[[covariates]]``; text as the form has it):
    #: stored with a participant this session registers (:mod:`protocol.study.covariates`).
    covariates: dict[str, str] = field(default_factory=dict)
    #: The part of a study of several parts to start (:mod:`protocol.study.parts`): its protocol in the
    #: participant's order is the session's, its kind ``kind``; "" in a study of one task.
    part: str = ""
    #: The visit of a schedule (:mod:`protocol.study.visits`) whose part ``part`` starts; "" without ``[[visits]]``.
    visit: str = ""
    #: Events ``(kind, detail)`` stored with a visit's new session at session time 0, as ``run --visit`` stores them
    #: (:mod:`study_app.models.schedule`): the study day it is held on, and the deviation with the experimenter's
    #: reason when it is out of order or outside its window.  The engine refuses a visit the schedule's rule
    #: refuses (:func:`protocol.runner.visit_schedule.visit_refusal`) without that deviation.
    events: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True, slots=True)
class ResumeSession:
    """Continue an interrupted session at its first unfinished trial (real rig: the calibration gate, as
    StartSession)."""

    db_path: str
    session_id: int
    override_reason: str = ""


@dataclass(frozen=True, slots=True)
class ListSessions:
    """List the interrupted (resumable) sessions of a database."""

    db_path: str


@dataclass(frozen=True, slots=True)
class Pause:
    """Hold before the next trial."""


@dataclass(frozen=True, slots=True)
class Resume:
    """Continue after a pause."""


@dataclass(frozen=True, slots=True)
class AbortTrial:
    """Abort the running trial (stored as aborted, re-queued).

    ``trial_index`` binds the command to the trial the experimenter confirmed: the engine refuses it
    when that trial is no longer running (a late "Yes" never aborts the next trial).
    """

    reason: str = "aborted by the experimenter"
    trial_index: int | None = None
    #: The experimenter's reason in their words ("" none given): stored as a note on the trial too.
    note: str = ""


@dataclass(frozen=True, slots=True)
class AbortSession:
    """Abort the running trial and end the session (refused if ``session_id`` is given and is not the running one)."""

    reason: str = "aborted by the experimenter"
    session_id: int | None = None


@dataclass(frozen=True, slots=True)
class Note:
    """The experimenter's note on the running session (``trial_index`` None) or one of its trials, stored on the
    session clock; ``deviation`` lists it among the report's deviations from the protocol."""

    text: str
    trial_index: int | None = None
    deviation: bool = False


@dataclass(frozen=True, slots=True)
class AnswerQuestionnaire:
    """The participant's answers to the questionnaire on their screen (item id → rating, or a pair's choice)."""

    session_id: int
    questionnaire: str
    block: str
    answers: dict[str, float | str]


@dataclass(frozen=True, slots=True)
class SkipQuestionnaire:
    """The experimenter skips the questionnaire waiting for the participant: stored as skipped, a deviation from the
    protocol with ``reason`` (the report lists it), and the next trial no longer waits."""

    session_id: int
    questionnaire: str
    block: str
    reason: str = ""


@dataclass(frozen=True, slots=True)
class AnswerTrial:
    """The participant's answer to the running trial's question (a task that asks: force discrimination's ``"1"``
    or ``"2"``), from the participant screen's keys or buttons."""

    session_id: int
    key: str


@dataclass(frozen=True, slots=True)
class ParticipantScreenState:
    """Whether the participant screen is open where the participant sees it (shown, not minimised, on a monitor).

    The GUI sends it whenever that changes.  While it is closed no session starts or resumes and no trial is
    cued; closed during a session, the running trial is aborted (cause ``participant_screen``, stored) and the
    session pauses.  ``detail`` says how it closed (``closed``, ``minimised``, ``off every monitor``).  An engine
    whose client never sent one (a script, a test) has no participant screen to check.
    """

    open: bool
    detail: str = ""


# -- events (engine → GUI) ----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class SessionsListed:
    """Resumable sessions of a database: dicts with session_id, code, kind, started_at, trials_planned (the
    designed trials), trials_done (designed trials done), trials_aborted (aborted attempts) and trials_total
    (the schedule with its re-runs).

    ``known``: every session of the database (:func:`study_app.engine.session_list.list_sessions`), for the setup
    form's checks (a code or participant number already used); ``withdrawn``: who withdrew (``code``,
    ``withdrawn_at``; :func:`study_app.engine.session_list.list_withdrawn`), whose codes are not used again.
    """

    db_path: str
    sessions: list[dict[str, Any]]
    known: list[dict[str, Any]] = field(default_factory=list)
    withdrawn: list[dict[str, str]] = field(default_factory=list)
    #: Each registered participant's covariates, by code (:func:`study_app.engine.session_list.list_covariates`).
    covariates: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class SessionStarted:
    """A session is stored and running; ``task`` is its protocol's task, which the views ask what a trial shows
    (:meth:`protocol.tasks.base.Task.screen`: the cue word, the band)."""

    session_id: int
    code: str
    kind: str
    trials_total: int
    start_position: int
    task: Task
    max_trial_s: float
    pause_s: float
    cue_s: float
    live_force_aid: bool
    schedule: list[dict[str, Any]] = field(default_factory=list)
    participant_number: int = 0
    #: A resumed session's trials stored before, in index order.
    stored_trials: list[TrialRecord] = field(default_factory=list)
    #: The session's (so the study's) seed.
    seed: int = 0
    #: A resumed session's notes stored before: (trial index or None for the session, text, a deviation).
    stored_notes: list[tuple[int | None, str, bool]] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class TrialStarted:
    """The cue of a trial (the participant screen shows its word)."""

    t_s: float
    trial_index: int
    position: int  # 1-based position in the schedule
    trials_total: int
    target_label: str
    target_force_n: float
    haptic_mode: str
    #: The trial this one re-runs (an aborted one), or None for a trial of the design.
    repeat_of: int | None = None


@dataclass(frozen=True, slots=True)
class PhaseEntered:
    """The trial machine entered ``phase`` (idle, cued, active, pause) at sample time ``t_s``."""

    t_s: float
    trial_index: int
    phase: str


@dataclass(frozen=True, slots=True)
class TrialEnded:
    """A trial ended and its record was stored; ``trials_total`` is the schedule's length now (re-runs included)."""

    t_s: float
    record: TrialRecord
    trials_total: int


@dataclass(frozen=True, slots=True)
class SessionEnded:
    """The session ended (``status``: completed or aborted; or ``interrupted`` when left resumable)."""

    session_id: int
    status: str
    reason: str
    completed: int
    aborted: int
    successes: int


@dataclass(frozen=True, slots=True)
class NoteStored:
    """A note was taken (stored at the next block of records); ``t_s`` is the sample time it was taken at."""

    t_s: float
    text: str
    trial_index: int | None
    deviation: bool


@dataclass(frozen=True, slots=True)
class ScoreCardShown:
    """Feedback to the trainee (the protocol's ``[feedback]``): a block ended, its score card is on the participant
    screen until the next cue (``lines``: a measure each, against the participant's earlier sessions)."""

    session_id: int
    block: str
    lines: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class QuestionnaireShown:
    """A questionnaire is due: the participant screen shows it, and the next cue waits for its answers."""

    session_id: int
    questionnaire: Questionnaire
    block: str


@dataclass(frozen=True, slots=True)
class QuestionnaireAnswered:
    """A questionnaire's answers were stored (the participant's, or the simulated participant's), or it was skipped
    by the experimenter (``skipped``: stored so, not answered)."""

    session_id: int
    questionnaire: str
    block: str
    skipped: bool = False


@dataclass(frozen=True, slots=True)
class StartChecking:
    """Real rig: Start was accepted by the calibration gate; the force at rest is measured for ``seconds`` first."""

    seconds: float
    message: str
