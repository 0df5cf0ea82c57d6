"""The study protocol as data: load and validate a protocol TOML file.

A protocol names the task (``[task]``, :mod:`protocol.tasks`; none: the paper's force regulation), the targets,
the haptic modes, the trial counts and timing, the ordering method and the training block.  :func:`load_protocol` checks
every field and raises one :class:`ProtocolError` that names the field, the
offending value and what is allowed -- nothing starts with a bad file.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from pipeline.devices.rig import ARM_NAME, ARM_NAME_WHAT, SINGLE_ARM_NAME
from pipeline.force.config import SafetyConfig
from pipeline.settings.tomlfields import Fields, parse_toml, read_toml
from protocol.study.covariates import Covariate, covariates_from_tables
from protocol.study.feedback import FeedbackConfig, feedback_from_table
from protocol.study.groups import GroupDesign, groups_from_table
from protocol.study.lsl_settings import LslSettings, lsl_from_table
from protocol.study.parts import (
    Counterbalance,
    PartPlace,
    counterbalance_from_table,
    order_of,
    part_tables,
    place_from_table,
)
from protocol.study.questionnaires import Questionnaire, questionnaires_from_tables
from protocol.study.visits import Visit, VisitPlace, visits_from_tables
from protocol.tasks.base import Task, Timing
from protocol.tasks.force_regulation import ForceRegulation
from protocol.tasks.registry import named, task_tables

__all__ = [
    "ABORT_POLICIES",
    "MAX_TRIAL_S",
    "MODES",
    "ORDERINGS",
    "ProtocolConfig",
    "ProtocolError",
    "Target",
    "TrainingConfig",
    "TrialTiming",
    "default_protocol",
    "load_protocol",
    "protocol_from_dict",
]

ORDERINGS = ("random", "blocked_by_mode", "counterbalanced")
ABORT_POLICIES = ("append", "reinsert")
MODES = ("on", "off")
#: Longest trial cap (s): ``trial.max_trial_s``, and each training trial's length.
MAX_TRIAL_S = 600.0
_LABEL = re.compile(r"^[A-Z][A-Z0-9_]{0,15}\Z")  # \Z, not $: "$" also matches before a final newline


class ProtocolError(ValueError):
    """A protocol file or value is invalid; the message names field, value and what is allowed."""


@dataclass(frozen=True, slots=True)
class Target:
    """A target force and the word the participant sees."""

    label: str
    force_n: float


@dataclass(frozen=True, slots=True)
class TrialTiming:
    """The timing of each trial, whatever its task (paper §V-B): its cap, the pause after it, how long its cue shows.

    The task's own parameters (the paper's band and hold) are the task's (:attr:`ProtocolConfig.task`).
    """

    max_trial_s: float = 12.0
    pause_s: float = 2.0
    cue_s: float = 1.0


@dataclass(frozen=True, slots=True)
class TrainingConfig:
    """Free-practice block before the experiment."""

    enabled: bool = True
    seconds_per_target_per_mode: float = 20.0
    live_force_aid: bool = True
    #: An experiment session needs a completed training session of the same participant
    #: (:mod:`protocol.runner.study_rules`).  In a file it defaults to ``enabled``; without training it is False.
    required: bool = True

    def __post_init__(self) -> None:
        if not self.enabled and self.required:  # nothing to require (e.g. dataclasses.replace(t, enabled=False))
            object.__setattr__(self, "required", False)


@dataclass(frozen=True, slots=True)
class ProtocolConfig:
    """A validated study protocol."""

    name: str
    targets: tuple[Target, ...]
    modes: tuple[str, ...]
    trials_per_cell: int
    ordering: str
    abort_policy: str
    trial: TrialTiming
    training: TrainingConfig
    version: int = 1
    #: The rig's arm whose instrument does the task (its force is the trial's task force; the other arms are
    #: recorded too).  "" (the default): the rig's only arm, or ``right`` on a rig of several (:meth:`task_arm_of`).
    task_arm: str = ""
    #: What each trial asks and how it is judged, with its parameters (:mod:`protocol.tasks`): the file's ``[task]``
    #: table; none is the paper's force regulation, whose band and hold are ``trial.tolerance_fraction`` and
    #: ``trial.hold_s``.
    task: Task = field(default_factory=ForceRegulation)
    #: What the study collects about each participant (:mod:`protocol.study.covariates`; the file's
    #: ``[[covariates]]``): none by default.
    covariates: tuple[Covariate, ...] = ()
    #: The questionnaires asked on the participant screen (:mod:`protocol.study.questionnaires`; the file's
    #: ``[[questionnaires]]``): none by default.
    questionnaires: tuple[Questionnaire, ...] = ()
    #: The between-group design (:mod:`protocol.study.groups`; the file's ``[groups]``): None, no groups.
    groups: GroupDesign | None = None
    #: What the session publishes and records on the Lab Streaming Layer (:mod:`protocol.study.lsl_settings`; the
    #: file's ``[lsl]``): nothing by default.
    lsl: LslSettings = field(default_factory=LslSettings)
    #: Feedback to the trainee (:mod:`protocol.study.feedback`; the file's ``[feedback]``): none by default.
    feedback: FeedbackConfig = field(default_factory=FeedbackConfig)
    #: The study's task blocks (:mod:`protocol.study.parts`; the file's ``[[parts]]``), each a protocol of its own
    #: with its :attr:`part` set, in the file's order: () for a study of one task (a training then an experiment
    #: session of :attr:`task`).
    parts: tuple[ProtocolConfig, ...] = ()
    #: Which parts' order varies across participants, and how (the file's ``[counterbalance]``).
    counterbalance: Counterbalance | None = None
    #: Which part of a study this protocol is (a part's protocol, as a session of it stores it); None otherwise.
    part: PartPlace | None = None
    #: The schedule of visits above the parts (:mod:`protocol.study.visits`; the file's ``[[visits]]``): () for a
    #: study done in one visit.
    visits: tuple[Visit, ...] = ()

    def plan_for(self, number: int, seed: int) -> tuple[ProtocolConfig, ...]:
        """Participant ``number``'s parts in their order (:func:`protocol.study.parts.order_of`), each with its
        place set; () for a study of one task.  With ``[[visits]]``: every visit's parts, visit after visit, each
        with its visit and its place in the visit's order (counterbalanced within the visit)."""
        if not self.parts:
            return ()
        by_name = {p.part.name: p for p in self.parts if p.part is not None}
        if not self.visits:
            return _placed(self, tuple(by_name), by_name, number, seed, None, ())
        out: list[ProtocolConfig] = []
        for i, v in enumerate(self.visits, start=1):
            trained = tuple(dict.fromkeys(p.part.name for p in out if p.part is not None
                                          and p.part.session == "training"))
            out.extend(_placed(self, v.parts, by_name, number, seed,
                               VisitPlace(v.name, i, v.day, v.window_days, v.role,
                                          v.day - self.visits[i - 2].day if i > 1 else 0), trained))
        return tuple(out)

    def part_of(self, name: str, number: int, seed: int, visit: str = "") -> ProtocolConfig:
        """Participant ``number``'s part ``name`` (of the visit ``visit`` in a study of visits: :meth:`plan_for`;
        :class:`KeyError` naming the parts, or the visits)."""
        if self.visits and visit not in self.visit_names:
            raise KeyError(f"no visit {visit!r}: the visits are {', '.join(self.visit_names)}")
        for p in self.plan_for(number, seed):
            if p.part is not None and p.part.name == name and (p.part.visit is None or p.part.visit.name == visit):
                return p
        where = f" in visit {visit!r}" if visit else ""
        raise KeyError(f"no part {name!r}{where}: the parts are {', '.join(self.part_names)}")

    @property
    def visit_names(self) -> tuple[str, ...]:
        """The visits' names in the schedule's order (() for a study without ``[[visits]]``)."""
        return tuple(v.name for v in self.visits)

    @property
    def visit(self) -> VisitPlace | None:
        """The visit of a schedule this part's session belongs to (a part's protocol in a study with visits)."""
        return self.part.visit if self.part is not None else None

    @property
    def part_names(self) -> tuple[str, ...]:
        """The parts' names in the file's order (() for a study of one task)."""
        return tuple(p.part.name for p in self.parts if p.part is not None)

    @property
    def trials_per_participant(self) -> int:
        """Targets × modes × trials per cell (20 for the paper)."""
        return len(self.targets) * len(self.modes) * self.trials_per_cell

    def target(self, label: str) -> Target:
        """The target with this label."""
        for t in self.targets:
            if t.label == label:
                return t
        raise KeyError(label)

    def task_arm_of(self, arms: Sequence[str]) -> str:
        """The task arm on a rig whose arms are ``arms`` (the first first).

        Raises
        ------
        ProtocolError
            One line when the protocol names an arm the rig does not have, or leaves the choice to a rig of
            several arms none of which is called ``right``.
        """
        if self.task_arm:
            if self.task_arm not in arms:
                raise ProtocolError(f"design.task_arm = {self.task_arm!r}: the rig has no such arm (its arms: "
                                    f"{', '.join(arms)})")
            return self.task_arm
        if len(arms) == 1:
            return arms[0]
        if SINGLE_ARM_NAME in arms:
            return SINGLE_ARM_NAME
        raise ProtocolError(f"design.task_arm is not set and the rig has {len(arms)} arms ({', '.join(arms)}), none "
                            f"called {SINGLE_ARM_NAME!r}: name the arm that does the task in the protocol")

    def check_ramps(self, safety: SafetyConfig, source: str = "protocol") -> None:
        """This protocol run by a pipeline whose ramps are ``safety``'s (``run --set ramp_in_s=…``): refused in one
        :class:`ProtocolError` line where an ON trial could not hold the ramp-in, or a pause the ramp-out (the
        checks the file had with the paper's ramps, :func:`_check_together`)."""
        _check_together(Fields(source, ProtocolError), self.task, self.trial, self.training, self.modes, safety,
                        tuple(t.label for t in self.targets), tuple(t.force_n for t in self.targets))
        for part in self.parts:
            assert part.part is not None
            part.check_ramps(safety, f"{source}, part {part.part.name!r}")

    def to_dict(self) -> dict[str, Any]:
        """Plain data in the file's structure (stored with each session; ``design.task_arm`` only when set and
        ``task`` only for another task than the paper's, so a protocol of before the arms and the tasks stores what it
        always stored)."""
        task, task_trial = task_tables(self.task)
        return {
            "name": self.name,
            "version": self.version,
            "targets": [asdict(t) for t in self.targets],
            "design": {
                "modes": list(self.modes),
                "trials_per_cell": self.trials_per_cell,
                "ordering": self.ordering,
                "abort_policy": self.abort_policy,
                **({"task_arm": self.task_arm} if self.task_arm else {}),
            },
            "trial": {**task_trial, **asdict(self.trial)},
            "training": asdict(self.training),
            **({"task": task} if task is not None else {}),
            **({"covariates": [c.to_dict() for c in self.covariates]} if self.covariates else {}),
            **({"questionnaires": [q.to_dict() for q in self.questionnaires]} if self.questionnaires else {}),
            **({"groups": self.groups.to_dict()} if self.groups is not None else {}),
            **({"lsl": lsl} if (lsl := self.lsl.to_dict()) is not None else {}),
            **({"parts": [_part_dict(p) for p in self.parts]} if self.parts else {}),
            **({"counterbalance": self.counterbalance.to_dict()} if self.counterbalance is not None else {}),
            **({"visits": [v.to_dict() for v in self.visits]} if self.visits else {}),
            **({"part": self.part.to_dict()} if self.part is not None else {}),
            **({"feedback": fb} if (fb := self.feedback.to_dict()) is not None else {}),
        }

    def to_json(self) -> str:
        """Canonical JSON of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), sort_keys=True)


def _placed(study: ProtocolConfig, names: tuple[str, ...], by_name: dict[str, ProtocolConfig], number: int,
            seed: int, visit: VisitPlace | None, trained: tuple[str, ...]) -> tuple[ProtocolConfig, ...]:
    """The parts ``names`` (file order) in participant ``number``'s order, each with its place (in ``visit``), and
    the training parts before it (``trained``: those done in earlier visits)."""
    balance = study.counterbalance
    if visit is not None and balance is not None:  # the visit's counterbalanced parts in the row's order among them
        full, row = order_of(balance.parts, balance, seed, number)
        mine = iter(n for n in full if n in names)
        order = tuple(next(mine) if n in balance.parts else n for n in names)
    else:
        order, row = order_of(names, balance, seed, number)
    training = {n for n, p in by_name.items() if p.part is not None and p.part.session == "training"}
    out = []
    for position, name in enumerate(order, start=1):
        part = by_name[name]
        assert part.part is not None
        trained_by = tuple(dict.fromkeys(trained + tuple(n for n in order[:position - 1] if n in training)))
        out.append(replace(part, part=replace(part.part, position=position, order=order, row=row,
                                              trained_by=trained_by, balance=study.counterbalance, visit=visit)))
    return tuple(out)


def _part_dict(part: ProtocolConfig) -> dict[str, Any]:
    """A part as the file's ``[[parts]]`` table writes it: its name and kind and all its own tables (its task named
    even when it is the paper's, so the study's ``[task]`` is not inherited on reading it back)."""
    assert part.part is not None
    d = part.to_dict()
    return {"name": part.part.name, "session": part.part.session, "task": d.get("task", {"kind": part.task.kind}),
            **{k: d[k] for k in ("targets", "design", "trial", "training")}}


def protocol_from_dict(d: Any, source: str = "protocol") -> ProtocolConfig:
    """Validate plain data (a parsed TOML file) into a :class:`ProtocolConfig`.

    Besides every field, what is derived from them is checked: the training
    session runs (and stores, and on resume re-reads) the protocol with
    ``trial.max_trial_s = training.seconds_per_target_per_mode``, so that
    value must be a valid trial cap too.

    Raises
    ------
    ProtocolError
        One line naming ``source``, the field, the value and what is allowed.
    """
    f = Fields(source, ProtocolError)
    top = f.table("", d, {"name", "version", "targets", "design", "trial", "training", "task", "covariates",
                          "questionnaires", "groups", "lsl", "feedback", "parts", "counterbalance", "part",
                          "visits"})
    name = f.string("name", top.get("name", "unnamed protocol"))
    f.version(top, "protocol")

    def target(field: str, t: Any) -> Target:
        t = f.table(field, t, {"label", "force_n"})
        label = f.string(f"{field}.label", t.get("label"), pattern=_LABEL,
                         what="an upper-case word of 1–16 letters/digits/_ (e.g. GENTLE)")
        return Target(label, f.number(f"{field}.force_n", t.get("force_n"), lo=0.0, hi=20.0))

    targets = f.list_of("targets", top.get("targets"), target, min_len=1, max_len=8,
                        what="a list of 1 to 8 [[targets]] tables")
    labels = [t.label for t in targets]
    if len(set(labels)) != len(labels):
        raise f.fail("targets", labels, "labels must be unique")

    design = f.section(top, "design", {"modes", "trials_per_cell", "ordering", "abort_policy", "task_arm"})
    modes = design.get("modes", list(MODES))
    if (
        not isinstance(modes, list) or not modes
        or any(not isinstance(m, str) or m not in MODES for m in modes) or len(set(modes)) != len(modes)
    ):
        raise f.fail("design.modes", modes, "must be a non-empty list of distinct values from 'on', 'off'")
    per_cell = f.integer("design.trials_per_cell", design.get("trials_per_cell", 5), lo=1, hi=100)
    ordering = f.choice("design.ordering", design.get("ordering", "random"), ORDERINGS)
    policy = f.choice("design.abort_policy", design.get("abort_policy", "append"), ABORT_POLICIES)
    task_arm = f.string("design.task_arm", design["task_arm"], pattern=ARM_NAME, what=ARM_NAME_WHAT) \
        if "task_arm" in design else ""

    kind, own = named(f, top)
    tr = f.section(top, "trial", {"max_trial_s", "pause_s", "cue_s", *kind.trial_fields})
    task = kind.from_tables(f, own, tr)
    timing = TrialTiming(
        max_trial_s=f.number("trial.max_trial_s", tr.get("max_trial_s", 12.0), lo=0.0, hi=MAX_TRIAL_S),
        pause_s=f.number("trial.pause_s", tr.get("pause_s", 2.0), lo=0.0, hi=600.0, lo_open=False),
        cue_s=f.number("trial.cue_s", tr.get("cue_s", 1.0), lo=0.0, hi=60.0, lo_open=False),
    )

    trn = f.section(top, "training", {"enabled", "seconds_per_target_per_mode", "live_force_aid", "required"})
    training = TrainingConfig(
        enabled=f.boolean("training.enabled", trn.get("enabled", True)),
        seconds_per_target_per_mode=f.number(
            "training.seconds_per_target_per_mode", trn.get("seconds_per_target_per_mode", 20.0), lo=0.0, hi=MAX_TRIAL_S
        ),
        live_force_aid=f.boolean("training.live_force_aid", trn.get("live_force_aid", True)),
        required=_training_required(f, trn),
    )
    _check_together(f, task, timing, training, tuple(modes), targets=tuple(labels),
                    forces=tuple(t.force_n for t in targets))
    covariates = covariates_from_tables(f, top.get("covariates"))
    own_count = task.trials_per_cell(per_cell)  # a task whose block has its own count (discrimination's task.trials)
    if own_count != per_cell and "trials_per_cell" in design:
        raise f.fail("design.trials_per_cell", per_cell, f"leave it out: the {task.title} task's trials per target "
                     f"are its own ({own_count})")
    return ProtocolConfig(
        name=name, targets=tuple(targets), modes=tuple(modes), trials_per_cell=own_count,
        ordering=ordering, abort_policy=policy, trial=timing, training=training, version=1, task_arm=task_arm,
        task=task, covariates=covariates,
        questionnaires=questionnaires_from_tables(f, top.get("questionnaires"), ordering),
        groups=groups_from_table(f, top.get("groups"), covariates),
        lsl=lsl_from_table(f, top),
        **_plan(f, top),
        feedback=feedback_from_table(f, top, ordering),
    )


def _plan(f: Fields, top: dict[str, Any]) -> dict[str, Any]:
    """The file's task blocks (``[[parts]]``, each validated as a protocol of its own), ``[counterbalance]`` and a
    stored session's ``part`` (:mod:`protocol.study.parts`): the :class:`ProtocolConfig` fields they set."""
    parts = []
    for t in part_tables(f, top):
        p = protocol_from_dict(t.tables, t.source)
        if t.session == "training" and not p.training.enabled:
            raise ProtocolError(f"{t.source}: session = 'training': the part's training.enabled is false, so it has "
                                "no trials (set [parts.training] enabled = true, or make it an experiment part)")
        parts.append(replace(p, part=PartPlace(t.name, t.session)))
    balance = counterbalance_from_table(f, top, [p.part.name for p in parts if p.part is not None])
    visits = visits_from_tables(f, top.get("visits"), {p.part.name: p.part.session for p in parts if p.part})
    return {"parts": tuple(parts), "counterbalance": balance, "part": place_from_table(f, top), "visits": visits}


