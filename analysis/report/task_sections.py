"""Each task's own section of the report, found from the task's kind (the report's per-task seam, issue 43).

The report's core (:mod:`analysis.report.report`) is what every task with trial metrics shares: the metrics
recomputed from the samples, one value per participant per mode, the tests ON vs OFF, the figures, the record and
the methods -- asked of the task and the metric registry, with no edit for a task.  What a task asks beyond that
(force tracking: how the force follows a moving target; force discrimination, which has no trial metric: a fit per
participant) is its **section**: one module ``analysis/report/section_KIND.py`` that defines ``SECTION``, a
:class:`TaskSection` naming the kinds it reports (:attr:`protocol.tasks.base.Task.kind`).  The file names are the
registry: every ``section_*`` module of this folder is a section, found by its kinds (:func:`section_for`), so a new
task's section is its one file, with no line to add anywhere else (``tests/analysis/test_report_sections.py``
checks that every one is a section of a known kind, and that no kind has two); :func:`register` adds one for a
``with`` block (a test's, a lab's own).  (A file prefix, not a sub-folder: a section uses the report's parts --
:mod:`analysis.report.html_parts`, :mod:`analysis.report.measures` -- and the report's core uses the sections, so
they are one floor.)

A study is read whole and its analysed experiment sessions grouped by their task's kind (:func:`study_parts`), in
the order the kinds first appear: each section is given its own task's sessions only (:class:`SectionInput`), so a
study of several tasks gets a section per task, each from its own sessions.  A section's result
(:class:`SectionOutput`) is a titled piece of the page, the tables the report writes with its codebook, the files
it wrote itself, and the lines the ``report`` command prints.  A study whose tasks have no trial metric has no core:
its page is its sections (:func:`sections_page`).
"""

from __future__ import annotations

import functools
import html
import importlib
import pkgutil
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import pandas as pd

from analysis.report.html_parts import part_banner, part_title

if TYPE_CHECKING:
    from analysis.reading.load import StudyData
    from protocol.tasks.base import Task

__all__ = [
    "PREFIX",
    "SectionInput",
    "SectionOutput",
    "TaskSection",
    "register",
    "section_for",
    "section_modules",
    "sections_page",
    "study_parts",
]

#: A section's module name begins so (``section_tracking``).
PREFIX = "section_"


@dataclass(frozen=True, slots=True)
class SectionInput:
    """What a section is given: the study as read, its task's analysed experiment sessions, and the core's results
    for those sessions where the study has trial metrics."""

    #: The whole study as read (:func:`analysis.reading.load.load_study`): its databases, sessions and tasks.
    study: StudyData
    #: The task kind the section reports here.
    kind: str
    #: The rows of ``study.sessions`` of this task's analysed experiment sessions.
    sessions: pd.DataFrame
    #: The core's recomputed trials of those sessions, each with its session's trial cap (``max_trial_s``); no rows
    #: when the study has no trial metrics.
    trials: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: The core's tests ON vs OFF (``stats.csv``'s rows, unrounded); no rows when the study has no trial metrics.
    stats: pd.DataFrame = field(default_factory=pd.DataFrame)
    zero_method: str = "wilcox"
    confidence: float = 0.95

    @property
    def keys(self) -> frozenset[tuple[str, int]]:
        """The sessions as (database, session id)."""
        return frozenset(zip(self.sessions["database"].astype(str), self.sessions["session_id"].astype(int),
                             strict=True))

    @property
    def tasks(self) -> list[Task]:
        """The sessions' tasks, one per session (a study's sessions of one kind may differ in parameters)."""
        return [self.study.task_of(db, sid) for db, sid in sorted(self.keys)]


