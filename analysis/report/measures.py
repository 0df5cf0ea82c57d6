"""The report's view of the metric registry: which figure draws which measures, and the words its sentences use.

Every list of measures the page shows or says -- the bar figures, the captions' "RMSE and Max AE", the methods'
"means over trials", the secondary measures and why their p is not adjusted -- is made here from the study's
metrics (its tasks', :attr:`analysis.reading.load.StudyData.metrics`, defined in :mod:`protocol.metrics`), so a
metric defined there and named by a task appears on the page of that task's studies without an edit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from protocol.metrics import Metric, Role, family_word, primary, split_unit, windowed

__all__ = ["FigureGroup", "figure_groups", "listed", "mean_words", "secondary", "secondary_note", "windowed_words"]

#: The headings of the report's bar figures, by figure key (another figure is headed by its measures).
_HEADINGS = {"success_rate": "Success rate", "tct": "Task completion time", "errors": "Force errors"}


class FigureGroup(NamedTuple):
    """A bar figure of the report: its key (``errors``), its file name (``rmse_max_ae``) and its metrics."""

    key: str
    file: str
    metrics: tuple[Metric, ...]

    @property
    def heading(self) -> str:
        """The figure's heading on the page."""
        said = listed([m.short for m in self.metrics])
        return _HEADINGS.get(self.key) or said[:1].upper() + said[1:]

    @property
    def alt(self) -> str:
        """The figure in words, for a reader who cannot see it."""
        return f"{listed([m.short for m in self.metrics])} per target and overall"


def figure_groups(metrics: Sequence[Metric]) -> list[FigureGroup]:
    """The report's bar figures of a study's ``metrics``, in the registry's order, each with the metrics that name it
    (:attr:`Metric.figure`)."""
    groups: dict[str, list[Metric]] = {}
    for m in metrics:
        if m.figure is not None:
            groups.setdefault(m.figure, []).append(m)
    return [FigureGroup(key, "_".join(split_unit(m.participant)[0] for m in ms), tuple(ms))
            for key, ms in groups.items()]


def listed(words: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def windowed_words(metrics: Sequence[Metric]) -> str:
    """The study's measures taken over the error window, in words: ``RMSE and Max AE``."""
    return listed([m.short for m in windowed(metrics)])


def mean_words(metrics: Sequence[Metric]) -> str:
    """The measures averaged over a participant's trials as they are (not a rate, not under the TCT policy)."""
    return listed([m.short for m in metrics if not m.boolean and not m.success_only])


def secondary(metrics: Sequence[Metric]) -> tuple[Metric, ...]:
    """The study's secondary measures: tested, each with its own p, outside Holm's family."""
    return tuple(m for m in metrics if m.role is Role.SECONDARY)


def secondary_note(metrics: Sequence[Metric]) -> str:
    """Why a secondary measure's p is not adjusted, beside the number it changes ("" when there is none)."""
    names = [m.short for m in secondary(metrics)]
    if not names:
        return ""
    one = len(names) == 1
    said = listed(names)
    return (f"{said[:1].upper()}{said[1:]} {'is a secondary measure' if one else 'are secondary measures'}: tested "
            f"like the others, but outside Holm's family of the {family_word(metrics)} primary measures "
            f"({listed([m.short for m in primary(metrics)])}), so {'its' if one else 'their'} p is not adjusted and p "
            "(Holm) is empty; a measure beside the study's outcome measures must not change their correction.")
