"""The tasks a protocol file may name, by kind: one line each, and how a protocol's ``[task]`` table is read.

A protocol file without a ``[task]`` table is the paper's force-regulation task (so every protocol file written
before the tasks reads as it always did, and a stored session's protocol too); ``[task] kind = "…"`` names another.
A new task is its module in this folder and its line in :data:`TASKS`; :func:`register` adds one at run time (a
test's toy task, a lab's own).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

from pipeline.settings.tomlfields import Fields
from protocol.tasks.base import Task
from protocol.tasks.force_discrimination import ForceDiscrimination
from protocol.tasks.force_regulation import ForceRegulation
from protocol.tasks.force_tracking import ForceTracking

__all__ = ["DEFAULT_KIND", "TASKS", "kinds", "named", "read_task", "register", "stored_task", "task_class",
           "task_tables"]

#: The task of a protocol that names none: the paper's.
DEFAULT_KIND = ForceRegulation.kind

#: Every task by its kind.
TASKS: dict[str, type[Task]] = {cls.kind: cls for cls in (ForceRegulation, ForceTracking, ForceDiscrimination)}


def kinds() -> tuple[str, ...]:
    """The kinds a protocol file may name, in registration order."""
    return tuple(TASKS)


def task_class(kind: str) -> type[Task]:
    """The task of that kind (:class:`KeyError` naming the known ones otherwise)."""
    try:
        return TASKS[kind]
    except KeyError:
        raise KeyError(f"no task {kind!r}: the tasks are {', '.join(TASKS)}") from None


@contextmanager
def register(cls: type[Task]) -> Iterator[type[Task]]:
    """Make a task nameable in protocol files while the ``with`` block runs (a kind already taken is refused)."""
    if cls.kind in TASKS:
        raise ValueError(f"task kind {cls.kind!r} is taken (by {TASKS[cls.kind].__qualname__})")
    TASKS[cls.kind] = cls
    try:
        yield cls
    finally:
        del TASKS[cls.kind]


def named(f: Fields, top: Mapping[str, Any]) -> tuple[type[Task], dict[str, Any]]:
    """The task a protocol names (its ``[task]`` table's ``kind``; none: :data:`DEFAULT_KIND`) and its parameters in
    that table, the table's fields checked against the task's (another task's field is refused, naming this one's).
    Which fields of ``[trial]`` are its own is :attr:`Task.trial_fields`."""
    table = top.get("task", {})
    if not isinstance(table, dict):
        raise f.fail("task", table, "must be a table")
    cls = TASKS[f.choice("task.kind", table.get("kind", DEFAULT_KIND), kinds())]
    f.table("task", table, {"kind", *cls.task_fields})
    return cls, {k: v for k, v in table.items() if k != "kind"}


def read_task(f: Fields, top: Mapping[str, Any], trial: Mapping[str, Any]) -> Task:
    """The task of a protocol (parsed TOML, or a stored session's JSON) with its parameters validated."""
    cls, own = named(f, top)
    return cls.from_tables(f, own, trial)


def stored_task(protocol: Mapping[str, Any], source: str, error: type[ValueError] = ValueError) -> Task:
    """The task of a stored protocol (a session's ``protocol_json``, parsed), for a reader of the record: a value
    it cannot read is one line naming ``source`` and the field, raised as ``error``."""
    f = Fields(source, error)
    trial = protocol.get("trial", {})
    return read_task(f, protocol, trial if isinstance(trial, dict) else f.table("trial", trial, set()))


def task_tables(task: Task) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    """What a protocol stores of its task: its ``task`` table (None for the paper's task, so a protocol of before
    the tasks stores what it always stored) and its fields of the ``trial`` table."""
    own, trial = task.tables()
    return (None if task.kind == DEFAULT_KIND else {"kind": task.kind, **own}), trial
