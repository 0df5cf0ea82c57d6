"""Which task a planning command works on, in a study of several parts (:mod:`protocol.study.parts`).

``power``, ``sweep`` and ``discrimination`` plan or measure *one* task: in a study of several parts the user names
the part with ``--part NAME`` (its task, targets, design, trial and training as the part's protocol gives them, the
study's covariates and groups; in a pilot with a schedule of visits, ``VISIT-PART`` as its report names it: a part
recurs across visits); without ``--part`` such a study is refused, naming its parts.  A training part is free
practice, analysed by nothing, and so is refused too.  Every refusal is one :class:`CliError` line, before any
work.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from typing import Any

from study_app.cli.error import CliError

__all__ = ["PART_HELP", "compared_measures", "one_part", "pilot_part"]

#: The ``--part`` option's help (one wording for every command that has it).
PART_HELP = ("in a protocol or pilot of several parts ([[parts]]): the part whose task this command works on (an "
             "experiment part, by its name in the file; of a pilot with [[visits]], VISIT-PART as its report names it)")


def one_part(protocol: Any, path: object, part: str | None, command: str) -> Any:
    """The protocol ``command`` works on: ``protocol`` itself (a study of one task), or its part ``part`` as a
    protocol of one task (the part's own protocol, its place in a participant's order dropped: the command plans
    the task, not the sequence).  One line for a study of several parts without ``--part``, a name it does not
    have, a training part, or ``--part`` with a study of one task."""
    names: tuple[str, ...] = protocol.part_names
    if part is None:
        if names:
            raise CliError(f"--protocol = {path!r}: a study of several parts ({', '.join(names)}); {command} works on "
                           "one task: choose its part with --part NAME")
        return protocol
    if not names:
        which = f"the protocol {path!r}" if path is not None else "the default protocol (the paper's study)"
        raise CliError(f"--part = {part!r}: {which} is a study of one task (no [[parts]]); leave --part out")
    chosen = {p.part.name: p for p in protocol.parts if p.part is not None}.get(part)
    if chosen is None:
        raise CliError(f"--part = {part!r}: not a part of {path!r}; its parts are {', '.join(names)}")
    _experiment(part, chosen.part.session, _experiment_names(protocol), command)
    return dataclasses.replace(chosen, part=None, name=f"{protocol.name} (part {part})")


def pilot_part(databases: Sequence[str | os.PathLike[str]], part: str | None, command: str) -> None:
    """Refuse (one line) a pilot of several parts without ``--part``, a part it does not hold, a training part, or
    ``--part`` with a pilot of one task.  Reads the databases' stored protocols only."""
    from analysis.report.plan_report import entry_key, study_plan

    plan = study_plan(databases)
    where = ", ".join(str(d) for d in databases)
    sessions = {entry_key(e): e.place.session for e in plan}  # VISIT-PART in a study with visits, as the report
    names = list(sessions)
    if part is None:
        if plan:
            raise CliError(f"--db = {where!r}: a study of several parts ({', '.join(names)}); {command} works on one "
                           "task: choose its part with --part NAME")
        return
    if not plan:
        raise CliError(f"--part = {part!r}: the pilot {where!r} is a study of one task (no parts); leave --part out")
    if part not in sessions:
        raise CliError(f"--part = {part!r}: the pilot {where!r} holds no session of it; its parts are "
                       f"{', '.join(names)}")
    _experiment(part, sessions[part], [n for n, s in sessions.items() if s == "experiment"], command)
    from protocol.tasks.registry import task_class

    compared_measures(task_class(next(e.task for e in plan if entry_key(e) == part)), f"--part = {part!r}", command)


def compared_measures(task: Any, which: str, command: str) -> None:
    """Refuse (one line) a task that produces no per-trial measure: ``command`` compares the modes on them (a
    force-discrimination block's result is a fitted JND per participant, which ``report`` and ``discrimination``
    give)."""
    if not task.metric_names:
        raise CliError(f"{which}: its task ({task.kind}) produces no per-trial measure, and {command} compares the "
                       "modes on those; its result per participant is in `haptic-study report` (and `haptic-study "
                       "discrimination` simulates it)")


def _experiment_names(protocol: Any) -> list[str]:
    return [p.part.name for p in protocol.parts if p.part is not None and p.part.session == "experiment"]


def _experiment(part: str, session: str, experiments: Sequence[str], command: str) -> None:
    if session != "experiment":
        raise CliError(f"--part = {part!r}: a {session} part (free practice, analysed by nothing); {command} works on "
                       f"an experiment part: {', '.join(experiments)}")
