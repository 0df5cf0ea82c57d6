"""The rules of a study that span its sessions: one seed per study, training before the experiment.

One definition, used by everyone who opens a session:

* :func:`protocol.runner.session_setup.open_new_session` enforces them when a session is stored (the GUI's study
  engine and the headless runner of ``haptic-study run`` both open sessions through it);
* ``haptic-study run`` checks them on a read-only look before it writes (:mod:`study_app.headless.plan`);
* the GUI's setup form checks the same functions against the sessions the engine listed, so it can say why
  before Start, propose the next step and show the seed read-only.

**One seed per study.**  A study database's seed is the seed of its first session; every later session
must use it (the schedules, the simulated rigs and participants derive from it), so a study stays
reproducible.  A different seed is refused with one line naming the stored one.

**Training before the experiment.**  When the protocol says so (``[training] required``, which applies
while ``[training] enabled``), an experiment session needs a *completed* training session of the same
participant.  In a study of several parts (:mod:`protocol.study.parts`) an experiment part needs the training parts
before it in the participant's order completed (none before it: nothing to require).  An experimenter may start
one anyway only with a typed reason (:func:`check_new_session`'s ``training_override``); the reason is stored as
a :data:`DEVIATION_EVENT` event of that session, whose detail begins with :data:`TRAINING_SKIPPED`, so the report
can list it among the study's deviations.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.force.config import FrameworkConfig
from pipeline.force.pipeline_settings import describe, non_default_settings, settings_of, stored_settings
from protocol.storage import SessionInfo, StorageError, StudyDatabase, StudyReader
from protocol.study.config import ProtocolConfig
from protocol.study.questionnaires import QUESTIONNAIRE_SKIPPED_EVENT

__all__ = [
    "CALIBRATION_OVERRIDE_EVENT", "DEVIATION_EVENT", "DEVIATION_KINDS", "FAULT_REHEARSAL_EVENT",
    "QUESTIONNAIRE_SKIPPED_EVENT", "TRAINING_SKIPPED",
    "StoredSession",
    "StudyRuleError", "check_arms", "check_new_session", "check_settings", "next_kind", "next_part", "part_states",
    "requires_training", "seed_refusal", "stored_sessions", "study_seed", "training_refusal", "training_state",
]

#: The ``events.kind`` of a deviation from the designed study an experimenter chose (and gave a reason for).
DEVIATION_EVENT = "deviation"
#: The ``events.kind`` of a real-rig session started by the experimenter's override of the calibration chain.
CALIBRATION_OVERRIDE_EVENT = "calibration_override"
#: The ``events.kind`` of a fault rehearsed on the simulated rig (``run --inject-fault``, the GUI's Rehearse a
#: fault): planned, and what it did.  A rehearsed fault aborts its trial like a real one; this says it was no
#: device failure.
FAULT_REHEARSAL_EVENT = "fault_rehearsal"
#: Every ``events.kind`` that records a deviation from the designed study (the report lists them all).
DEVIATION_KINDS = (DEVIATION_EVENT, CALIBRATION_OVERRIDE_EVENT, FAULT_REHEARSAL_EVENT, QUESTIONNAIRE_SKIPPED_EVENT)
#: How the detail of the deviation "experiment without a completed training session" begins.
TRAINING_SKIPPED = "training skipped"


class StudyRuleError(StorageError):
    """A session the study's rules refuse (another seed; an experiment without training); one line, nothing stored."""


@dataclass(frozen=True, slots=True)
class StoredSession:
    """What the rules need of a stored session."""

    session_id: int
    code: str
    kind: str
    status: str
    seed: int
    #: The study part it is ("" in a study of one task: :attr:`protocol.storage.SessionInfo.part`).
    part: str = ""
    #: The visit of a schedule it belongs to ("" in a study without visits: :attr:`protocol.storage.SessionInfo.visit`).
    visit: str = ""
    #: When it started (ISO 8601, UTC; "" where not known): a schedule's days count from the first one.
    started_at: str = ""

    @classmethod
    def of(cls, d: dict[str, Any]) -> StoredSession:
        """From a dict with these keys (:func:`study_app.engine.session_list.list_sessions`' rows; ``part``,
        ``visit`` and ``started_at`` optional)."""
        return cls(int(d["session_id"]), str(d["code"]), str(d["kind"]), str(d["status"]), int(d["seed"]),
                   str(d.get("part", "")), str(d.get("visit", "")), str(d.get("started_at") or ""))


