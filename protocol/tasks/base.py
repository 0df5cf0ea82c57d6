"""The task seam: what a trial asks of the participant, how it is judged, what the screens show, what it measures.

A task is one module of :mod:`protocol.tasks` defining one :class:`Task` (the paper's is
:class:`protocol.tasks.force_regulation.ForceRegulation`) and its line in :data:`protocol.tasks.registry.TASKS`.  An
instance holds the task's parameters as the protocol file set them (validated there: one line naming the field, its
value and what is allowed); everything that runs, shows or analyses a trial asks it:

* **its target over trial time** (:meth:`Task.target_n`) and **its rule**: the streaming form the live trial machine
  feeds sample by sample (:meth:`Task.rule`, exact on integer-ns times) and the offline form that judges a whole
  trial and computes its metrics (:meth:`Task.judge`), one definition: the live machine checks that both agree;
* **the metrics it produces**, by name in the metric registry (:attr:`Task.metric_names`, :mod:`protocol.metrics`);
* **what the screens show** of a trial (:meth:`Task.screen`: the cue word, the band over trial time that every view
  asks at its time -- the participant screen, the experimenter's live plot, the training gauge, replay and the
  report's figures -- and their words) and the cue event's text (:meth:`Task.cue_text`);
* **what a simulated participant is told** at the cue (:meth:`Task.aim`, the pipeline's
  :class:`pipeline.core.aim.TrialAim`: what to aim at, when, and with which aid);
* **its words in the report** (:meth:`Task.rule_words`, :meth:`Task.methods`);
* for a task that *presents* a force and *asks* about it (force discrimination): **the question's answers**
  (:attr:`Task.answer_keys`, asked when the rule completes, until :meth:`Task.answer_by_s`) and **its procedure**
  (:meth:`Task.stimulus_procedure`: each trial's :class:`Stimulus` -- the commanded force the loop renders and the
  values that define it -- chosen from the answers so far, and each answer scored), rebuilt from the stored answers.

A trial reaches the task as a :class:`TrialCondition`: its target (label and reference force, as the schedule and
the ``trials`` table store them) and its haptic mode -- a schedule entry, a stored record, the engine's message and
an analysis row all are one.  The trial's cap, pause and cue are the protocol's (:class:`protocol.tasks.base.Timing`
is what a task's checks see of them).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
import numpy.typing as npt

from pipeline.core.aim import TrialAim
from pipeline.core.force_program import ForceProgram
from pipeline.force.config import SafetyConfig
from pipeline.settings.tomlfields import Fields
from protocol.metrics import Metric, select
from protocol.tasks.window import TrialMetrics

__all__ = ["Answered", "BandEdges", "ConstantBand", "Parameter", "Procedure", "Stimulus", "Task", "TaskTables",
           "Timing", "TrialCondition", "TrialRule", "TrialScreen", "TrialTarget", "constant_band", "listed",
           "metrics_of"]


class TrialCondition(Protocol):
    """A trial as every floor has it: its target by label and reference force, and its haptic mode (``on``/``off``)."""

    @property
    def target_label(self) -> str: ...

    @property
    def target_force_n(self) -> float: ...

    @property
    def haptic_mode(self) -> str: ...


@dataclass(frozen=True, slots=True)
class TrialTarget:
    """A trial's condition as plain data (a :class:`TrialCondition`): what a table row read back gives a task."""

    target_label: str
    target_force_n: float
    haptic_mode: str

    @classmethod
    def of(cls, row: Mapping[str, Any]) -> TrialTarget:
        """From a row with the ``trials`` table's ``target_label``, ``target_force_n`` and ``haptic_mode``."""
        return cls(str(row["target_label"]), float(row["target_force_n"]), str(row["haptic_mode"]))


class TrialRule(Protocol):
    """A task's success rule in its streaming form: fed a trial's samples in time order, from its cue on."""

    def feed(self, t_ns: int, force_n: float) -> bool:
        """One sample (``t_ns`` since the cue, integer ns); True at the sample that completes the task (once)."""
        ...


