"""Force discrimination: a two-alternative forced-choice (2AFC) block on the haptic device (issue 43).

Force regulation asks a participant to *produce* a force; discrimination measures whether they can *tell* two forces
apart, and how far apart they must be (the just-noticeable difference, JND).  The paper's GENTLE band (±0.06 N at the
tip, ±0.026 N at the hand after the tanh law) is only 1–1.5 JNDs wide, so a trainee's JND bounds what regulation
training can reach (docs/discrimination.md).  Definitions:

* **reference** -- each ``[[targets]]`` entry is a reference: its tip force (GENTLE 0.6 N, FIRM 1.2 N) as the
  paper's tanh law renders it at the hand (:func:`pipeline.force.scaling.scale_magnitude`: 0.257 N, 0.509 N), so
  the JND is measured where the participant feels the band;
* **trial** -- two forces rendered one after the other on the device, the reference and the comparison
  ``reference + Δ`` in an order drawn from the seed (:func:`comparison_first`): after a ``lead_in_s`` at zero (the
  safety stage's fade-in), each interval rises over ``ramp_s``, holds for ``stimulus_s`` and falls over ``ramp_s``,
  with ``gap_s`` between them; then the participant answers which was stronger (key 1 or 2, or one of two buttons)
  within ``response_s``.  The force is *commanded*, rendered through the pipeline's safety stage (bounded by
  ``safety.f_max_n`` and the device's limit, slew-limited, faded in and out);
* **the next Δ** -- QUEST+ (Watson 2017; the ``questplus`` package), :class:`NextDelta`: a Bayesian posterior over
  a Weibull psychometric function's threshold, slope and lapse, updated after each answer, and the next Δ the one of
  least expected posterior entropy; its state is a function of the block's (Δ, answer) history only, so a resumed
  block rebuilds it from the stored trials;
* **the block ends** after ``trials`` trials per reference (the schedule's cells: references shuffled by the seed);
* **in a study** (``haptic-study run``, the GUI) the block is a session: at each cue its procedure (the seam's
  :meth:`~protocol.tasks.base.Task.stimulus_procedure`, rebuilt from the session's stored answers) gives the
  trial's :class:`~protocol.tasks.base.Stimulus` -- the two-interval command as a
  :class:`pipeline.core.force_program.ForceProgram` the loop renders through its safety stage -- and after the answer
  (key ``1`` or ``2``) scores it from the force the loop rendered over each plateau.

Validated when the file is read (one line naming the field, the value and what is allowed): the largest comparison
within the device's range (``safety.f_max_n``), ramps the safety stage's slew limit can render as shaped, a lead-in
at least the safety stage's fade-in, and a trial (lead-in, two intervals, gap, answer window) within the trial cap.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from pipeline.core.aim import TrialAim
from pipeline.core.force_program import ForceProgram
from pipeline.settings.tomlfields import Fields
from protocol.tasks.base import (
    Answered,
    Parameter,
    Stimulus,
    Task,
    TaskTables,
    Timing,
    TrialCondition,
    TrialScreen,
    listed,
)
from protocol.tasks.force_tracking import ProfileEnd
from protocol.tasks.window import TrialMetrics, capped, judged

__all__ = ["PROCEDURES", "DiscriminationProcedure", "ForceDiscrimination", "NextDelta", "comparison_first",
           "interval_means"]

#: How the next Δ is chosen: QUEST+ (the only one; a staircase would be a second entry).
PROCEDURES = ("questplus",)
#: QUEST+'s grid of Δ, as fractions of the reference: 40 log-spaced values from 0.5 % up to ``max_delta_fraction``.
_DELTA_POINTS = 40
_DELTA_MIN_FRACTION = 0.005
#: QUEST+'s parameter grid (Weibull on Δ/reference): thresholds 1–60 % of the reference (force Weber fractions are
#: 5–15 %: Jones 2000), slopes 1.5–4 (2AFC Weibull slopes of ~2–3.5: Wichmann & Hill 2001), lapses 0–4 %.
_THRESHOLDS = np.geomspace(0.01, 0.6, 30)
_SLOPES = (1.5, 2.0, 3.0, 4.0)
_LAPSES = (0.0, 0.02, 0.04)


def comparison_first(seed: int, participant: int, reference: int, trial: int) -> bool:
    """Whether a trial's comparison comes first: a fair coin drawn from the study's seed, the participant, the
    reference's index and the trial's index (so a re-run or a resumed block draws the same order)."""
    rng = np.random.default_rng([seed, participant, reference, trial, 0x2AFC])
    return bool(rng.random() < 0.5)


def interval_means(t_s: npt.NDArray[np.float64], force_n: npt.NDArray[np.float64],
                   spans: tuple[tuple[float, float], tuple[float, float]]) -> tuple[float, float]:
    """The mean force over each interval's plateau (``spans``: each plateau's start and end, s): what was felt."""
    out = []
    for a, b in spans:
        inside = (t_s >= a) & (t_s < b)
        out.append(float(np.mean(force_n[inside])) if np.any(inside) else math.nan)
    return out[0], out[1]


class NextDelta:
    """QUEST+ over one reference's trials: :meth:`next_n` the next Δ (N), :meth:`answered` after each answer.

    A Weibull ``γ + (1 − γ − λ)(1 − exp(−(x/α)^β))`` on ``x = Δ / reference`` with ``γ = 0.5`` (two alternatives), its
    ``α``, ``β`` and ``λ`` on the module's grids under a flat prior; the next Δ minimises the expected entropy of
    the posterior (Watson 2017).  The posterior depends only on the (Δ, correct) history, so replaying a stored
    block's answers rebuilds it exactly.
    """

    def __init__(self, reference_n: float, max_delta_fraction: float) -> None:
        import questplus  # a heavy import (xarray), only where a block runs

        self.reference_n = reference_n
        self.fractions = np.geomspace(_DELTA_MIN_FRACTION, max_delta_fraction, _DELTA_POINTS)
        self._q = questplus.QuestPlus(
            stim_domain={"intensity": self.fractions},
            param_domain={"threshold": _THRESHOLDS, "slope": np.asarray(_SLOPES), "lower_asymptote": 0.5,
                          "lapse_rate": np.asarray(_LAPSES)},
            outcome_domain={"response": ["Correct", "Incorrect"]}, func="weibull", stim_scale="linear",
            stim_selection_method="min_entropy")

    def next_n(self) -> float:
        """The next trial's Δ, N (a point of the grid, times the reference)."""
        return float(self._q.next_stim["intensity"]) * self.reference_n

    def answered(self, delta_n: float, correct: bool) -> None:
        """One answer to a trial of Δ ``delta_n`` (the nearest grid point: the one :meth:`next_n` gave)."""
        k = int(np.argmin(np.abs(self.fractions - delta_n / self.reference_n)))
        self._q.update(stim={"intensity": self.fractions[k]},
                       outcome={"response": "Correct" if correct else "Incorrect"})

    def threshold_fraction(self) -> float:
        """The posterior mean of the Weibull's threshold ``α`` (a fraction of the reference): a running estimate."""
        return float(self._q.param_estimate["threshold"])