@dataclass(frozen=True, slots=True)
class SectionOutput:
    """A section's part of the report."""

    #: Its heading on the page.
    title: str
    #: Its HTML, below the heading ("": the section has nothing to say for this study, and is left out).
    body: str
    #: CSV tables the report writes beside its own, described in its ``codebook.csv`` (rounded as the codebook
    #: says; :mod:`analysis.reading.codebook` must know their columns).
    tables: Mapping[str, pd.DataFrame] = field(default_factory=dict)
    #: The files the section wrote itself into the report's folder (its figures, tables with a codebook of their
    #: own), relative to it.
    files: tuple[str, ...] = ()
    #: What the ``report`` command prints of it, a line each.
    lines: tuple[str, ...] = ()

    def html(self, level: int = 2) -> str:
        """Its heading (at ``level``) and body ("" when it has nothing to say)."""
        return f"<h{level}>{html.escape(self.title)}</h{level}>\n{self.body}" if self.body else ""


class TaskSection(Protocol):
    """A task's section: the kinds it reports, and how it builds its part of the report."""

    #: The task kinds (:attr:`protocol.tasks.base.Task.kind`) whose sessions it reports.
    kinds: tuple[str, ...]

    def build(self, given: SectionInput, folder: Path) -> SectionOutput:
        """The section for ``given``'s sessions; figures and files of its own written into ``folder`` (the
        report's temporary folder; ``folder / "figures"`` exists).  A study it cannot report raises
        :class:`analysis.reading.errors.AnalysisError` naming why."""
        ...


def section_modules() -> list[str]:
    """The sections' modules: every ``section_*`` module of this folder, by name."""
    folder = str(Path(__file__).resolve().parent)
    package = __name__.rpartition(".")[0]
    return sorted(f"{package}.{i.name}" for i in pkgutil.iter_modules([folder]) if i.name.startswith(PREFIX))


@functools.cache
def _found() -> dict[str, TaskSection]:
    """Every section by kind (each ``section_*`` module's ``SECTION``)."""
    found: dict[str, TaskSection] = {}
    owner: dict[str, str] = {}
    for name in section_modules():
        section: TaskSection = importlib.import_module(name).SECTION  # every section_* module is a section
        for kind in section.kinds:
            if kind in found:
                raise RuntimeError(f"task kind {kind!r} has two report sections ({owner[kind]} and {name})")
            found[kind], owner[kind] = section, name
    return found


_ADDED: dict[str, TaskSection] = {}


def section_for(kind: str) -> TaskSection | None:
    """The section of a task kind (None: the kind's report is the core's alone)."""
    return _ADDED.get(kind) or _found().get(kind)


@contextmanager
def register(section: TaskSection) -> Iterator[TaskSection]:
    """Make ``section`` the section of its kinds while the ``with`` block runs (a kind with a section is refused)."""
    taken = [k for k in section.kinds if section_for(k) is not None]
    if taken:
        raise ValueError(f"task kind {taken[0]!r} has a report section already")
    _ADDED.update(dict.fromkeys(section.kinds, section))
    try:
        yield section
    finally:
        for k in section.kinds:
            del _ADDED[k]


def study_parts(study: StudyData) -> list[tuple[str, pd.DataFrame]]:
    """The study's analysed experiment sessions grouped by their task's kind, in the order the kinds first appear
    (by database, then session id): (kind, its rows of ``study.sessions``)."""
    sessions = study.sessions[(study.sessions["kind"] == "experiment") & study.sessions["analysed"].astype(bool)]
    kinds = [study.task_of(db, sid).kind for db, sid in zip(sessions["database"], sessions["session_id"],
                                                             strict=True)]
    return [(kind, sessions[[k == kind for k in kinds]]) for kind in dict.fromkeys(kinds)]


def sections_page(outputs: Sequence[SectionOutput], study: StudyData | None = None) -> str:
    """report.html of a study without trial metrics: its sections (one: its title is the page's), under its part's
    banner in a part's report (``study``'s part; None: no part)."""
    shown = [o for o in outputs if o.body]
    head, part = (part_banner(study), study.part) if study is not None else ("", None)
    if len(shown) == 1:
        title = part_title(part, shown[0].title)
        return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title></head><body>{head}"
                f"{shown[0].html(1)}</body></html>")
    parts = "".join(o.html(2) for o in shown)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{part_title(part, 'haptic-study report')}"
            f"</title></head><body>{head}<h1>Haptic feedback study: report</h1>{parts}</body></html>")
