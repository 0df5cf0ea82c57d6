"""A schedule of visits above the parts: a participant comes back on given days, each visit a sequence of parts.

A protocol with ``[[parts]]`` (:mod:`protocol.study.parts`) may declare ``[[visits]]``; a file without them is one
visit, read and run exactly as before::

    [[visits]]
    name = "baseline"        # a lower-case word, unique among the visits
    day = 0                  # days after the participant's first visit (the first visit's day is 0)
    window_days = 0          # ± days the visit may be held around its day (default 0)
    parts = ["practice", "test"]   # the parts done in this visit, in this order (counterbalanced: see below)
    role = "baseline"        # optional: baseline | training | post | retention (what the report compares)

**Days and windows.**  Days increase strictly from 0; the windows of two visits do not overlap (each visit's
latest day is before the next one's earliest), so the order of the visits is the order of their days.

**Roles** (optional) tell the report which visits to compare (:mod:`analysis.report.learning`): at most one
``baseline`` (before every training and post visit), at most one ``post`` (after every training visit), any number
of ``training`` and ``retention`` visits (a retention visit needs a post visit before it); the baseline, post and
retention visits share an experiment part (the same test, so retention − post and post − baseline compare like
with like).

**Parts.**  A part may recur in several visits (the same test at baseline, post and retention) but at most once in
a visit; every declared part is in at least one visit.  Counterbalancing (``[counterbalance]``) applies within a
visit: the counterbalanced parts a visit holds take the participant's row of the square among themselves.

**Each stored session is one (visit, part)**: the session's protocol record stores, in its ``part`` table, the
visit (:class:`VisitPlace`: name, number, day, window, role) beside the part, so resume, one writer per session,
withdrawal, export, check and replay work per session as before.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.settings.tomlfields import Fields

__all__ = ["MAX_VISITS", "ROLES", "Visit", "VisitPlace", "visit_place_from_table", "visits_from_tables"]

#: What a visit is for in the analysis (optional).
ROLES = ("baseline", "training", "post", "retention")
#: At most this many visits in a schedule.
MAX_VISITS = 30
#: The latest day a visit may be planned on (about three years: a retention test, not an open list).
MAX_DAY = 1100
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,23}\Z")
_NAME_WHAT = "a lower-case word of 1–24 letters/digits/_ beginning with a letter (e.g. baseline)"
_KEYS = {"name", "day", "window_days", "parts", "role"}


@dataclass(frozen=True, slots=True)
class Visit:
    """One visit of the schedule, as the file declares it."""

    name: str
    day: int
    window_days: int
    parts: tuple[str, ...]
    role: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The ``[[visits]]`` table as the file writes it."""
        return {"name": self.name, "day": self.day, "window_days": self.window_days, "parts": list(self.parts),
                **({"role": self.role} if self.role else {})}


@dataclass(frozen=True, slots=True)
class VisitPlace:
    """Which visit a stored session belongs to (stored in its protocol's ``part`` table as ``visit``)."""

    name: str
    number: int  # 1-based place in the schedule
    day: int  # planned day (days after the participant's first visit)
    window_days: int = 0
    role: str = ""
    #: Planned days since the previous visit (0 for the first): the simulated participant's forgetting reads it
    #: from the stored session alone (:mod:`pipeline.sim.learning`), so a resumed session meets the same person.
    gap_days: int = 0

    def to_dict(self) -> dict[str, Any]:
        """The stored ``part.visit`` table."""
        return {"name": self.name, "number": self.number, "day": self.day, "window_days": self.window_days,
                "gap_days": self.gap_days, **({"role": self.role} if self.role else {})}


def visits_from_tables(f: Fields, raw: Any, parts: Mapping[str, str]) -> tuple[Visit, ...]:
    """The file's ``[[visits]]`` over its parts (``parts``: name → session kind, the file's order); () without them.

    Raises ``f``'s error, one line naming the visit's field, the value and what is allowed."""
    if raw is None:
        return ()
    if not parts:
        raise f.fail("visits", raw, "a schedule of visits sequences the study's [[parts]]: the file has none (declare "
                     "the parts each visit holds)")
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_VISITS:
        raise f.fail("visits", raw, f"must be a list of 1 to {MAX_VISITS} [[visits]] tables")
    out: list[Visit] = []
    for i, item in enumerate(raw, start=1):
        out.append(_visit(f, f"visits[{i}]", item, parts, out))
    unused = [p for p in parts if not any(p in v.parts for v in out)]
    if unused:
        raise f.fail("visits", [v.name for v in out], f"no visit holds the part {unused[0]!r}: every declared part "
                     "is in at least one visit")
    _check_roles(f, out, parts)
    return tuple(out)


