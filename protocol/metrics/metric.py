"""What a trial metric is: its definition (:class:`Metric`) and what it is computed from (:class:`TrialWindow`).

A metric is computed from one trial's window -- its samples, the task's target at each of them, the task's
verdict and the error window the analysis chose -- by a pure function; the live trial machine and the offline
analysis both build the window and call the same function, so the number stored during the session and the
number the report recomputes cannot disagree.  Everything else about a metric (its unit, its words in the
codebook, which way is better, whether the report tests it, how the CSV files round it) is data on the
:class:`Metric`, which every consumer reads instead of listing metrics of its own.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

import numpy as np
import numpy.typing as npt

__all__ = ["UNIT_TOKENS", "Metric", "MetricValue", "Role", "TrialWindow", "exported_name", "split_unit"]

#: A metric's value for one trial: a yes/no outcome, a number, or None where it is undefined (TCT of a failure).
MetricValue = bool | float | None

#: The unit parts of a name, as the database and the analysis spell them (``_n`` newtons, ``_s`` seconds) and as
#: the exported files spell them (``_N``): a name ends with its unit.
UNIT_TOKENS: dict[str, str] = {"n": "N", "s": "s", "ms": "ms"}


def split_unit(name: str) -> tuple[str, tuple[str, ...]]:
    """A name's stem and its unit parts: ``abs_impulse_n_s`` → (``abs_impulse``, (``n``, ``s``)).

    Counts begin with ``n_`` (``n_trials``), so a trailing ``_n`` is always newtons.
    """
    parts = name.split("_")
    k = len(parts)
    while k > 1 and parts[k - 1] in UNIT_TOKENS:
        k -= 1
    return "_".join(parts[:k]), tuple(parts[k:])


def exported_name(name: str) -> str:
    """A name as the exported files spell it: the newton suffix ``_N`` (``rmse_n`` → ``rmse_N``; ``tct_s`` stays)."""
    stem, units = split_unit(name)
    return "_".join((stem, *(UNIT_TOKENS[u] for u in units)))


class Role(StrEnum):
    """What the report does with a metric."""

    #: One of the paper's outcome measures: tested ON vs OFF, in the family Holm's correction runs across.
    PRIMARY = "primary"
    #: Tested ON vs OFF and reported with its own p-value, outside that family (a measure added after the
    #: paper's must not change the correction of its primary outcomes).
    SECONDARY = "secondary"
    #: Aggregated per participant and reported, not tested.
    DESCRIPTIVE = "descriptive"


@dataclass(frozen=True, slots=True)
class TrialWindow:
    """One trial as its metrics see it: the samples of its window and what the task made of them (a plain record,
    filled by the task's window, :func:`protocol.tasks.window.judged`, live and offline alike).

    Attributes
    ----------
    t_ns
        Sample times since the cue, integer ns, from the cue (t = 0) to the trial end, both included.
    force_n
        The task force at those times, N (NaN where it was not measured: out of band, left out of the errors).
    target_n
        The task's target at those times, N (the force-regulation task's is a constant F*).
    on_target
        Whether each sample is within the task's success region (the force-regulation task's band around F*).
    completed
        The task's success rule was met within the window (the hold completed).
    end_s
        The trial end, s since the cue: the completing sample on success, else the trial cap.
    error_n
        F − target over the error window -- from the cue, or from first contact (none without contact) -- at its
        samples with a finite force, in time order, N.
    error_t_s
        The times of :attr:`error_n`, s since the cue (ns / 1e9: the double nearest the exact time).
    sample_period_s
        The nominal sample period, s.
    contact_s
        The first sample in contact (task force above the task's contact threshold), s since the cue; None
        without contact.
    reached_s
        The first sample at which the force reached the task's band from below (at or above its lower edge: in the
        band, or through it in one sample), s since the cue; None when it never did.
    """

    t_ns: npt.NDArray[np.int64]
    force_n: npt.NDArray[np.float64]
    target_n: npt.NDArray[np.float64]
    on_target: npt.NDArray[np.bool_]
    completed: bool
    end_s: float
    error_n: npt.NDArray[np.float64]
    error_t_s: npt.NDArray[np.float64]
    sample_period_s: float = 0.001
    contact_s: float | None = None
    reached_s: float | None = None


@dataclass(frozen=True)
class Metric:
    """One trial metric, defined once.

    Attributes
    ----------
    name
        Its name with its unit, as the database's ``trials`` column and the analysis tables have it (``rmse_n``).
    unit
        Its unit in the codebook (``"N"``, ``"s"``, ``"N·s"``; ``""`` for a yes/no outcome).
    label
        The measure's heading in tables and figures, with its unit (``"RMSE (N)"``; a yes/no outcome's is its
        rate's, ``"success rate"``).
    description
        What it is for one trial, in the codebook's words.
    compute
        Its value from a trial's window (:class:`TrialWindow`): the one definition, live and offline.
    better
        Which way is better: ``"higher"``, ``"lower"`` or ``"one"`` (nearer 1: a gain).
    role
        Whether the report tests it, and in which family (:class:`Role`).
    decimals
        Its rounding in the CSV files (a yes/no outcome's rate: 4 decimals).
    windowed
        Taken over the error window (from the cue, or from first contact), as RMSE and Max AE are.
    boolean
        A yes/no outcome: stored as the trial's outcome, not a column of its own, and aggregated as a rate
        (``n_success`` and ``success_rate``).
    success_only
        Defined for a successful trial only (TCT): stored only with a success, averaged per participant under the
        analysis's TCT policy (successful trials only, or failures counted at the cap) with the count of trials that
        entered the mean.
    figure
        The report's figure it is drawn in, with the other metrics of that figure (None: none).
    mean_description
        What the per-participant value is, in the codebook's words (default: ``mean <label> over the trials``).
    count_description, count_label
        A yes/no outcome's count of successes, in the codebook's words and as a heading.
    values
        The range the per-participant value can take (a sweep's intervals are clipped to it).
    in_database
        Computed live and kept in the ``trials`` table (the default); False: a measure the analysis computes from
        the recording (and the database-less simulated runner from its trials), which adds no column to a study
        database -- the phases of the speed–accuracy trade (rise time, RMSE after band entry).
    """

    name: str
    unit: str
    label: str
    description: str
    compute: Callable[[TrialWindow], MetricValue]
    better: Literal["higher", "lower", "one"]
    role: Role
    decimals: int
    windowed: bool = False
    boolean: bool = False
    success_only: bool = False
    figure: str | None = None
    mean_description: str = ""
    count_description: str = ""
    count_label: str = ""
    values: tuple[float, float] = (0.0, math.inf)
    in_database: bool = True

    def __post_init__(self) -> None:
        if self.better not in ("higher", "lower", "one"):
            raise ValueError(f"{self.name}: better = {self.better!r}: allowed are 'higher', 'lower' and 'one'")
        if self.boolean and self.success_only:
            raise ValueError(f"{self.name}: a yes/no outcome is defined for every trial (success_only is for TCT)")

    # -- its names, derived once from its name: the exported files' spelling and the per-participant columns ------
    @property
    def stem(self) -> str:
        """The name without its unit: ``rmse_n`` → ``rmse``."""
        return split_unit(self.name)[0]

    @property
    def exported(self) -> str:
        """Its name in the CSV files: the newton suffix spelled ``_N`` (``rmse_n`` → ``rmse_N``)."""
        return exported_name(self.name)

    @property
    def participant(self) -> str:
        """Its per-participant column (analysis' name): a yes/no outcome's rate (``success_rate``), else its name."""
        return f"{self.name}_rate" if self.boolean else self.name

    @property
    def participant_exported(self) -> str:
        """Its per-participant column as the CSV files name it."""
        return f"{self.name}_rate" if self.boolean else self.exported

    @property
    def count(self) -> str | None:
        """The per-participant count beside it: a yes/no outcome's successes (``n_success``), the trials that entered
        a success-only mean (``n_tct``); None for the others."""
        return f"n_{self.name}" if self.boolean else f"n_{self.stem}" if self.success_only else None

    @property
    def censored(self) -> str | None:
        """A success-only metric's trial column with a failed trial counted as the trial cap (``tct_censored_s``)."""
        if not self.success_only:
            return None
        stem, units = split_unit(self.name)
        return "_".join((stem, "censored", *units))

    @property
    def short(self) -> str:
        """The label without its unit: ``RMSE (N)`` → ``RMSE``."""
        return self.label.split(" (")[0]

    @property
    def summary_label(self) -> str:
        """The label of a per-mode summary: a success-only metric says whose trials (``TCT, successful trials (s)``)."""
        if not self.success_only:
            return self.label
        head, _, unit = self.label.partition(" (")
        return f"{head}, successful trials ({unit}"

    @property
    def participant_description(self) -> str:
        """What the per-participant value is, in the codebook's words."""
        return self.mean_description or f"mean {self.short} over the trials"

    @property
    def tested(self) -> bool:
        """The report tests it ON vs OFF (primary or secondary)."""
        return self.role is not Role.DESCRIPTIVE

    @property
    def stored(self) -> bool:
        """It has a column of its own in the ``trials`` table (a yes/no outcome is the trial's ``outcome``; an
        analysis measure, :attr:`in_database` False, has none)."""
        return not self.boolean and self.in_database