def _training_required(f: Fields, trn: dict[str, Any]) -> bool:
    """``training.required``: defaults to ``training.enabled``; required without a training block is refused."""
    enabled = bool(trn.get("enabled", True))
    required = f.boolean("training.required", trn.get("required", enabled))
    if required and not enabled:
        raise f.fail("training.required", required, "must be false when training.enabled = false (an experiment "
                     "cannot require a training session the protocol does not have)")
    return required


def _check_together(f: Fields, task: Task, timing: TrialTiming, training: TrainingConfig, modes: tuple[str, ...],
                    ramps: SafetyConfig | None = None, targets: tuple[str, ...] = (),
                    forces: tuple[float, ...] = ()) -> None:
    """Values valid alone but not together: one line naming both fields.

    * The task's parameters against the trial's cap, each training trial's length and the feedback's ramps
      (:meth:`protocol.tasks.base.Task.check_timing`: the paper's hold must fit a trial, and its ramp-in too when
      haptics ON is in the design).
    * ``trial.pause_s`` ≥ the feedback's ramp-out when haptics ON is in the
      design: otherwise the next trial is cued while the last one's force is
      still fading out (an OFF trial would start with feedback).

    The ramps are the safety stage's own (:class:`pipeline.force.safety.SafetyConfig`, their one definition):
    the paper's pipeline when the file is loaded, the pipeline a study runs with (``run --set``) at its start
    (:meth:`ProtocolConfig.check_ramps`).
    """
    ramps = ramps or SafetyConfig()
    on = "on" in modes
    task.check_timing(f, Timing(timing.max_trial_s, training.seconds_per_target_per_mode, on, ramps, targets, forces))
    if on and timing.pause_s < ramps.fault_ramp_s:
        raise f.fail("trial.pause_s", timing.pause_s,
                     f"must be at least the feedback's {ramps.fault_ramp_s:g} s ramp-out (safety.fault_ramp_s) when "
                     "design.modes has 'on': otherwise a trial is cued while the last one's force still fades out")


