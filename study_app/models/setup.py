"""Session setup: what the experimenter enters before a session, validated field by field.

Besides each field's own rules, the form knows the database's sessions (listed
by the engine) and checks the entry against them before Start, as the runner
would after it: a code that already has a session of this kind is an error
(the database keeps one per participant); a participant number already given
to someone else is a warning (the same number draws the same counterbalanced
schedule, which is right only when replacing a participant who dropped out).
Until the experimenter sets the number, the form suggests one: the code's own
number if it has sessions (training, then experiment), else the next free one.

The study's rules (:mod:`protocol.runner.study_rules`, the functions the engine applies
when it stores a session) are checked here too, so the form says why before
Start: a database's seed is fixed by its first session (the form takes it and
the view shows it read-only); an experiment without the completed training the
protocol requires is an error that only an override with a typed reason passes.
Until the experimenter picks the kind, the form proposes the participant's next
step: training, then the experiment.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, replace
from typing import Any

from foundation.platform_support.files import may_write
from protocol.runner.study_rules import (
    StoredSession,
    next_kind,
    requires_training,
    seed_refusal,
    study_seed,
    training_refusal,
    training_state,
)
from protocol.storage import StorageError, clash_of, near_duplicate, normalise_code, validate_code
from protocol.study.config import ProtocolConfig, ProtocolError, load_protocol
from study_app.engine import messages as m
from study_app.engine.session_list import next_participant_number
from study_app.models import Emitter
from study_app.models.covariate_form import CovariateForm
from study_app.models.plan import PlanRow, next_part_name, plan_rows, plan_words
from study_app.models.schedule import ScheduleForm, visit_events
from study_app.models.session import TrialCount

__all__ = ["KINDS", "TRAINING_OVERRIDE_HINT", "SessionSetup", "SetupModel", "article", "breakable", "with_db_suffix"]

KINDS = ("training", "experiment")
_FIELD_NAMES = {"participant_number": "participant number", "seed": "seed"}
#: What the form adds to a training refusal: the way past it, and what it costs.
TRAINING_OVERRIDE_HINT = "Run the training first, or Start without training… with a reason (stored as a deviation)"
#: The same, when the training ended early: the database keeps one training session per participant.
TRAINING_ENDED_HINT = ("A participant's training is not run twice (one session per kind): Start without training… "
                       "with a reason (stored as a deviation)")


def breakable(text: str, run: int = 16) -> str:
    """``text`` with a zero-width space after every ``run`` characters of a word longer than that (for display): a
    label wraps only between words, and a long pasted code in a message ran past the form's narrow column and
    pushed the lines above it out of view."""
    return re.sub(rf"\S{{{run}}}(?=\S)", lambda m: m.group(0) + "\u200b", text)


def with_db_suffix(path: str) -> str:
    """A new study database typed without a file type (``study``) is ``study.db``: a file no program knows what to
    open with is no study record.  A file that exists (or a folder, refused later) keeps its name."""
    text = path.strip()
    if not text or os.path.exists(text) or os.path.splitext(text)[1] or text.endswith(os.sep):
        return path
    return text + ".db"


def article(word: str) -> str:
    """``a`` or ``an`` before ``word`` (an aborted, a completed)."""
    return "an" if word[:1].lower() in "aeiou" else "a"


@dataclass(frozen=True, slots=True)
class SessionSetup:
    """The setup form's values."""

    db_path: str = ""
    code: str = ""
    participant_number: int = 1
    kind: str = "experiment"
    protocol_path: str = ""  # empty: the paper's protocol
    seed: int = 0
    #: The part to start in a study of several parts (:mod:`protocol.study.parts`); "" in a study of one task.
    part: str = ""
    #: The visit whose part starts, in a study with a schedule of visits (:mod:`protocol.study.visits`); "" without.
    visit: str = ""