def _visit(f: Fields, field: str, item: Any, parts: Mapping[str, str], before: Sequence[Visit]) -> Visit:
    """One ``[[visits]]`` table, checked against the visits ``before`` it."""
    t = f.table(field, item, set(_KEYS))
    for key, what in (("name", _NAME_WHAT), ("day", "days after the first visit (0 for the first)"),
                      ("parts", "the parts done in the visit, in order")):
        f.required(t, field, key, what)
    name = f.string(f"{field}.name", t["name"], pattern=_NAME, what=_NAME_WHAT)
    if any(v.name == name for v in before):
        raise f.fail(f"{field}.name", name, "names must be unique among the visits")
    day = f.integer(f"{field}.day", t["day"], lo=0, hi=MAX_DAY)
    if not before and day != 0:
        raise f.fail(f"{field}.day", day, "the first visit's day must be 0 (days count from the first visit)")
    if before and day <= before[-1].day:
        raise f.fail(f"{field}.day", day, f"days must increase: must be after the previous visit "
                     f"{before[-1].name!r} (day {before[-1].day})")
    window = f.integer(f"{field}.window_days", t.get("window_days", 0), lo=0, hi=MAX_DAY)
    if before and day - window <= before[-1].day + before[-1].window_days:
        prev = before[-1]
        raise f.fail(f"{field}.window_days", window, f"the window (days {day - window}–{day + window}) must begin "
                     f"after the previous visit {prev.name!r}'s (which ends on day {prev.day + prev.window_days})")
    names = t["parts"]
    if not isinstance(names, list) or not names or any(not isinstance(n, str) for n in names):
        raise f.fail(f"{field}.parts", names, "must be a non-empty list of part names")
    unknown = [n for n in names if n not in parts]
    if unknown:
        raise f.fail(f"{field}.parts", names, f"names no part {unknown[0]!r}: the parts are {', '.join(parts)}")
    if len(set(names)) != len(names):
        raise f.fail(f"{field}.parts", names, "each part at most once in a visit (a part may recur in other visits)")
    role = f.choice(f"{field}.role", t["role"], ROLES) if "role" in t else ""
    return Visit(name, day, window, tuple(names), role)


def _check_roles(f: Fields, visits: Sequence[Visit], parts: Mapping[str, str]) -> None:
    """The roles' order and their shared test (module docstring)."""
    def where(role: str) -> list[int]:
        return [i for i, v in enumerate(visits) if v.role == role]

    base, train, post, keep = where("baseline"), where("training"), where("post"), where("retention")
    for role, found in (("baseline", base), ("post", post)):
        if len(found) > 1:
            raise f.fail(f"visits[{found[1] + 1}].role", role, f"at most one {role} visit (the first is "
                         f"{visits[found[0]].name!r})")
    if base and (train or post) and base[0] > min(train + post):
        i = min(train + post)
        raise f.fail(f"visits[{base[0] + 1}].role", "baseline", f"the baseline must come before the "
                     f"{visits[i].role} visit {visits[i].name!r}")
    if post and train and max(train) > post[0]:
        raise f.fail(f"visits[{max(train) + 1}].role", "training", f"a training visit must come before the post "
                     f"visit {visits[post[0]].name!r}")
    for i in keep:
        if not post:
            raise f.fail(f"visits[{i + 1}].role", "retention", "a retention visit needs a post visit (role = 'post') "
                         "before it: retention is measured against the post-test")
        if i < post[0]:
            raise f.fail(f"visits[{i + 1}].role", "retention", f"a retention visit must come after the post visit "
                         f"{visits[post[0]].name!r} (day {visits[post[0]].day})")
    tests = base + post + keep
    if len(tests) > 1:
        shared = set.intersection(*({p for p in visits[i].parts if parts[p] == "experiment"} for i in tests))
        if not shared:
            raise f.fail("visits", [visits[i].name for i in tests], "the baseline, post and retention visits must "
                         "share an experiment part (the same test, so their differences compare like with like)")


def visit_place_from_table(f: Fields, t: Any) -> VisitPlace:
    """A stored session's ``part.visit`` table."""
    v = f.table("part.visit", t, {"name", "number", "day", "window_days", "role", "gap_days"})
    role = v.get("role", "")
    return VisitPlace(name=f.string("part.visit.name", v.get("name"), pattern=_NAME, what=_NAME_WHAT),
                      number=f.integer("part.visit.number", v.get("number"), lo=1, hi=MAX_VISITS),
                      day=f.integer("part.visit.day", v.get("day"), lo=0, hi=MAX_DAY),
                      window_days=f.integer("part.visit.window_days", v.get("window_days", 0), lo=0, hi=MAX_DAY),
                      gap_days=f.integer("part.visit.gap_days", v.get("gap_days", 0), lo=0, hi=MAX_DAY),
                      role=f.choice("part.visit.role", role, ROLES) if role else "")
