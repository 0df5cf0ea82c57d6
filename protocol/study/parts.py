"""A study as a sequence of task blocks ("parts"): which tasks run in which order, counterbalanced where asked.

The identifier is *part* (``[[parts]]``, :class:`PartPlace`): "block" already names a recording block of the
session's records (``session_blocks``, :mod:`protocol.recording`).  A protocol file without ``[[parts]]`` is one
task, run as a training session then an experiment session, as it always was::

    [[parts]]
    name = "practice"            # a lower-case word, unique in the file
    session = "training"         # the stored session's kind: "training" (free practice) or "experiment" (default)

    [[parts]]
    name = "tracking"
    [parts.task]                 # the part's own tables: task, targets, design, trial, training
    kind = "force_tracking"
    ...

    [counterbalance]             # optional: these parts' places rotate across participants
    parts = ["regulation", "tracking", "discrimination"]
    method = "latin_square"      # a balanced Latin square (Williams 1949) or "rotation" (a cyclic Latin square)

**A part's protocol** is the study's file with the part's tables in place of the study's: each of ``task``,
``targets``, ``design`` and ``training`` a part gives replaces the study's whole table; ``trial`` is the study's
with the part's fields over it, except that a part whose task is of another kind than the study's does not inherit
the study task's own ``[trial]`` fields (force regulation's band and hold).  Covariates, questionnaires, groups and
the LSL settings are the study's.  Each part's protocol is validated as a protocol file is (one line naming the
part, the field, the value and what is allowed).

**Each part is run and stored as a session of its own** (its kind and its protocol, with the part's name, its place
in the participant's order and that order stored in the protocol's ``part`` table): resume, one writer per session,
withdrawal, export, check and replay work per session as before.

**Counterbalancing.**  The parts named in ``[counterbalance]`` keep the places they have in the file between them,
and participant *n* takes row *r(n)* of a Latin square over them: ``latin_square`` is Williams' balanced square
(each part in each place, and each part directly before each other equally often: k rows for an even number of
parts, 2k for an odd one, whose mirrored rows complete the balance), ``rotation`` the cyclic square (k rows: each
part in each place once).  The rows are dealt in an order drawn from the study seed, ``r(n) = perm[(n − 1) mod R]``,
so every run of R consecutive participant numbers holds every row once (each order equally often) while which
participant gets which order is not fixed by the file alone.  Same file, seed and participant number → the same
order.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.settings.tomlfields import Fields
from protocol.study.visits import VisitPlace, visit_place_from_table
from protocol.tasks.registry import DEFAULT_KIND, task_class

__all__ = ["COUNTERBALANCE_METHODS", "PART_KINDS", "Counterbalance", "PartPlace", "PartTables", "balanced_rows",
           "counterbalance_from_table", "order_of", "part_tables", "place_from_table", "stored_place"]

#: The session kinds a part is run as.
PART_KINDS = ("training", "experiment")
#: How a counterbalanced group's order varies across participants.
COUNTERBALANCE_METHODS = ("latin_square", "rotation")
#: A part's own tables (the rest of the study's file is every part's).
_PART_KEYS = frozenset({"name", "session", "task", "targets", "design", "trial", "training"})
#: The study-level tables a part's protocol does not take from the file's top level.
_PLAN_KEYS = frozenset({"parts", "counterbalance", "part", "visits"})
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,23}\Z")
_NAME_WHAT = "a lower-case word of 1–24 letters/digits/_ beginning with a letter (e.g. tracking)"
#: At most this many parts in a study (a participant's day, not an open list).
MAX_PARTS = 12
#: The seed stream of the row order (one study seed, several independent draws).
_ROW_STREAM = 4301


@dataclass(frozen=True, slots=True)
class PartPlace:
    """Which part of the study a session is, stored with its protocol (``part``).

    Attributes
    ----------
    name
        The part's name in the protocol file.
    session
        The kind of session it is run as (``training`` or ``experiment``).
    position
        1-based place in the participant's order (0 in the study's file, before an order is dealt).
    order
        The participant's whole order of parts, by name.
    row
        The counterbalancing row the order is (0-based; 0 without counterbalancing).
    trained_by
        The training parts the participant does before this one (an experiment part whose protocol requires
        training needs them completed: :mod:`protocol.runner.study_rules`).
    balance
        The study's ``[counterbalance]`` the order was dealt by (None: the file's order), so a session's record
        says how its place was chosen (the report's methods).
    visit
        The visit of the schedule this session of the part belongs to (:mod:`protocol.study.visits`; None in a
        study without ``[[visits]]``); ``position`` and ``order`` are then the part's within that visit.
    """

    name: str
    session: str
    position: int = 0
    order: tuple[str, ...] = ()
    row: int = 0
    trained_by: tuple[str, ...] = ()
    balance: Counterbalance | None = None
    visit: VisitPlace | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``part`` table as stored with a session's protocol."""
        return {"name": self.name, "session": self.session, "position": self.position, "order": list(self.order),
                "row": self.row, "trained_by": list(self.trained_by),
                **({"counterbalance": self.balance.to_dict()} if self.balance is not None else {}),
                **({"visit": self.visit.to_dict()} if self.visit is not None else {})}

    def before(self) -> tuple[str, ...]:
        """The parts the participant does before this one."""
        return self.order[:max(self.position - 1, 0)]


@dataclass(frozen=True, slots=True)
class Counterbalance:
    """The file's ``[counterbalance]``: which parts rotate, and how."""

    parts: tuple[str, ...]
    method: str

    def rows(self) -> list[tuple[int, ...]]:
        """The Latin square's rows over the group (indices into :attr:`parts`)."""
        k = len(self.parts)
        if self.method == "rotation":
            return [tuple((r + j) % k for j in range(k)) for r in range(k)]
        return balanced_rows(k)

    def to_dict(self) -> dict[str, Any]:
        """The table as the file writes it."""
        return {"parts": list(self.parts), "method": self.method}


@dataclass(frozen=True, slots=True)
class PartTables:
    """A part as read from the file: its name and kind, and its protocol's tables (validated by the caller)."""

    name: str
    session: str
    tables: dict[str, Any]
    #: How the part is named in an error line (``FILE, part 'NAME' (parts[i])``).
    source: str


def balanced_rows(k: int) -> list[tuple[int, ...]]:
    """Williams' balanced Latin square of ``k`` treatments (Williams 1949; Bradley 1958): the first row is
    0, 1, k−1, 2, k−2, …, each further row adds 1 mod k; for odd ``k`` the mirrored rows follow, so each treatment
    comes directly before each other equally often (k rows for even k, 2k for odd)."""
    first, lo, hi = [0], 1, k - 1
    while len(first) < k:
        first.append(lo)
        lo += 1
        if len(first) < k:
            first.append(hi)
            hi -= 1
    rows = [tuple((v + r) % k for v in first) for r in range(k)]
    if k % 2:
        rows += [tuple(reversed(row)) for row in rows]
    return rows


def order_of(names: Sequence[str], balance: Counterbalance | None, seed: int,
             number: int) -> tuple[tuple[str, ...], int]:
    """Participant ``number``'s order of the parts ``names`` (file order) and its counterbalancing row.

    The counterbalanced parts keep their places between them and take row ``perm[(number − 1) mod R]`` of the
    square, ``perm`` a permutation of the R rows drawn from ``seed`` (module docstring)."""
    if number < 1:
        raise ValueError(f"participant_number = {number}: must be ≥ 1")
    if balance is None:
        return tuple(names), 0
    rows = balance.rows()
    perm = np.random.default_rng([seed, _ROW_STREAM]).permutation(len(rows)).tolist()
    row = int(perm[(number - 1) % len(rows)])
    ordered = iter(balance.parts[i] for i in rows[row])
    return tuple(next(ordered) if n in balance.parts else n for n in names), row


def part_tables(f: Fields, top: Mapping[str, Any]) -> list[PartTables]:
    """The file's ``[[parts]]``, each with its protocol's tables (module docstring); [] without them."""
    if "parts" not in top:
        return []
    raw = top["parts"]
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_PARTS:
        raise f.fail("parts", raw, f"must be a list of 1 to {MAX_PARTS} [[parts]] tables")
    study = {k: v for k, v in top.items() if k not in _PLAN_KEYS}
    study_kind = _kind_of(top)
    out: list[PartTables] = []
    for i, item in enumerate(raw, start=1):
        field = f"parts[{i}]"
        part = f.table(field, item, set(_PART_KEYS))
        f.required(part, field, "name", f"every part has a name: {_NAME_WHAT}")
        name = f.string(f"{field}.name", part["name"], pattern=_NAME, what=_NAME_WHAT)
        if any(p.name == name for p in out):
            raise f.fail(f"{field}.name", name, "names must be unique among the parts")
        session = f.choice(f"{field}.session", part.get("session", "experiment"), PART_KINDS)
        tables = dict(study)
        for key in ("task", "targets", "design", "training"):
            if key in part:
                tables[key] = part[key]
        trial = study.get("trial", {})
        if isinstance(trial, dict) and _kind_of(tables) != study_kind:  # another task: not the study task's fields
            own = _trial_fields(study_kind)
            trial = {k: v for k, v in trial.items() if k not in own}
        given = part.get("trial", {})
        if not isinstance(given, dict):
            raise f.fail(f"{field}.trial", given, "must be a table")
        tables["trial"] = {**(trial if isinstance(trial, dict) else {}), **given}
        out.append(PartTables(name, session, tables, f"{f.source}, part {name!r} ({field})"))
    if not any(p.session == "experiment" for p in out):
        raise f.fail("parts", [p.name for p in out], "at least one part must be an experiment session (session = "
                     "'experiment', the default): a study of practice only measures nothing")
    return out


def _kind_of(tables: Mapping[str, Any]) -> object:
    """The task kind a protocol's tables name (the paper's when none; a bad one is refused where it is read)."""
    task = tables.get("task", {})
    return task.get("kind", DEFAULT_KIND) if isinstance(task, dict) else None


def _trial_fields(kind: object) -> frozenset[str]:
    """The ``[trial]`` fields that are the task kind's own (none for an unknown kind: refused where it is read)."""
    try:
        return task_class(str(kind)).trial_fields
    except KeyError:
        return frozenset()


def counterbalance_from_table(f: Fields, top: Mapping[str, Any], names: Sequence[str]) -> Counterbalance | None:
    """The file's ``[counterbalance]`` over the parts ``names``; None without it."""
    if "counterbalance" not in top:
        return None
    t = f.table("counterbalance", top["counterbalance"], {"parts", "method"})
    if not names:
        raise f.fail("counterbalance", t, "counterbalances [[parts]]: the file has none")
    f.required(t, "counterbalance", "parts", "the parts whose order varies across participants")
    group = t["parts"]
    if not isinstance(group, list) or len(group) < 2 or any(not isinstance(n, str) for n in group):
        raise f.fail("counterbalance.parts", group, "must be a list of at least 2 part names")
    unknown = [n for n in group if n not in names]
    if unknown:
        raise f.fail("counterbalance.parts", group, f"names no part {unknown[0]!r}: the parts are "
                     f"{', '.join(names)}")
    if len(set(group)) != len(group):
        raise f.fail("counterbalance.parts", group, "each part at most once")
    method = f.choice("counterbalance.method", t.get("method", "latin_square"), COUNTERBALANCE_METHODS)
    return Counterbalance(tuple(group), method)


def stored_place(protocol: Mapping[str, Any], source: str) -> PartPlace | None:
    """A stored session's place in its participant's plan (its protocol's ``part`` table, parsed JSON), for a
    reader of the record; None for a single-task study's session; a value it cannot read: one ``ValueError`` line."""
    return place_from_table(Fields(source, ValueError), protocol)


def place_from_table(f: Fields, top: Mapping[str, Any]) -> PartPlace | None:
    """A stored session's ``part`` table (None when it has none: a single-task study's session)."""
    if "part" not in top:
        return None
    t = f.table("part", top["part"], {"name", "session", "position", "order", "row", "trained_by", "counterbalance",
                                      "visit"})
    name = f.string("part.name", t.get("name"), pattern=_NAME, what=_NAME_WHAT)
    names = {}
    for key in ("order", "trained_by"):
        names[key] = t.get(key, [])
        if not isinstance(names[key], list) or any(not isinstance(n, str) for n in names[key]):
            raise f.fail(f"part.{key}", names[key], "must be a list of part names")
    return PartPlace(name=name, session=f.choice("part.session", t.get("session"), PART_KINDS),
                     position=f.integer("part.position", t.get("position", 0), lo=0, hi=MAX_PARTS),
                     order=tuple(names["order"]), row=f.integer("part.row", t.get("row", 0), lo=0, hi=2 * MAX_PARTS),
                     trained_by=tuple(names["trained_by"]),
                     balance=counterbalance_from_table(f, t, _balanced_names(t, names["order"]))
                     if "counterbalance" in t else None,
                     visit=visit_place_from_table(f, t["visit"]) if "visit" in t else None)


def _balanced_names(t: Mapping[str, Any], order: list[str]) -> list[str]:
    """The parts a stored ``part.counterbalance`` may name: the participant's order, and in a visit (which holds
    some of the study's parts, :mod:`protocol.study.visits`) the group's own parts too."""
    group = t["counterbalance"].get("parts", []) if "visit" in t and isinstance(t["counterbalance"], dict) else []
    return [*order, *(n for n in group if isinstance(n, str) and n not in order)]
