"""Questionnaires a protocol asks on the participant screen: NASA-TLX and Likert items of the lab's own.

Declared in the protocol file's ``[[questionnaires]]`` tables (none by default)::

    [[questionnaires]]
    name = "workload"
    kind = "nasa_tlx"          # the six ratings (protocol.study.tlx)
    weighted = true            # and the 15 pairwise comparisons for the weights (default true)
    after = "block"            # after each block of one haptic mode ("session": once, at the session's end)

    [[questionnaires]]
    name = "confidence"
    kind = "likert"
    after = "session"
    scale = { min = 1, max = 7, low = "strongly disagree", high = "strongly agree" }   # its items' default
      [[questionnaires.items]]
      id = "control"
      text = "I felt in control of the force I applied."

A Likert item needs a scale, its own or its questionnaire's (an item without one is refused).  Questionnaires
are asked in experiment sessions (not in training), on the participant screen, between two trials: ``block``
after the last trial of each block of one haptic mode (an ordering by mode is needed: ``blocked_by_mode`` or
``counterbalanced``; a mode is asked about once, so the re-run of an aborted trial appended later does not ask
again), ``session`` after the last trial.  :func:`due` says which is due before a schedule position;
:func:`checked_answers` checks an answered sheet.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.settings.tomlfields import Fields, show
from protocol.study import tlx

__all__ = [
    "QUESTIONNAIRE_KINDS", "QUESTIONNAIRE_SKIPPED_EVENT", "Item", "LikertScale", "Prompt", "Questionnaire",
    "checked_answers", "due", "questionnaires_from_tables", "skip_detail", "skipped_key",
]

QUESTIONNAIRE_KINDS = ("nasa_tlx", "likert")
#: The ``events.kind`` of a questionnaire the experimenter skipped while it waited for the participant: not
#: answered, stored so (a resume does not ask it again) and listed with the deviations from the protocol; its detail
#: begins ``NAME/BLOCK:`` (:func:`skip_detail`).
QUESTIONNAIRE_SKIPPED_EVENT = "questionnaire_skipped"
AFTER = ("block", "session")
#: A questionnaire's ``block`` when it follows the session rather than a block of one mode.
SESSION = "session"
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}\Z")
_MAX_ITEMS = 40


@dataclass(frozen=True, slots=True)
class LikertScale:
    """A Likert item's scale: whole numbers ``lo`` to ``hi``, its two ends' words."""

    lo: int
    hi: int
    low: str
    high: str

    def to_dict(self) -> dict[str, Any]:
        return {"min": self.lo, "max": self.hi, "low": self.low, "high": self.high}


@dataclass(frozen=True, slots=True)
class Item:
    """One question: its id (stored), its text, and its scale (a Likert item) -- a NASA-TLX item is a subscale's
    rating (``scale`` None, 0–100 in steps of 5) or one of its 15 pairs (``pair``: the two subscales' ids)."""

    id: str
    text: str
    scale: LikertScale | None = None
    pair: tuple[str, str] | None = None


@dataclass(frozen=True, slots=True)
class Questionnaire:
    """One declared questionnaire."""

    name: str
    kind: str
    after: str
    weighted: bool = True
    items: tuple[Item, ...] = ()

    def questions(self) -> tuple[Item, ...]:
        """Every question the participant answers, in order: a NASA-TLX's six ratings then (weighted) its 15 pairs."""
        if self.kind != "nasa_tlx":
            return self.items
        ratings = tuple(Item(s.id, s.question) for s in tlx.SUBSCALES)
        if not self.weighted:
            return ratings
        names = {s.id: s.name for s in tlx.SUBSCALES}
        return ratings + tuple(Item(tlx.pair_id(a, b), f"{names[a]} or {names[b]}?", pair=(a, b))
                               for a, b in tlx.pairs())

    def to_dict(self) -> dict[str, Any]:
        """The declaration as the file writes it (stored with each session's protocol)."""
        d: dict[str, Any] = {"name": self.name, "kind": self.kind, "after": self.after}
        if self.kind == "nasa_tlx":
            d["weighted"] = self.weighted
        else:
            d["items"] = [{"id": i.id, "text": i.text, **({"scale": i.scale.to_dict()} if i.scale else {})}
                          for i in self.items]
        return d


@dataclass(frozen=True, slots=True)
class Prompt:
    """A questionnaire due now: which, and the block it follows (a haptic mode, or :data:`SESSION`)."""

    questionnaire: Questionnaire
    block: str

    @property
    def key(self) -> tuple[str, str]:
        """What identifies its answers in a session: (questionnaire, block)."""
        return self.questionnaire.name, self.block


def _scale(f: Fields, field: str, v: Any) -> LikertScale:
    t = f.table(field, v, {"min", "max", "low", "high"})
    for key in ("min", "max", "low", "high"):
        f.required(t, field, key, "a scale needs min, max (whole numbers) and the words of its ends, low and high")
    lo = f.integer(f"{field}.min", t["min"], lo=-10, hi=10)
    hi = f.integer(f"{field}.max", t["max"], lo=-10, hi=20)
    if not 1 <= hi - lo <= 20:
        raise f.fail(f"{field}.max", hi, f"must be 1 to 20 more than {field}.min = {lo} (a scale of 2 to 21 points)")
    return LikertScale(lo, hi, f.string(f"{field}.low", t["low"]), f.string(f"{field}.high", t["high"]))


def _items(f: Fields, field: str, t: dict[str, Any]) -> tuple[Item, ...]:
    default = _scale(f, f"{field}.scale", t["scale"]) if "scale" in t else None
    f.required(t, field, "items", "a Likert questionnaire needs its [[questionnaires.items]]")
    raw = t["items"]
    if not isinstance(raw, list) or not 1 <= len(raw) <= _MAX_ITEMS:
        raise f.fail(f"{field}.items", raw, f"must be a list of 1 to {_MAX_ITEMS} items")
    out: list[Item] = []
    for i, it in enumerate(raw):
        where = f"{field}.items[{i}]"
        it = f.table(where, it, {"id", "text", "scale"})
        f.required(it, where, "id", "every item needs an id (lower case letters, digits, _)")
        item_id = f.string(f"{where}.id", it["id"], pattern=_NAME, what="a lower-case id of 1–32 letters, digits or _")
        if item_id in (o.id for o in out):
            raise f.fail(f"{where}.id", item_id, "is used twice in this questionnaire: item ids must be unique")
        f.required(it, where, "text", "every item needs the text the participant reads")
        scale = _scale(f, f"{where}.scale", it["scale"]) if "scale" in it else default
        if scale is None:
            raise f.fail(f"{where}.scale", None, "every Likert item needs its scale (or its questionnaire's), e.g. "
                         "scale = {min = 1, max = 7, low = \"strongly disagree\", high = \"strongly agree\"}")
        out.append(Item(item_id, f.string(f"{where}.text", it["text"]), scale))
    return tuple(out)


def _one(f: Fields, field: str, t: Any, taken: Iterable[str], ordering: str) -> Questionnaire:
    t = f.table(field, t, {"name", "kind", "after", "weighted", "scale", "items"})
    f.required(t, field, "name", "every questionnaire needs a name (lower case letters, digits, _)")
    name = f.string(f"{field}.name", t["name"], pattern=_NAME, what="a lower-case name of 1–32 letters, digits or _")
    if name in taken:
        raise f.fail(f"{field}.name", name, "is declared twice: questionnaire names must be unique")
    f.required(t, field, "kind", f"allowed kinds: {', '.join(QUESTIONNAIRE_KINDS)}")
    kind = f.choice(f"{field}.kind", t["kind"], QUESTIONNAIRE_KINDS)
    after = f.choice(f"{field}.after", t.get("after", "block"), AFTER)
    if after == "block" and ordering == "random":
        raise f.fail(f"{field}.after", after, "needs design.ordering 'blocked_by_mode' or 'counterbalanced' (a random "
                     "order has no block of one mode to ask about); or ask after the 'session'")
    if kind == "nasa_tlx":
        for key in ("scale", "items"):
            if key in t:
                raise f.fail(f"{field}.{key}", t[key], "NASA-TLX has its own six subscales and scale (0–100)")
        return Questionnaire(name, kind, after, f.boolean(f"{field}.weighted", t.get("weighted", True)))
    if "weighted" in t:
        raise f.fail(f"{field}.weighted", t["weighted"], "only a NASA-TLX is weighted")
    return Questionnaire(name, kind, after, items=_items(f, field, t))


def questionnaires_from_tables(f: Fields, v: Any, ordering: str) -> tuple[Questionnaire, ...]:
    """The protocol file's ``[[questionnaires]]`` (absent: none), each checked (one line naming the field)."""
    if v is None:
        return ()
    if not isinstance(v, list) or len(v) > 8:
        raise f.fail("questionnaires", v, "must be a list of at most 8 [[questionnaires]] tables")
    out: list[Questionnaire] = []
    for i, t in enumerate(v):
        out.append(_one(f, f"questionnaires[{i}]", t, [q.name for q in out], ordering))
    return tuple(out)


def due(questionnaires: Sequence[Questionnaire], modes: Sequence[str], position: int,
        answered: Iterable[tuple[str, str]]) -> Prompt | None:
    """The questionnaire to ask before schedule position ``position`` (``modes``: each scheduled trial's haptic
    mode), if one is due and not yet ``answered`` (keys ``(questionnaire, block)``); blocks before the session.

    A block's questionnaire is due where the trial before ``position`` has another mode than the trial at it (or
    the schedule ends); the session's where the schedule ends.
    """
    if position <= 0 or position > len(modes):
        return None
    done = set(answered)
    ended = modes[position - 1]
    block_ends = position == len(modes) or modes[position] != ended
    for want, block, now in (("block", ended, block_ends), ("session", SESSION, position == len(modes))):
        if not now:
            continue
        for q in questionnaires:
            if q.after == want and (q.name, block) not in done:
                return Prompt(q, block)
    return None


def checked_answers(q: Questionnaire, answers: Mapping[str, Any]) -> dict[str, float | str]:
    """An answered sheet, checked: every question answered on its scale, nothing else (one line otherwise).

    Ratings are numbers (a NASA-TLX subscale 0–100 in steps of 5; a Likert item a whole number on its scale); a
    NASA-TLX pair is the id of the subscale chosen.
    """
    questions = {i.id: i for i in q.questions()}
    for k in answers:
        if k not in questions:
            raise ValueError(f"questionnaire {q.name}: answer {k!r} = {show(answers[k])}: no such question (its "
                             f"questions: {', '.join(questions)})")
    out: dict[str, float | str] = {}
    for item_id, item in questions.items():
        v = answers.get(item_id)
        where = f"questionnaire {q.name}: {item_id} = {show(v)}"
        if item.pair is not None:
            if v not in item.pair:
                raise ValueError(f"{where}: must be {item.pair[0]!r} or {item.pair[1]!r}")
            out[item_id] = str(v)
            continue
        x = _number(v)
        if item.scale is None:
            if x is None or not 0 <= x <= tlx.RATING_MAX or x % tlx.RATING_STEP:
                raise ValueError(f"{where}: must be 0 to {tlx.RATING_MAX} in steps of {tlx.RATING_STEP}")
        elif x is None or not x.is_integer() or not item.scale.lo <= x <= item.scale.hi:
            raise ValueError(f"{where}: must be a whole number from {item.scale.lo} to {item.scale.hi}")
        out[item_id] = x
    return out


def _number(v: Any) -> float | None:
    """A finite real number (not a bool) as a float, else None."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return None
    return float(v)


def skip_detail(name: str, block: str, words: str, reason: str) -> str:
    """The detail of a :data:`QUESTIONNAIRE_SKIPPED_EVENT`: ``NAME/BLOCK:`` (read back by :func:`skipped_key`), then
    the prompt's words and the experimenter's reason."""
    why = reason.strip() or "no reason given"
    return f"{name}/{block}: {words} skipped by the experimenter, not answered (reason: {why})"


def skipped_key(detail: str) -> tuple[str, str] | None:
    """The (questionnaire, block) a :data:`QUESTIONNAIRE_SKIPPED_EVENT`'s detail names (None: not one of its)."""
    head = detail.split(":", 1)[0]
    name, sep, block = head.partition("/")
    return (name, block) if sep and _NAME.match(name) and block else None
