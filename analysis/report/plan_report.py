"""The report of a study of several parts (:mod:`protocol.study.parts`): each experiment part's own report, and the
plan -- which parts each participant ran in which order, and how that order was chosen.

Each part is one task with its own sessions, analysed on its own (:func:`analysis.report.report.fill_report` with
``part``: one value per participant per condition, per task; nothing is pooled across tasks): its report is the
folder ``PART/`` of the output.  The output's ``report.html`` is the plan's page (the parts, the counterbalancing
method in words, each order and how many participants ran it, links to the parts' reports) and ``parts.csv`` holds
one row per participant and part (its place, row, session and status).
"""

from __future__ import annotations

import html
import json
import os
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.report.learning_report import VisitPart, write_learning
from protocol.storage import EmptyDatabase, StudyReader
from protocol.study.parts import Counterbalance, PartPlace, stored_place
from protocol.tasks.registry import stored_task

__all__ = ["PlanEntry", "plan_methods", "study_plan", "write_plan_report"]

#: The columns of ``parts.csv`` and what each holds (the page lists them as its codebook).
PARTS_COLUMNS = {
    "participant_code": "the participant's pseudonymous code",
    "participant_number": "the participant's number in the study (it deals the counterbalancing row)",
    "part": "the part's name in the protocol file",
    "position": "the part's place in this participant's order (1 = first)",
    "session_kind": "training (practice, not analysed) or experiment",
    "task": "the part's task kind",
    "counterbalancing_row": "the row of the Latin square this participant's order is (0-based)",
    "order": "the participant's whole order of parts",
    "session_id": "the part's session in its database",
    "status": "the session's status (completed, aborted: ended early, running: interrupted)",
    "database": "the study database the session is in",
}
#: parts.csv's further columns in a study with a schedule of visits (:mod:`protocol.study.visits`).
VISIT_COLUMNS = {
    "visit": "the visit of the schedule the session belongs to (position and order are within the visit)",
    "visit_number": "the visit's place in the schedule (1 = first)",
    "visit_day": "the visit's planned day (days after the participant's first visit)",
    "visit_role": "what the visit is for in the analysis: baseline, training, post, retention (empty: none)",
}


@dataclass(frozen=True, slots=True)
class PlanEntry:
    """One stored session of a part: who, which part, where in their order."""

    database: str
    code: str
    number: int
    place: PartPlace
    task: str
    session_id: int
    status: str


def study_plan(databases: Sequence[str | os.PathLike[str]]) -> list[PlanEntry]:
    """Every session of a part in the databases, by participant number and place ([] for a study of one task)."""
    out: list[PlanEntry] = []
    for db in databases:
        try:
            reader = StudyReader(str(db), check=False)
        except EmptyDatabase:  # no session: no plan (a command that needs one says so where it reads it)
            continue
        with reader:
            for info in reader.sessions():
                stored = json.loads(info.protocol_json)
                place = stored_place(stored, f"{db}: session {info.session_id}")
                if place is None:
                    continue
                task = stored_task(stored, f"{db}: session {info.session_id}").kind
                out.append(PlanEntry(str(db), info.code, info.participant_number, place, task, info.session_id,
                                     info.status))
    return sorted(out, key=lambda e: (e.database, e.number, e.place.visit.number if e.place.visit else 0,
                                      e.place.position, e.session_id))


def entry_key(e: PlanEntry) -> str:
    """The report's name of an entry's part: ``VISIT-PART`` in a study with visits
    (:func:`protocol.storage.database.part_key`), else the part's name."""
    return f"{e.place.visit.name}-{e.place.name}" if e.place.visit is not None else e.place.name


def _experiment_parts(plan: Sequence[PlanEntry]) -> list[tuple[str, str]]:
    """The experiment parts (name, task kind) in the order of the first participant's plan that has each (with
    visits: each visit's part, ``VISIT-PART``)."""
    seen: dict[str, str] = {}
    for e in plan:
        if e.place.session == "experiment":
            seen.setdefault(entry_key(e), e.task)
    return list(seen.items())


def _method_words(balance: Counterbalance | None, names: Sequence[str]) -> str:
    """How the order was chosen, in words."""
    if balance is None:
        return f"Every participant ran the parts in the protocol file's order ({', '.join(names)})."
    group = ", ".join(balance.parts)
    k, rows = len(balance.parts), len(balance.rows())
    fixed = [n for n in names if n not in balance.parts]
    square = ("a balanced Latin square (Williams 1949): each part in each place, and directly before each other "
              f"part, equally often over its {rows} rows ({'k' if k % 2 == 0 else '2k'} rows for k = {k} parts"
              f"{'' if k % 2 == 0 else ': an odd k needs the mirrored rows for the carry-over balance'})"
              if balance.method == "latin_square" else
              f"a cyclic Latin square ({rows} rows: each part in each place once)")
    kept = f"; {', '.join(fixed)} kept {'its place' if len(fixed) == 1 else 'their places'}" if fixed else ""
    return (f"The order of {group} was counterbalanced across participants by {square}. The rows were dealt to the "
            f"participant numbers in an order drawn from the study seed (participant n takes row perm[(n − 1) mod "
            f"{rows}]), so every {rows} consecutive numbers hold each order once{kept}.")