def load_protocol(path: str | Path | None = None) -> ProtocolConfig:
    """Load and validate a protocol file (default: the paper's study, ``protocol/study/default.toml``)."""
    if path is None:
        source = "protocol/study/default.toml"
        text = resources.files("protocol.study").joinpath("default.toml").read_text(encoding="utf-8")
        data = parse_toml(text, source, ProtocolError)
    else:
        source = str(Path(path))
        data = read_toml(Path(path), ProtocolError, "protocol file")
        if "part" in data:  # the software's record of which part a stored session is: not a file's to say
            raise Fields(source, ProtocolError).fail("part", data["part"], "is stored with each session of a "
                                                     "[[parts]] study, not written in a protocol file")
    protocol = protocol_from_dict(data, source)
    _check_cue(Fields(source, ProtocolError), protocol.trial)
    for part in protocol.parts:
        assert part.part is not None
        _check_cue(Fields(f"{source}, part {part.part.name!r}", ProtocolError), part.trial)
    return protocol


def _check_cue(f: Fields, timing: TrialTiming) -> None:
    """A protocol file's cue must end before its trial's cap: a cue as long as the trial shows the target word
    throughout, another condition than the design's brief cue (``cue_s = 30`` with a 12 s cap ran a whole study).
    Checked where a file is loaded for new sessions, not where a stored session's protocol is read back, so a
    session stored before the check can still be resumed, checked and analysed as it ran."""
    if timing.cue_s >= timing.max_trial_s:
        raise f.fail("trial.cue_s", timing.cue_s, f"must be shorter than trial.max_trial_s = {timing.max_trial_s:g} "
                     "(the cue word is shown at the start of each trial, then the screen goes blank)")


def default_protocol() -> ProtocolConfig:
    """The paper's study."""
    return load_protocol(None)