@dataclass(frozen=True, slots=True)
class ForceDiscrimination(Task):
    """Which of two forces was stronger (module docstring: its fields are the file's ``[task]`` table's)."""

    trials: int = 50
    stimulus_s: float = 1.0
    ramp_s: float = 0.2
    gap_s: float = 0.8
    lead_in_s: float = 0.6
    response_s: float = 4.0
    max_delta_fraction: float = 0.5
    procedure: str = "questplus"

    kind: ClassVar[str] = "force_discrimination"
    answer_keys: ClassVar[tuple[str, ...]] = ("1", "2")
    title: ClassVar[str] = "force discrimination"
    #: No metric of a trial's force window: a trial's result is its answer (its Δ and whether it was right), fitted
    #: per participant and reference (:mod:`analysis.stats.psychometric`).
    metric_names: ClassVar[tuple[str, ...]] = ()
    task_fields: ClassVar[frozenset[str]] = frozenset({"trials", "stimulus_s", "ramp_s", "gap_s", "lead_in_s",
                                                       "response_s", "max_delta_fraction", "procedure"})
    described: ClassVar[tuple[Parameter, ...]] = (
        Parameter("trials", "trials per reference", "", "trials", 0),
        Parameter("stimulus_s", "each interval's plateau", "s", "stimulus (s)", 3),
        Parameter("ramp_s", "each interval's rise and fall", "s", "ramp (s)", 3),
        Parameter("gap_s", "between the two intervals", "s", "gap (s)", 3),
        Parameter("lead_in_s", "zero force before the first interval (the safety stage's fade-in)", "s",
                  "lead-in (s)", 3),
        Parameter("response_s", "the answer window after the second interval", "s", "answer (s)", 3),
        Parameter("max_delta_fraction", "the largest Δ, a fraction of the reference", "", "max Δ", 3),
        Parameter("procedure", "how the next Δ is chosen (questplus: QUEST+, Watson 2017)", "", "procedure", 0),
    )

    # -- its parameters ------------------------------------------------------------------------------------------
    @classmethod
    def from_tables(cls, f: Fields, task: Mapping[str, Any], trial: Mapping[str, Any]) -> ForceDiscrimination:
        d = cls()

        def seconds(key: str, lo: float, hi: float, lo_open: bool = True) -> float:
            return f.number(f"task.{key}", task.get(key, getattr(d, key)), lo=lo, hi=hi, lo_open=lo_open)

        return cls(
            trials=f.integer("task.trials", task.get("trials", d.trials), lo=10, hi=1000,
                             what="a whole number of trials per reference (a psychometric fit needs at least 10)"),
            stimulus_s=seconds("stimulus_s", 0.2, 5.0, lo_open=False),
            ramp_s=seconds("ramp_s", 0.0, 2.0),
            gap_s=seconds("gap_s", 0.2, 5.0, lo_open=False),
            lead_in_s=seconds("lead_in_s", 0.0, 10.0, lo_open=False),
            response_s=seconds("response_s", 0.5, 60.0, lo_open=False),
            max_delta_fraction=f.number("task.max_delta_fraction", task.get("max_delta_fraction",
                                                                            d.max_delta_fraction),
                                        lo=0.02, hi=2.0, lo_open=False),
            procedure=f.choice("task.procedure", task.get("procedure", d.procedure), PROCEDURES),
        )

    def tables(self) -> TaskTables:
        return {k: getattr(self, k) for k in sorted(self.task_fields)}, {}

    def check_timing(self, f: Fields, timing: Timing) -> None:
        """The largest comparison within ``safety.f_max_n``, ramps the slew limit renders as shaped, a lead-in at
        least the fade-in, and the trial within the cap (a training trial too)."""
        limit = timing.ramps.f_max_n
        for label, tip in zip(timing.targets, timing.target_forces_n, strict=False):
            top = self.reference_n(tip) * (1.0 + self.max_delta_fraction)
            if top > limit:
                raise f.fail("task.max_delta_fraction", self.max_delta_fraction,
                             f"{label}'s largest comparison would be {top:.3g} N at the hand: it must stay within "
                             f"safety.f_max_n = {limit:g} N (the device's force limit)")
            if self.ramp_s * timing.ramps.slew_n_per_s < top:
                raise f.fail("task.ramp_s", self.ramp_s,
                             f"must be at least {top / timing.ramps.slew_n_per_s:.3g} s: {label}'s largest "
                             f"comparison ({top:.3g} N) at safety.slew_n_per_s = {timing.ramps.slew_n_per_s:g} N/s")
        if self.lead_in_s < timing.ramps.ramp_in_s:
            raise f.fail("task.lead_in_s", self.lead_in_s, f"must be at least safety.ramp_in_s = "
                         f"{timing.ramps.ramp_in_s:g} s (the force must have faded in before the first interval)")
        need = self.trial_s()
        for fld, cap in (("trial.max_trial_s", timing.max_trial_s),
                         ("training.seconds_per_target_per_mode", timing.training_s)):
            if cap < need:
                raise f.fail(fld, cap, f"must be at least the discrimination trial's {need:g} s (task.lead_in_s + "
                             "2 × (2 × task.ramp_s + task.stimulus_s) + task.gap_s + task.response_s)")

    def trials_per_cell(self, designed: int) -> int:
        """A reference's trials are ``trials`` (the only mode is ON: a cell is a reference)."""
        return self.trials

    def answer_by_s(self, max_trial_s: float) -> float:
        """The answer window closes ``response_s`` after the question (within the cap: checked)."""
        return min(self.trial_s(), max_trial_s)

    def stimulus_procedure(self, seed: int, block: int, history: Sequence[Answered]) -> DiscriminationProcedure:
        """QUEST+ per reference, its posterior rebuilt from the block's answers so far."""
        return DiscriminationProcedure(self, seed, block, history)

    def felt(self, t_s: npt.NDArray[np.float64], rendered_n: npt.NDArray[np.float64]) -> tuple[float, ...]:
        """The mean force rendered over each interval's plateau, N."""
        return interval_means(t_s, rendered_n, self.plateaus())

    def program(self, first_n: float, second_n: float) -> ForceProgram:
        """The two-interval command as knots (:meth:`stimulus_n`'s trapezoids, exactly: they are linear)."""
        (a1, b1), (a2, b2) = self.plateaus()
        r = self.ramp_s
        return ForceProgram(((0.0, 0.0), (a1 - r, 0.0), (a1, first_n), (b1, first_n), (b1 + r, 0.0),
                             (a2 - r, 0.0), (a2, second_n), (b2, second_n), (b2 + r, 0.0)))

    # -- the stimulus ------------------------------------------------------------------------------------------
    @staticmethod
    def reference_n(tip_force_n: float) -> float:
        """A reference at the hand: a target's tip force as the paper's tanh law renders it (3 N · tanh(F/7 N))."""
        # (deferred: the law is compiled code, and reading a protocol file needs no compiler)
        from pipeline.force.scaling import scale_magnitude

        return scale_magnitude(tip_force_n)

    def interval_s(self) -> float:
        """One interval: rise, plateau, fall, s."""
        return 2.0 * self.ramp_s + self.stimulus_s

    def answer_at_s(self) -> float:
        """When the answer is asked (the second interval's end), s since the cue."""
        return self.lead_in_s + 2.0 * self.interval_s() + self.gap_s

    def trial_s(self) -> float:
        """A whole trial: the two intervals and the answer window, s."""
        return self.answer_at_s() + self.response_s

    def plateaus(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Each interval's plateau (start, end), s since the cue: where the felt force is taken."""
        a = self.lead_in_s + self.ramp_s
        b = a + self.interval_s() + self.gap_s
        return (a, a + self.stimulus_s), (b, b + self.stimulus_s)

    def stimulus_n(self, first_n: float, second_n: float, t_s: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The commanded force at trial times ``t_s``: two trapezoids of ``first_n`` and ``second_n``, N."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.zeros_like(t)
        for (a, b), level in zip(self.plateaus(), (first_n, second_n), strict=True):
            rise = np.clip((t - (a - self.ramp_s)) / self.ramp_s, 0.0, 1.0) if self.ramp_s > 0 else (t >= a) * 1.0
            fall = np.clip(((b + self.ramp_s) - t) / self.ramp_s, 0.0, 1.0) if self.ramp_s > 0 else (t < b) * 1.0
            out += level * np.minimum(rise, fall)
        return out

    def next_delta(self, reference_n: float) -> NextDelta:
        """A fresh QUEST+ for one reference's trials."""
        return NextDelta(reference_n, self.max_delta_fraction)

    # -- the seam: a discrimination trial seen as a force over trial time -------------------------------------------
    def target_n(self, trial: TrialCondition, t_s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The reference's envelope (both intervals at the reference: the trial's Δ is chosen by the block)."""
        ref = self.reference_n(trial.target_force_n)
        return self.stimulus_n(ref, ref, t_s)

    def rule(self, trial: TrialCondition) -> ProfileEnd:
        """The trial completes when the second interval has ended and the answer is asked."""
        return ProfileEnd(int(round(self.answer_at_s() * 1e9)))

    def judge(self, t_ns: npt.ArrayLike, force_n: npt.ArrayLike, trial: TrialCondition, *, max_trial_s: float,
              window: str = "cue", sample_period_s: float = 0.001) -> TrialMetrics:
        t, f = capped(t_ns, force_n, max_trial_s, window)
        reached = np.flatnonzero(t >= int(round(self.answer_at_s() * 1e9)))
        done = int(reached[0]) if len(reached) else None
        return judged(t, f, done, target_n=lambda times: self.target_n(trial, times / 1e9),
                      on_target=lambda force: np.zeros(len(force), dtype=np.bool_),  # no band: the answer counts
                      max_trial_s=max_trial_s, window=window, sample_period_s=sample_period_s, metrics=self.metrics)

    def cue_text(self, trial: TrialCondition) -> str:
        return f"{trial.target_label} compare around {self.reference_n(trial.target_force_n):.3f} N"

    def screen(self, trial: TrialCondition) -> TrialScreen:
        ref = self.reference_n(trial.target_force_n)
        (a1, b1), (a2, b2) = self.plateaus()
        r = self.ramp_s
        return TrialScreen(cue_word="Feel the two forces", band=None, band_label=f"{trial.target_label}: "
                           f"reference {ref:.3f} N at the hand", band_legend="",
                           spans=((a1 - r, b1 + r, "first"), (a2 - r, b2 + r, "second")),
                           question="Which was stronger?", answers=(("1", "first"), ("2", "second")))

    def aim(self, trial: TrialCondition, aid: bool) -> TrialAim:
        """The stylus held still (the device moves the hand): a zero target; the answer is the observer's."""
        return TrialAim.constant(0.0, trial.haptic_mode == "on", gauge=False, practice=aid)

    def rule_words(self) -> str:
        return (f"2AFC, {self.stimulus_s:g} s intervals {self.gap_s:g} s apart, {self.trials} trials per reference, "
                "QUEST+")

    @classmethod
    def methods(cls, tasks: Sequence[Task], caps: Sequence[float]) -> str:
        mine = [t for t in tasks if isinstance(t, ForceDiscrimination)]
        return (f"Each trial rendered two forces on the haptic device, the reference and the reference + Δ in an "
                f"order drawn from the seed, each held {listed([t.stimulus_s for t in mine], ' s')} after a ramp of "
                f"{listed([t.ramp_s for t in mine], ' s')}, {listed([t.gap_s for t in mine], ' s')} apart; the "
                "participant answered which was stronger (two-alternative forced choice). QUEST+ (Watson 2017) chose "
                f"each next Δ; {listed([t.trials for t in mine], '')} trials per reference. The JND is the Δ at d′ = 1 "
                "(76 % correct without lapses) of a cumulative Gaussian with a lapse rate fitted by maximum "
                "likelihood, its 95 % interval from the profile likelihood; the Weber fraction is JND / reference.")


class DiscriminationProcedure:
    """One block's QUEST+ per reference (by target label), each trial's order from the seed, each answer scored
    from the rendered force (the seam's :class:`~protocol.tasks.base.Procedure`)."""

    def __init__(self, task: ForceDiscrimination, seed: int, block: int, history: Sequence[Answered]) -> None:
        self.task, self.seed, self.block = task, seed, block
        self._quests: dict[str, NextDelta] = {}
        for done in history:  # the posterior is a function of the (Δ, correct) history only
            if done.answer is not None:
                self._quest(done.target_label, float(done.values["reference_n"])).answered(
                    float(done.values["delta_n"]), bool(done.values["correct"]))

    def _quest(self, label: str, reference_n: float) -> NextDelta:
        if label not in self._quests:
            self._quests[label] = self.task.next_delta(reference_n)
        return self._quests[label]

    def next(self, trial: TrialCondition, index: int) -> Stimulus:
        task = self.task
        ref = task.reference_n(trial.target_force_n)
        delta = self._quest(trial.target_label, ref).next_n()
        first = comparison_first(self.seed, self.block, 0, index)
        program = task.program(ref + delta if first else ref, ref if first else ref + delta)
        return Stimulus(program, {"reference_n": ref, "delta_n": delta, "comparison_first": float(first)})

    def answered(self, trial: TrialCondition, stimulus: Stimulus, answer: str | None,
                 t_s: npt.NDArray[np.float64], rendered_n: npt.NDArray[np.float64]) -> dict[str, float]:
        v = stimulus.values
        felt_first, felt_second = self.task.felt(t_s, rendered_n)
        out = {**v, "felt_first_n": felt_first, "felt_second_n": felt_second}
        if answer is not None:
            correct = (answer == "1") == bool(v["comparison_first"])
            out["correct"] = float(correct)
            self._quest(trial.target_label, float(v["reference_n"])).answered(float(v["delta_n"]), correct)
        return out