@dataclass
class SetupModel:
    """The form's state and what is wrong with it.

    ``errors`` (field → message) block Start; ``warnings`` do not, but Start asks first;
    ``hint`` says what to do next (e.g. enter a code) and blocks Start while the code is empty.
    """

    values: SessionSetup = field(default_factory=SessionSetup)
    errors: dict[str, str] = field(default_factory=dict)
    warnings: dict[str, str] = field(default_factory=dict)
    hint: str = ""
    resumable: list[dict[str, object]] = field(default_factory=list)
    #: Every session of the database (:func:`study_app.engine.session_list.list_sessions`), as the engine listed them.
    known: list[dict[str, Any]] = field(default_factory=list)
    #: Who withdrew (``code``, ``withdrawn_at``): a withdrawn code is not used again.
    withdrawn: list[dict[str, str]] = field(default_factory=list)
    #: Field → the text typed into it when that text is no value the field takes (an empty or partial number):
    #: the form would otherwise start with the last value the field took, which is no longer on screen.
    entry_problems: dict[str, str] = field(default_factory=dict)
    #: The number follows the suggestion until the experimenter sets it.
    number_suggested: bool = True
    #: The kind follows the participant's next step (training, then experiment) until the experimenter picks one.
    kind_suggested: bool = True
    #: The session that fixed the database's seed (None: no session yet, the seed may still be chosen).
    seed_fixed_by: StoredSession | None = None
    #: The protocol as loaded from the form's file (None while it does not load).
    protocol: ProtocolConfig | None = None
    _protocol_key: tuple[str, float] | None = None
    #: The session running now (not a conflict with itself).
    running_session: int | None = None
    #: The session to select in the resume list when it is listed (the one an engine failure interrupted).
    preferred_resume: int | None = None
    #: What the form asks about a new participant (the protocol's covariates), and each registered participant's
    #: stored covariates by code (as the engine listed them).
    covariates: CovariateForm = field(default_factory=CovariateForm)
    registered: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: The participant's schedule of visits (:mod:`study_app.models.schedule`), and why the form's visit needs the
    #: experimenter's reason (out of order, outside its window).
    schedule: ScheduleForm = field(default_factory=ScheduleForm)
    changed: Emitter = field(default_factory=Emitter)
    resumable_changed: Emitter = field(default_factory=Emitter)

    def update(self, **kwargs: object) -> None:
        """Change fields and re-validate (codes are normalised as storage stores them: a pasted ' P07 ' is P07)."""
        if isinstance(kwargs.get("code"), str):
            kwargs["code"] = normalise_code(str(kwargs["code"]))
        if isinstance(kwargs.get("db_path"), str):
            kwargs["db_path"] = with_db_suffix(str(kwargs["db_path"]))
        if "participant_number" in kwargs:
            self.number_suggested = False
        if "kind" in kwargs or "part" in kwargs or "visit" in kwargs:
            self.kind_suggested = False
        self.values = replace(self.values, **kwargs)  # type: ignore[arg-type]  # kwargs are checked field names
        if "visit" in kwargs and "part" not in kwargs:  # a visit chosen: its first part not done yet
            self._refresh_schedule()
            self.values = replace(self.values, part=self.schedule.first_left(self.values.visit))
        if "part" in kwargs or "visit" in kwargs:
            self._kind_of_part()
        self._suggest_number()
        self._suggest_kind()
        self.validate()

    def set_number(self, number: int) -> None:
        """The experimenter set the participant number (it no longer follows the suggestion)."""
        if number != self.values.participant_number:
            self.update(participant_number=int(number))

    def _suggest_number(self) -> None:
        if not self.number_suggested:
            return
        mine = [s for s in self.known if s["code"] == self.values.code]
        n = int(mine[-1]["participant_number"]) if mine else next_participant_number(self.known)
        self.values = replace(self.values, participant_number=n)

    def _suggest_kind(self) -> None:
        protocol = self._load_protocol() if self.kind_suggested else None
        if protocol is None:
            return
        if protocol.visits:  # a schedule of visits: the participant's next (visit, part)
            self._refresh_schedule()
            v = self.values
            visit, part = self.schedule.next or (v.visit, v.part)
            if visit not in protocol.visit_names:  # no participant yet: the schedule's first visit
                visit = protocol.visit_names[0]
                part = self.schedule.first_left(visit)
            self.values = replace(v, visit=visit, part=part)
            self._kind_of_part()
            return
        if protocol.parts or self.values.part:  # a study of several parts: the participant's next part
            v = self.values
            name = next_part_name(protocol, self._stored(), v.code, v.participant_number, v.seed)
            self.values = replace(v, part=name or (v.part if v.part in protocol.part_names else ""))
            self._kind_of_part()
            return
        kind = next_kind(self._stored(), self.values.code, protocol)
        if kind != self.values.kind:
            self.values = replace(self.values, kind=kind)

    def _kind_of_part(self) -> None:
        """A part's session is of the part's kind (a training part: a training session)."""
        part = self.part_protocol()
        if part is not None and part.part is not None and part.part.session != self.values.kind:
            self.values = replace(self.values, kind=part.part.session)

    def part_protocol(self) -> ProtocolConfig | None:
        """The protocol of the form's part for this participant (its place in their order); None without one."""
        v, protocol = self.values, self.protocol
        if protocol is None or v.part not in protocol.part_names:
            return None
        try:  # in a schedule of visits: the part of the form's visit (None while the visit does not hold it)
            return protocol.part_of(v.part, max(v.participant_number, 1), max(v.seed, 0), v.visit)
        except KeyError:
            return None

    def plan(self) -> list[PlanRow]:
        """The participant's plan in a study of several parts, each part's state (:mod:`study_app.models.plan`)."""
        v = self.values
        return plan_rows(self.protocol, self._stored(), v.code, v.participant_number, v.seed)

    def _refresh_schedule(self) -> None:
        v = self.values
        self.schedule.update(self._load_protocol(), self.known, v.code, v.participant_number, v.seed, v.visit)

    def _stored(self) -> list[StoredSession]:
        return [StoredSession.of(s) for s in self.known]

    def _load_protocol(self) -> ProtocolConfig | None:
        """The form's protocol (loaded again only when its file or its time stamp changes); None if it does not load."""
        path = self.values.protocol_path.strip()
        try:
            key = (path, os.path.getmtime(path) if path else 0.0)
        except OSError:
            key = (path, -1.0)
        if key != self._protocol_key:
            self._protocol_key = key
            try:
                self.protocol = load_protocol(path or None)
            except ProtocolError:
                self.protocol = None
        return self.protocol

    def validate(self) -> dict[str, str]:
        """Check every field as the engine will, and the entry against the database; returns (and stores) the errors."""
        v = self.values
        errors: dict[str, str] = {}
        if not v.db_path.strip():
            errors["db_path"] = "study database: choose a file (it is created if missing)"
        else:
            p = os.path.abspath(v.db_path)
            parent = os.path.dirname(p)
            if os.path.isdir(p):
                errors["db_path"] = f"study database = {v.db_path!r}: is a folder, not a file"
            elif not os.path.isdir(parent):
                errors["db_path"] = f"study database = {v.db_path!r}: the folder {parent} does not exist"
            elif not may_write(p) if os.path.exists(p) else not may_write(parent, os.W_OK | os.X_OK):
                errors["db_path"] = f"study database = {v.db_path!r}: not writable"
        self.hint = ""
        if not v.code:
            self.hint = "Enter the participant's code (pseudonymous, e.g. P07) to start."
        else:
            try:
                validate_code(v.code)
            except StorageError as exc:
                errors["code"] = str(exc)
        if v.kind not in KINDS:
            errors["kind"] = f"session kind = {v.kind!r}: allowed values are training, experiment"
        self._refresh_schedule()
        self._check_part(errors)
        if v.protocol_path.strip():
            try:
                load_protocol(v.protocol_path)
            except ProtocolError as exc:
                errors["protocol_path"] = str(exc)
        self._load_protocol()
        self._ask_covariates(errors)
        if not (isinstance(v.seed, int) and v.seed >= 0):
            errors["seed"] = f"seed = {v.seed!r}: must be a whole number ≥ 0"
        if not (isinstance(v.participant_number, int) and v.participant_number >= 1):
            errors["participant_number"] = f"participant number = {v.participant_number!r}: must be a whole number ≥ 1"
        errors.update(self.entry_problems)
        warnings: dict[str, str] = {}
        self.seed_fixed_by = study_seed(self._stored())
        why = seed_refusal(self._stored(), v.seed) if "seed" not in errors else ""
        if why:
            errors["seed"] = why
        if "code" not in errors and v.code:
            self._check_against_database(errors, warnings)
        self.errors, self.warnings = errors, warnings
        self.changed.emit()
        return errors

    def _check_part(self, errors: dict[str, str]) -> None:
        """A study of several parts starts one of its parts (of the part's kind); a study of one task, none."""
        names = self.protocol.part_names if self.protocol is not None else ()
        part = self.values.part
        visits = self.protocol.visit_names if self.protocol is not None else ()
        if visits and self.values.visit not in visits:
            errors["visit"] = (f"visit = {self.values.visit!r}: this protocol's visits are {', '.join(visits)}: "
                               "choose one")
        elif visits and names and part not in self.schedule.parts_of.get(self.values.visit, names):
            errors["part"] = (f"part = {part!r}: visit {self.values.visit!r} holds the parts "
                              f"{', '.join(self.schedule.parts_of[self.values.visit])}: choose one")
        elif names and part not in names:
            errors["part"] = f"part = {part!r}: this protocol's parts are {', '.join(names)}: choose one"
        elif part and not names and self.protocol is not None:
            errors["part"] = f"part = {part!r}: this protocol has no parts (a study of one task)"

    def _ask_covariates(self, errors: dict[str, str]) -> None:
        """The protocol's covariates: asked of a participant not registered yet (their answers checked), shown for
        one who is (a participant with a session is registered, with the values stored then, perhaps none)."""
        code = self.values.code
        stored = self.registered.get(code)
        if stored is None and code and any(s["code"] == code for s in self.known):
            stored = {}
        self.covariates.set_questions(self.protocol.covariates if self.protocol is not None else (), stored)
        why = self.covariates.error() if code else ""
        if why:
            errors["covariates"] = why

    def set_entry_problem(self, name: str, text: str, message: str | None) -> None:
        """The view's field ``name`` shows ``text``, which is no value it takes (``message`` says what is allowed);
        None: its text is a value again.  Start is refused meanwhile."""
        if message is None:
            if self.entry_problems.pop(name, None) is not None:
                self.validate()
            return
        self.entry_problems[name] = f"{_FIELD_NAMES.get(name, name)} = {text!r}: {message}"
        self.validate()

    def _check_against_database(self, errors: dict[str, str], warnings: dict[str, str]) -> None:
        v = self.values
        other = near_duplicate(v.code, [str(s["code"]) for s in self.known] + [w["code"] for w in self.withdrawn])
        if other is not None:  # p01 beside P01: one participant as a person reads them (protocol.storage.codes)
            errors["code"] = clash_of(v.code, other, "this study")
            return
        gone = next((w for w in self.withdrawn if w["code"] == v.code), None)
        if gone is not None:
            errors["code"] = (f"{v.code} withdrew from the study ({gone['withdrawn_at'][:16].replace('T', ' ')} UTC) "
                              "and their data were erased; a withdrawn code is not used again: enter a new code")
            return
        same = [s for s in self.known if s["code"] == v.code and s["kind"] == v.kind and s.get("part", "") == v.part
                and s.get("visit", "") == v.visit and s["session_id"] != self.running_session]
        if same:
            s = same[-1]
            if s["status"] == "running" and s.get("writer"):
                errors["code"] = (f"{v.code}'s {v.kind} session (session {s['session_id']}) is being run right now "
                                  f"by {s['writer']} (another window or command): one writer per session")
            elif s["status"] == "running":
                errors["code"] = (f"{v.code} has an interrupted {v.kind} session (session {s['session_id']}, "
                                  f"{self.count_of(s).text()}): resume it from the list below")
            else:
                way = ("choose the experiment (Start without training… with a reason, if the training did not "
                       "complete) or enter a new code" if v.kind == "training" else "enter a new code")
                errors["code"] = (f"{v.code} already has {article(str(s['status']))} {s['status']} {v.kind} session "
                                  f"(session {s['session_id']}); the database keeps one per participant: {way}")
        elif v.kind == "experiment" and self.protocol is not None and self.running_session is None:
            why = training_refusal(self._stored(), v.code, self.part_protocol() or self.protocol)
            if why:
                ended = training_state(self._stored(), v.code)[0] == "ended"
                errors["training"] = f"{why}. {TRAINING_ENDED_HINT if ended else TRAINING_OVERRIDE_HINT}."
        others = sorted({s["code"] for s in self.known
                         if s["participant_number"] == v.participant_number and s["code"] != v.code})
        if others:
            free = next_participant_number(self.known)
            warnings["participant_number"] = (
                f"number {v.participant_number} is already {', '.join(others)}'s: the same number gives the same "
                f"trial order (counterbalancing). Use {free} for a new participant; keep {v.participant_number} "
                "only to replace a participant who dropped out")
        mine = [s for s in self.known if s["code"] == v.code]
        if mine and mine[-1]["participant_number"] != v.participant_number:
            warnings["code"] = (f"{v.code} ran as number {mine[-1]['participant_number']} before (session "
                                f"{mine[-1]['session_id']}): the number decides the trial order")

    def count_of(self, s: dict[str, Any]) -> TrialCount:
        """The progress of a listed session, counted as the running one is (:class:`TrialCount`)."""
        listed = next((r for r in self.resumable if r["session_id"] == s["session_id"]), s)

        def n(key: str) -> int:
            v = listed.get(key, 0)
            return int(v) if isinstance(v, (int, float, str)) else 0

        return TrialCount(n("trials_planned"), n("trials_done"), n("trials_aborted"), n("reruns_run"))

    @property
    def valid(self) -> bool:
        """True when every field passed :meth:`validate` and a code is entered."""
        return not self.errors and bool(self.values.code)

    @property
    def training_missing(self) -> str:
        """Why the experiment would be refused for want of training, when that is the form's only error ("" else):
        the case an override with a reason may pass."""
        return self.errors["training"] if set(self.errors) == {"training"} and self.values.code else ""

    def next_step(self) -> str:
        """What the participant does next, in words ("" without a code or a protocol)."""
        v, p = self.values, self.protocol
        if p is not None and p.visits:
            return self.schedule.words()
        if p is not None and p.parts:
            return plan_words(self.plan(), v.code)
        if not v.code or p is None or not p.training.enabled:
            return ""
        proposed = next_kind(self._stored(), v.code, p)
        rule = "required before the experiment" if requires_training(p) else "the protocol's practice block"
        if proposed == "training":
            return f"Next for {v.code}: training ({rule}), then the experiment."
        return f"Next for {v.code}: the experiment."

    def start_command(self, training_override: str = "", visit_reason: str = "") -> m.StartSession:
        """The command that starts this session (validate first); ``training_override`` passes a missing training,
        ``visit_reason`` a visit out of order or outside its window (:attr:`schedule`'s refusal; stored as a
        deviation, as ``run --visit --deviation`` stores it)."""
        errors = dict(self.validate())
        if training_override.strip() and self.training_missing:
            errors.pop("training")
        if errors or not self.values.code:
            raise ValueError("; ".join(errors.values()) or self.hint)
        v = self.values
        events = () if not v.visit or self.protocol is None else visit_events(
            self.protocol, self.known, v.code, v.participant_number, v.seed, v.visit, v.part, visit_reason.strip(),
            os.path.abspath(v.db_path))
        return m.StartSession(os.path.abspath(v.db_path), v.code, v.kind, v.protocol_path.strip() or None, v.seed,
                              v.participant_number, training_override=training_override.strip(),
                              covariates=self.covariates.values(), part=v.part, visit=v.visit, events=events)

    def set_resumable(self, sessions: list[dict[str, object]]) -> None:
        """Interrupted sessions listed by the engine."""
        self.resumable = list(sessions)
        self.resumable_changed.emit()

    def default_resume(self) -> int | None:
        """The session the resume list selects: the one an engine failure interrupted, else the first listed."""
        ids = [int(s["session_id"]) for s in self.resumable]  # type: ignore[call-overload]  # an int in an untyped row
        if self.preferred_resume in ids:
            return self.preferred_resume
        return ids[0] if ids else None

    def set_known(self, sessions: list[dict[str, Any]], withdrawn: list[dict[str, str]] | None = None,
                  covariates: dict[str, dict[str, Any]] | None = None) -> None:
        """Every session of the database, who withdrew and the registered participants' covariates (listed by the
        engine): suggestions and checks follow them; a database with sessions has its seed, and the form takes it
        (the view shows it read-only)."""
        self.known = list(sessions)
        self.withdrawn = list(withdrawn or [])
        self.registered = dict(covariates or {})
        first = study_seed(self._stored())
        if first is not None and self.values.seed != first.seed:
            self.values = replace(self.values, seed=first.seed)
        self._suggest_number()
        self._suggest_kind()
        self.validate()

    def session_began(self, code: str, kind: str, participant_number: int, session_id: int | None = None,
                      seed: int | None = None) -> None:
        """A session started or resumed: the form shows whose it is (and knows it is stored: the study's seed
        is fixed from now on, before the database is listed again)."""
        self.running_session = session_id
        if self.covariates.asking and code == self.values.code and code not in self.registered:
            self.registered[code] = self.covariates.typed()  # stored with this session (until listed again)
        if session_id == self.preferred_resume:
            self.preferred_resume = None
        if session_id is not None and seed is not None and all(s["session_id"] != session_id for s in self.known):
            self.known.append({"session_id": session_id, "code": code, "participant_number": participant_number,
                               "kind": kind, "status": "running", "seed": seed, "trials_planned": 0,
                               "trials_done": 0, "trials_aborted": 0, "part": self.values.part,
                               "visit": self.values.visit})
        listed = next((s for s in self.known if s["session_id"] == session_id), None)
        v = self.values
        if listed is not None:  # a resumed part: its own part (and visit)
            v = replace(v, part=str(listed.get("part", "")), visit=str(listed.get("visit", "")))
        self.values = replace(v, code=code, kind=kind, participant_number=participant_number)
        self.number_suggested = False
        self.validate()

    def session_ended(self, kind: str, status: str) -> None:
        """The running session ended; if it finished (completed or aborted), set up the next one
        (:meth:`next_participant`)."""
        for s in self.known:  # as stored now, before the database is listed again
            if s["session_id"] == self.running_session:
                s["status"] = status
        self.running_session = None
        if status in ("completed", "aborted"):
            self.next_participant(kind)
        else:
            self.validate()

    def next_participant(self, ended_kind: str) -> None:
        """After training the same participant does the experiment; after an experiment, the next participant
        (empty code, the next free number suggested)."""
        v = self.values
        coming = next_part_name(self.protocol, self._stored(), v.code, v.participant_number, v.seed)
        self._refresh_schedule()
        if coming and self.schedule.next is not None and self.schedule.next[0] != v.visit:
            coming = ""  # the visit is done: the participant comes back for the next one, another comes now
        if coming:  # a study of several parts: the same participant's next part
            self.kind_suggested = True
            self._suggest_kind()
        elif ended_kind == "training" and not v.part:
            self.values = replace(self.values, kind="experiment")
        else:
            self.values = replace(self.values, code="")
            self.covariates.clear()
            self.number_suggested = True
            self.kind_suggested = True
            self._suggest_number()
            self._suggest_kind()
        self.validate()

    def describe_resumable(self, s: dict[str, object]) -> str:
        """One line for the resume list, its progress counted as the running session's is."""
        part = f" (part {s['part']})" if s.get("part") else ""
        if s.get("visit"):
            part = f" (visit {s['visit']}, part {s['part']})"
        return (f"session {s['session_id']}: {s['code']} {s['kind']}{part}, {self.count_of(s).text()}, started "
                f"{str(s['started_at'])[:16].replace('T', ' ')}")