def stored_sessions(db: StudyDatabase) -> list[StoredSession]:
    """Every session of the database, oldest first."""
    return [StoredSession(int(s.session_id), str(s.code), str(s.kind), str(s.status), int(s.seed), s.part, s.visit,
                          str(s.started_at))
            for s in StudyReader.over(db).sessions()]


def study_seed(sessions: Iterable[StoredSession]) -> StoredSession | None:
    """The session that fixed the study's seed (the first stored), or None for an empty study."""
    return min(sessions, key=lambda s: s.session_id, default=None)


def seed_refusal(sessions: Iterable[StoredSession], seed: int) -> str:
    """Why ``seed`` may not start a session of this study ("" when it may)."""
    first = study_seed(sessions)
    if first is None or first.seed == seed:
        return ""
    return (f"seed = {seed}: this study's seed is {first.seed}, fixed by its first session (session "
            f"{first.session_id}, {first.code}); every session of a study uses it, so its schedules can be "
            f"reproduced: use seed {first.seed}, or a new database for a new study")


def requires_training(protocol: ProtocolConfig) -> bool:
    """Whether the protocol requires a completed training session before an experiment session (a part of a study:
    only when training parts come before it in the participant's order)."""
    needs = protocol.training.enabled and protocol.training.required
    return needs and (protocol.part is None or bool(protocol.part.trained_by))


def training_state(sessions: Iterable[StoredSession], code: str,
                   part: str | None = None) -> tuple[str, StoredSession | None]:
    """A participant's training (of the study part ``part``, when given): ``completed``, ``interrupted``
    (resumable), ``ended`` (ended early) or ``none``, with the session that says so."""
    mine = [s for s in sessions if s.code == code and s.kind == "training" and (part is None or s.part == part)]
    for state, match in (("completed", "completed"), ("interrupted", "running")):
        found = [s for s in mine if s.status == match]
        if found:
            return state, found[-1]
    return ("ended", mine[-1]) if mine else ("none", None)


def training_refusal(sessions: Sequence[StoredSession], code: str, protocol: ProtocolConfig) -> str:
    """Why an experiment session of ``code`` may not start for want of training ("" when it may); a part of a
    study: each training part before it in the participant's order (:attr:`PartPlace.trained_by`)."""
    if not requires_training(protocol):
        return ""
    for part in protocol.part.trained_by if protocol.part is not None else (None,):
        why = _training_missing(sessions, code, part)
        if why:
            return why
    return ""


def _training_missing(sessions: Sequence[StoredSession], code: str, part: str | None) -> str:
    """Why ``code``'s training (of ``part``) is not there to start an experiment on ("" when it is completed)."""
    state, s = training_state(sessions, code, part)
    if state == "completed":
        return ""
    rule = "the protocol requires a completed one before the experiment (training.required)"
    what = "training" if part is None else f"training part {part!r}"
    if state == "interrupted" and s is not None:
        return f"{code}'s {what} (session {s.session_id}) was interrupted; {rule}: resume it first"
    if state == "ended" and s is not None:
        return f"{code}'s {what} (session {s.session_id}) ended {s.status}, not completed; {rule}"
    return f"{code} has no {what} session; {rule}"


def next_kind(sessions: Sequence[StoredSession], code: str, protocol: ProtocolConfig) -> str:
    """The session a participant does next: ``training`` (when the protocol has one and it is not done),
    then ``experiment``."""
    if not protocol.training.enabled:
        return "experiment"
    state, _ = training_state(sessions, code)
    began = any(s.code == code and s.kind == "experiment" for s in sessions)
    return "training" if state == "interrupted" or (state == "none" and not began) else "experiment"


