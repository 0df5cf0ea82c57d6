"""The NASA Task Load Index, as its authors define it: six subscales, their ratings, their weights, the scores.

NASA-TLX (Hart & Staveland 1988; Hart 2006, "NASA-Task Load Index (NASA-TLX); 20 years later") rates a task's
workload on six subscales -- mental, physical and temporal demand, performance, effort, frustration -- each on a
scale of 21 gradations, scored 0 to 100 in steps of 5 (performance from *perfect*, 0, to *failure*, 100: on every
subscale a higher number is more workload).  The **weighted** score asks, for each of the 15 pairs of subscales,
which contributed more to the workload of the task; a subscale's weight is the number of times it was chosen
(0 to 5; the weights sum to 15) and the score is Σ weight × rating / 15.  The **raw** score (RTLX; Hart 2006 §3)
leaves the pairs out: the mean of the six ratings.

This module is the one definition of the scale, its words and its scores; the participant screen shows
:data:`SUBSCALES` and :func:`pairs`, the storage keeps the answers by their ids (:func:`pair_id`), and the analysis
scores them with :func:`score`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["RATING_STEP", "SUBSCALES", "Subscale", "TlxScore", "pair_id", "pairs", "score", "weights"]

#: A rating's gradations: 0, 5, …, 100 (21 marks).
RATING_STEP = 5
RATING_MAX = 100


@dataclass(frozen=True, slots=True)
class Subscale:
    """One subscale: its id (stored), its name and question as the participant reads them, the scale's ends."""

    id: str
    name: str
    question: str
    low: str = "Very low"
    high: str = "Very high"


#: The six subscales, in the order of the original rating sheet.
SUBSCALES = (
    Subscale("mental", "Mental demand", "How mentally demanding was the task?"),
    Subscale("physical", "Physical demand", "How physically demanding was the task?"),
    Subscale("temporal", "Temporal demand", "How hurried or rushed was the pace of the task?"),
    Subscale("performance", "Performance", "How successful were you in accomplishing what you were asked to do?",
             "Perfect", "Failure"),
    Subscale("effort", "Effort", "How hard did you have to work to accomplish your level of performance?"),
    Subscale("frustration", "Frustration", "How insecure, discouraged, irritated, stressed, and annoyed were you?"),
)
_IDS = tuple(s.id for s in SUBSCALES)


def pairs() -> tuple[tuple[str, str], ...]:
    """The 15 pairs of subscales (each unordered pair once, in the sheet's order)."""
    return tuple(itertools.combinations(_IDS, 2))


def pair_id(a: str, b: str) -> str:
    """How a pair's answer is stored: ``"mental|physical"`` (its two ids in the sheet's order)."""
    first, second = sorted((a, b), key=_IDS.index)
    return f"{first}|{second}"


@dataclass(frozen=True, slots=True)
class TlxScore:
    """One questionnaire's scores: raw (mean of the six ratings) and weighted (None without the pairs)."""

    raw: float
    weighted: float | None
    weights: dict[str, int]


def weights(choices: Mapping[str, str]) -> dict[str, int]:
    """Each subscale's weight: how many of the 15 pairs it was chosen in (``choices``: pair id → chosen id).

    Raises ``ValueError`` unless every pair is answered with one of its two subscales.
    """
    w = dict.fromkeys(_IDS, 0)
    for a, b in pairs():
        chosen = choices.get(pair_id(a, b))
        if chosen not in (a, b):
            raise ValueError(f"NASA-TLX pair {pair_id(a, b)} = {chosen!r}: must be {a!r} or {b!r}")
        w[chosen] += 1
    return w


def score(ratings: Mapping[str, float], choices: Mapping[str, str] | None = None) -> TlxScore:
    """The scores of one answered sheet: ``ratings`` by subscale id (0–100, steps of 5), ``choices`` the 15 pairs
    (None or empty: raw only).

    Raises ``ValueError`` when a rating is missing or off the scale, or a pair is missing.
    """
    for s in _IDS:
        r = ratings.get(s)
        if r is None or not math.isfinite(r) or not 0 <= r <= RATING_MAX or r % RATING_STEP:
            raise ValueError(f"NASA-TLX rating {s} = {r!r}: must be 0 to {RATING_MAX} in steps of {RATING_STEP}")
    raw = sum(float(ratings[s]) for s in _IDS) / len(_IDS)
    if not choices:
        return TlxScore(raw, None, {})
    w = weights(choices)
    weighted = sum(w[s] * float(ratings[s]) for s in _IDS) / len(pairs())
    return TlxScore(raw, weighted, w)