#: A band over trial time: its lower and upper edge at trial times ``t_s`` (s since the cue), N.
BandEdges = Callable[[npt.NDArray[np.float64]], tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]

#: Points a band is sampled at to find its extent over a span of trial time (:meth:`TrialScreen.band_extent`).
_EXTENT_POINTS = 256


@dataclass(frozen=True, slots=True)
class ConstantBand:
    """A band that holds all trial (the force-regulation task's), as :data:`BandEdges` (a value, not a closure: a
    screen travels to the report's figure workers and across the engine's pipe)."""

    lo_n: float
    hi_n: float

    def __call__(self, t_s: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        n = len(t_s)
        return np.full(n, self.lo_n), np.full(n, self.hi_n)


def constant_band(lo_n: float, hi_n: float) -> BandEdges:
    """A band that holds all trial (:class:`ConstantBand`)."""
    return ConstantBand(lo_n, hi_n)


@dataclass(frozen=True, slots=True)
class TrialScreen:
    """What the screens show of one trial (the phases around it -- rest, wait, thanks -- are the session's).

    Every view asks it for the band *at a time* (:meth:`band_at`, :meth:`band_over`): the participant screen and the
    training gauge at present, the experimenter's live plot from the cue to now, replay's session figure and the
    report's trace figures over the trial -- so a band that moves (a tracked target) is drawn where it was.

    Attributes
    ----------
    cue_word
        The participant screen's word at the cue (``GENTLE``).
    band
        The success region over trial time, :data:`BandEdges` (None: the task has none).
    band_label
        The live plot's words for it (``GENTLE: target 0.6 N ± 10 % (0.54–0.66 N)``).
    band_legend
        A figure's legend for it (``target band 0.6 N ± 10%``).
    follow
        What the participant screen says while it shows the band all trial, without the force (a target that
        moves, which the participant follows: ``Follow the target``); "" -- the participant screen shows the band
        only on the training gauge, with the force (the paper's).
    show_band, ahead_s
        Whether the participant screen shows the band (False: a task's display of the word only), and how far
        ahead in trial time it draws the band's course above it (0: the band at present only), s.
    spans
        Words the participant screen shows over spans of trial time ``(t0_s, t1_s, word)``: force discrimination's
        ``first`` and ``second`` while each force is presented.
    question, answers
        What the participant screen asks once the trial's question is open (:attr:`Task.answer_keys`), and each
        answer's key with its words (``("1", "first")``): its buttons, and the keys that give them.
    """

    cue_word: str
    band: BandEdges | None
    band_label: str
    band_legend: str
    follow: str = ""
    show_band: bool = True
    ahead_s: float = 0.0
    spans: tuple[tuple[float, float, str], ...] = ()
    question: str = ""
    answers: tuple[tuple[str, str], ...] = ()

    def word_at(self, t_s: float) -> str:
        """The word of the span holding trial time ``t_s`` ("" outside them)."""
        return next((w for a, b, w in self.spans if a <= t_s < b), "")

    def band_over(self, t_s: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
        """The band's lower and upper edge at trial times ``t_s`` (s since the cue), N; None without a band."""
        if self.band is None:
            return None
        lo, hi = self.band(np.atleast_1d(np.asarray(t_s, dtype=np.float64)))
        return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)

    def band_at(self, t_s: float) -> tuple[float, float] | None:
        """The band at trial time ``t_s`` (s since the cue), N; None without a band."""
        edges = self.band_over([t_s])
        return None if edges is None else (float(edges[0][0]), float(edges[1][0]))

    def band_extent(self, t0_s: float, t1_s: float) -> tuple[float, float] | None:
        """The lowest and highest edge of the band between two trial times (an axis that holds it all), N."""
        edges = self.band_over(np.linspace(t0_s, max(t0_s, t1_s), _EXTENT_POINTS))
        return None if edges is None else (float(np.min(edges[0])), float(np.max(edges[1])))


@dataclass(frozen=True, slots=True)
class Timing:
    """What a task's checks see of the protocol's timing: the trial cap, each training trial's length, whether
    haptics ON is in the design, the feedback's ramps (the safety stage's, :class:`SafetyConfig`), the targets'
    labels and their forces, N (empty: not known to the check)."""

    max_trial_s: float
    training_s: float
    haptics_on: bool
    ramps: SafetyConfig
    targets: tuple[str, ...] = ()
    target_forces_n: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class Parameter:
    """One of a task's parameters as the exported tables describe it: the codebook's entry for its column (the
    sessions and trials tables carry each session's task parameters, :meth:`Task.parameters`).

    Attributes
    ----------
    name, description, unit, label
        Its column's name, what it means, its unit and its short heading in the report's tables.
    decimals
        How far the files round it.
    """

    name: str
    description: str
    unit: str
    label: str
    decimals: int


@dataclass(frozen=True, slots=True)
class Stimulus:
    """What a trial presents beyond its target: the force the loop renders as commanded (from the cue on), and the
    values that define it (stored with the trial's answer: force discrimination's ``delta_n``,
    ``comparison_first``, ``reference_n``)."""

    program: ForceProgram
    values: Mapping[str, float]


@dataclass(frozen=True, slots=True)
class Answered:
    """One trial of a block as its procedure sees it: its target, its stimulus's values and its answer's (scored:
    ``correct``), and the answer (None: none given)."""

    target_label: str
    values: Mapping[str, float]
    answer: str | None


class Procedure(Protocol):
    """A task's procedure over one block (a session): each trial's stimulus, each answer scored.  Its state is a
    function of the block's :class:`Answered` history only (:meth:`Task.stimulus_procedure` rebuilds it from the stored
    answers, so a resumed block continues where it stopped)."""

    def next(self, trial: TrialCondition, index: int) -> Stimulus:
        """The stimulus of the block's trial ``index`` (the schedule's trial index) at ``trial``'s target."""
        ...

    def answered(self, trial: TrialCondition, stimulus: Stimulus, answer: str | None,
                 t_s: npt.NDArray[np.float64], rendered_n: npt.NDArray[np.float64]) -> dict[str, float]:
        """One trial answered: its values to store (the stimulus's and the answer's: what was felt, whether it was
        right), from the force rendered at trial times ``t_s``; the procedure takes it into its state."""
        ...


#: A task's parameters as the protocol file has them: its ``[task]`` table's fields (``kind`` aside) and the
#: ``[trial]`` table's fields that are its own.
TaskTables = tuple[dict[str, Any], dict[str, Any]]


class Task(ABC):
    """One kind of trial: its parameters (an instance's fields) and everything asked of it (module docstring)."""

    #: Its name in the protocol file (``[task] kind = "…"``) and in the stored protocol.
    kind: ClassVar[str]
    #: Its name in words (``force regulation``).
    title: ClassVar[str]
    #: The metrics it produces, by name in the registry (:mod:`protocol.metrics`).
    metric_names: ClassVar[tuple[str, ...]]
    #: The fields of the file's ``[task]`` table it reads, ``kind`` aside.
    task_fields: ClassVar[frozenset[str]] = frozenset()
    #: The fields of the file's ``[trial]`` table that are its parameters (beside the cap, pause and cue).
    trial_fields: ClassVar[frozenset[str]] = frozenset()
    #: Its parameters' columns as the codebook describes them (one per name of :meth:`parameters`).
    described: ClassVar[tuple[Parameter, ...]] = ()
    #: The answers a trial's question allows (the participant screen's keys); () -- it asks none.
    answer_keys: ClassVar[tuple[str, ...]] = ()

    # -- its parameters ------------------------------------------------------------------------------------------
    @classmethod
    @abstractmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> Task:
        """Its parameters from the file's ``[task]`` and ``[trial]`` tables (their keys already checked against
        :attr:`task_fields` and :attr:`trial_fields`); a bad value is ``f.fail`` naming the field."""

    @abstractmethod
    def tables(self) -> TaskTables:
        """Its parameters as the file has them (stored with every session), :data:`TaskTables`."""

    def parameters(self) -> dict[str, Any]:
        """Its parameters by name, as the report's tables have them (columns of the sessions and trials tables)."""
        own, trial = self.tables()
        return {**own, **trial}

    def check_timing(self, f: Fields, timing: Timing) -> None:  # noqa: B027  # a task may have nothing to check
        """Refuse, in one ``f.fail`` line naming both fields, parameters that do not fit the protocol's timing."""

    @property
    def metrics(self) -> tuple[Metric, ...]:
        """The metrics it produces, in the registry's order."""
        return select(self.metric_names)

    # -- its target and its rule ---------------------------------------------------------------------------------
    @abstractmethod
    def target_n(self, trial: TrialCondition, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The target force at trial times ``t_s`` (s since the cue), N."""

    @abstractmethod
    def rule(self, trial: TrialCondition) -> TrialRule:
        """A fresh streaming rule for one trial (the live trial machine feeds it every sample)."""

    @abstractmethod
    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        """The offline form: a whole trial's samples (``t_ns`` since the cue) judged and measured.

        ``window`` is the error window (``"cue"`` or ``"first_contact"``, :mod:`protocol.tasks.window`); the
        verdict must be the streaming rule's on the same samples.
        """

    def trials_per_cell(self, designed: int) -> int:
        """The trials of each target × mode cell: the design's (``design.trials_per_cell``), unless the task's block
        has its own count (force discrimination: ``task.trials`` per reference)."""
        return designed

    # -- what it presents and asks -------------------------------------------------------------------------------
    def answer_by_s(self, max_trial_s: float) -> float:
        """When a trial's answer window closes, s since the cue (a task that asks: its own; default the cap)."""
        return max_trial_s

    def stimulus_procedure(self, seed: int, block: int, history: Sequence[Answered]) -> Procedure | None:
        """Its procedure for one block (the study's ``seed``, the block's number: its session), its state rebuilt
        from the block's answers so far; None -- the task presents no stimulus (the loop renders the sensor's
        force, Algorithm 1)."""
        return None

    def felt(self, t_s: npt.NDArray[np.float64], rendered_n: npt.NDArray[np.float64]) -> tuple[float, ...]:
        """What a trial presented, as a participant felt it: from the force rendered at trial times ``t_s`` (force
        discrimination: the mean over each interval's plateau); () -- it presents nothing."""
        return ()

    # -- what it shows and tells ---------------------------------------------------------------------------------
    @abstractmethod
    def cue_text(self, trial: TrialCondition) -> str:
        """The trial's target in the cue event's words (``GENTLE 0.6 N``)."""

    @abstractmethod
    def screen(self, trial: TrialCondition) -> TrialScreen:
        """What the participant screen and the experimenter's plot show of the trial."""

    @abstractmethod
    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        """What a simulated participant is told at the cue (``aid``: a training trial with the live force aid)."""

    # -- its words in the report ---------------------------------------------------------------------------------
    @abstractmethod
    def rule_words(self) -> str:
        """Its success rule in a few words, one session's (``band ±10%, hold 1 s``)."""

    @classmethod
    @abstractmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        """The report's sentences defining its rule, over the analysed sessions' tasks of this kind and their trial
        caps (sorted, distinct: several values are listed with ``/``)."""


def metrics_of(tasks: Iterable[Task]) -> tuple[Metric, ...]:
    """A study's metrics: those its tasks produce, in the registry's order (what its database, files, codebook,
    tests and report list; a study of the paper's task has the paper's)."""
    return select(name for task in tasks for name in task.metric_names)


def listed(values: Sequence[float], unit: str) -> str:
    """Distinct values as the report lists them: ``10 % / 15 %``."""
    return " / ".join(f"{v:g}{unit}" for v in sorted(set(values)))