def part_states(sessions: Sequence[StoredSession], code: str,
                parts: Sequence[ProtocolConfig]) -> list[tuple[ProtocolConfig, str, StoredSession | None]]:
    """Where a participant is in their plan (``parts``: :meth:`ProtocolConfig.plan_for`, in their order): each part
    with its state -- ``completed``, ``interrupted`` (resumable), ``ended`` (ended early: not run again) or ``to do``
    -- and its session (the newest of that part, in its visit where the study has visits)."""
    out: list[tuple[ProtocolConfig, str, StoredSession | None]] = []
    for p in parts:
        assert p.part is not None
        visit = p.part.visit.name if p.part.visit is not None else ""
        mine = [s for s in sessions if s.code == code and s.part == p.part.name and s.kind == p.part.session
                and s.visit == visit]
        s = mine[-1] if mine else None
        state = "to do" if s is None else {"completed": "completed", "running": "interrupted"}.get(s.status, "ended")
        out.append((p, state, s))
    return out


def next_part(sessions: Sequence[StoredSession], code: str,
              parts: Sequence[ProtocolConfig]) -> tuple[ProtocolConfig, StoredSession | None] | None:
    """The part a participant does next (the first in their order not completed or ended), with its interrupted
    session to resume (None: a new session); None when the whole plan is done."""
    for p, state, s in part_states(sessions, code, parts):
        if state in ("interrupted", "to do"):
            return p, s
    return None


def check_new_session(
    sessions: Sequence[StoredSession], *, code: str, kind: str, seed: int, protocol: ProtocolConfig,
    training_override: str = "",
) -> str:
    """Apply the study's rules to a session about to be stored.

    Returns the detail of the deviation event to store with it ("" when there is none): an experiment
    without a completed training session, started with the experimenter's ``training_override`` reason.

    Raises
    ------
    StudyRuleError
        Another seed than the study's; an experiment without a completed training session and no reason
        given.  One line; nothing is stored.
    """
    why = seed_refusal(sessions, seed)
    if why:
        raise StudyRuleError(why)
    if kind != "experiment":
        return ""
    why = training_refusal(sessions, code, protocol)
    if not why:
        return ""
    reason = " ".join(training_override.split())
    if not reason:
        raise StudyRuleError(why)
    return f"{TRAINING_SKIPPED}: {code}'s experiment started without a completed training session ({why}). " \
           f"Reason given: {reason}"


def check_arms(sessions: Sequence[SessionInfo], db_path: str, arms: Sequence[str]) -> None:
    """One rig per study: refuse (:class:`StorageError`) arms other than those the stored sessions ran on.

    ``arms`` is the rig's arms, the task arm first, as :attr:`SessionInfo.arms` reads them: a study started on two
    simulated arms and continued on one would give its next participants another rig (and a one-arm study, arms it
    never had), although continuing promises the sessions an uninterrupted study would have had.
    """
    for info in sessions:
        if tuple(info.arms) != tuple(arms):
            raise StorageError(
                f"{db_path}: {info.code}'s {info.kind} session {info.session_id} ran on the arms "
                f"{','.join(info.arms)} (the task arm first); this command's: {','.join(arms)}; one study runs on one "
                "rig, nothing was changed (give the --sim-arms the study was started with, or use a new database)"
            )


def check_settings(sessions: Sequence[SessionInfo], db_path: str, framework: FrameworkConfig | None) -> None:
    """One pipeline per study: refuse (:class:`StorageError`) settings other than those a stored session ran with.

    The settings are the ones ``run --set`` chooses (:mod:`pipeline.force.pipeline_settings`), read from each
    session's ``config_json``; a study whose sessions ran with different filters or scalings compares nothing.
    """
    chosen = settings_of(framework or FrameworkConfig())
    for info in sessions:
        try:
            record = json.loads(info.config_json).get("framework")
        except (TypeError, ValueError, AttributeError):
            record = None
        have = stored_settings(record)
        if have != chosen:
            raise StorageError(
                f"{db_path}: {info.code}'s {info.kind} session {info.session_id} ran with the pipeline settings: "
                f"{describe(non_default_settings(have))}; this command's: {describe(non_default_settings(chosen))}; "
                "one study runs one pipeline, nothing was changed (give the --set the study was started with, or use "
                "a new database)"
            )