def plan_methods(plan: Sequence[PlanEntry]) -> str:
    """The plan in the methods' words: the parts, each a session of its own, and how their order was chosen."""
    if not plan:
        return ""
    first = plan[0].place
    names = list(first.order) or [first.name]
    kinds = {e.place.name: (e.place.session, e.task) for e in plan}
    parts = "; ".join(f"{n} ({kinds[n][0]}, {kinds[n][1].replace('_', ' ')})" for n in names if n in kinds)
    return (f"Each participant ran {len(names)} parts, each stored and run as a session of its own: {parts} (in "
            f"the order of {plan[0].code}). "
            + _method_words(first.balance, names)
            + " Each experiment part is analysed on its own, one value per participant per condition of its task; "
              "no measure is pooled across parts.")


def _orders_table(plan: Sequence[PlanEntry]) -> str:
    """Each order that occurred and how many participants ran it (the balance as run)."""
    per_participant = {(e.database, e.code): tuple(e.place.order) for e in plan}
    counts = Counter(per_participant.values())
    rows = "".join(f"<tr><td>{html.escape(' → '.join(order))}</td><td>{n}</td></tr>"
                   for order, n in sorted(counts.items()))
    return f"<table><tr><th>order</th><th>participants</th></tr>{rows}</table>"


def parts_frame(plan: Sequence[PlanEntry]) -> pd.DataFrame:
    """``parts.csv``: a row per participant and part."""
    visits = any(e.place.visit is not None for e in plan)
    columns = list(PARTS_COLUMNS) + (list(VISIT_COLUMNS) if visits else [])
    return pd.DataFrame([{
        "participant_code": e.code, "participant_number": e.number, "part": e.place.name,
        "position": e.place.position, "session_kind": e.place.session, "task": e.task,
        "counterbalancing_row": e.place.row, "order": " > ".join(e.place.order), "session_id": e.session_id,
        "status": e.status, "database": e.database,
        **({"visit": e.place.visit.name, "visit_number": e.place.visit.number, "visit_day": e.place.visit.day,
            "visit_role": e.place.visit.role} if e.place.visit is not None else {}),
    } for e in plan], columns=columns)


def _page(plan: Sequence[PlanEntry], parts: Sequence[tuple[str, str]], study_name: str, learning: bool = False) -> str:
    visits = ('<h2>Learning over the visits</h2><p><a href="learning.html">Learning curves, the mixed model of session '
              "number, gain and retention</a></p>" if learning else "")
    links = "".join(f'<li><a href="{html.escape(name)}/report.html">{html.escape(name)}</a> '
                    f"({html.escape(kind.replace('_', ' '))})</li>" for name, kind in parts)
    codebook = "".join(f"<tr><td>{c}</td><td>{html.escape(w)}</td></tr>" for c, w in PARTS_COLUMNS.items())
    n = len({(e.database, e.code) for e in plan})
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(study_name)}: the plan</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}td,th{{padding:2px 8px;text-align:left}}</style>
</head><body>
<h1>{html.escape(study_name)}</h1>
<h2>The plan</h2>
<p>{html.escape(plan_methods(plan))}</p>
<p>{n} participants; the orders as run:</p>
{_orders_table(plan)}
{visits}
<h2>Each part's report</h2>
<ul>{links}</ul>
<h2>parts.csv</h2>
<p>A row per participant and part:</p>
<table><tr><th>column</th><th>what it holds</th></tr>{codebook}</table>
</body></html>
"""


def write_plan_report(folder: Path, databases: Sequence[str | os.PathLike[str]], plan: Sequence[PlanEntry],
                      fill_part: Callable[[Path, str, str], tuple[list[str], pd.DataFrame | None]]) -> list[str]:
    """The plan's page and ``parts.csv`` into ``folder``, and each experiment part's report into ``folder/PART``
    by ``fill_part(subfolder, part, task kind)`` (its lines, and its per-participant table); in a study with visits
    each visit's part is ``VISIT-PART``, and the learning page follows (:mod:`analysis.report.learning_report`);
    the lines to print."""
    lines: list[str] = []
    parts = _experiment_parts(plan)
    with StudyReader(str(databases[0]), check=False) as reader:
        first = reader.sessions()[0]
    study_name = str(json.loads(first.protocol_json).get("name", "study"))
    overall: dict[str, pd.DataFrame | None] = {}
    for name, kind in parts:
        sub = folder / name
        sub.mkdir()
        said, overall[name] = fill_part(sub, name, kind)
        lines.extend(f"{name}: {line}" for line in said)
    parts_frame(plan).to_csv(folder / "parts.csv", index=False)
    visits = [VisitPart(e.place.visit, entry_key(e), e.place.session, e.task) for e in plan]
    learning = write_learning(folder, visits, overall) if any(v.visit is not None for v in visits) else []
    lines.extend(learning)
    (folder / "report.html").write_text(_page(plan, parts, study_name, bool(learning)), encoding="utf-8")
    return lines

