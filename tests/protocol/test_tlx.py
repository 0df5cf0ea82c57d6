"""NASA-TLX scored as its authors define it (Hart & Staveland 1988; Hart 2006), recomputed here independently.

The independent computation works from the definition, not from the module: every one of the 15 comparisons is a
cell of a 6 × 6 tally matrix (row = the subscale chosen), a subscale's weight is its row sum, the weighted score is
the weights' dot product with the ratings over 15, the raw score the mean of the six ratings.  Scores are sums of
multiples of 5 divided by 6 or 15, so they are compared to 1e-12 (a few ulps of 100).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from protocol.study import tlx

IDS = ["mental", "physical", "temporal", "performance", "effort", "frustration"]


def _independent(ratings: dict[str, float], chosen: dict[frozenset[str], str]) -> tuple[float, float, list[int]]:
    tally = np.zeros((6, 6), dtype=int)
    for a, b in itertools.combinations(range(6), 2):
        winner = IDS.index(chosen[frozenset((IDS[a], IDS[b]))])
        loser = b if winner == a else a
        tally[winner, loser] += 1
    w = tally.sum(axis=1)
    r = np.array([ratings[i] for i in IDS], dtype=float)
    return float(r.mean()), float(w @ r / 15.0), [int(x) for x in w]


def _sheet(rng: np.random.Generator) -> tuple[dict[str, float], dict[frozenset[str], str]]:
    ratings = {i: float(5 * rng.integers(0, 21)) for i in IDS}
    chosen = {frozenset((a, b)): (a if rng.random() < 0.5 else b) for a, b in itertools.combinations(IDS, 2)}
    return ratings, chosen


def test_the_sheet_has_six_subscales_fifteen_pairs_and_21_marks() -> None:
    assert [s.id for s in tlx.SUBSCALES] == IDS
    assert len(tlx.pairs()) == 15 and len({frozenset(p) for p in tlx.pairs()}) == 15
    assert tlx.RATING_MAX // tlx.RATING_STEP + 1 == 21
    perf = next(s for s in tlx.SUBSCALES if s.id == "performance")
    assert (perf.low, perf.high) == ("Perfect", "Failure")  # on every subscale higher is more workload


@pytest.mark.parametrize("seed", range(40))
def test_raw_and_weighted_scores_equal_the_definitions_on_random_sheets(seed: int) -> None:
    ratings, chosen = _sheet(np.random.default_rng(seed))
    choices = {tlx.pair_id(a, b): chosen[frozenset((a, b))] for a, b in tlx.pairs()}
    got = tlx.score(ratings, choices)
    raw, weighted, w = _independent(ratings, chosen)
    assert got.raw == pytest.approx(raw, abs=1e-12)
    assert got.weighted == pytest.approx(weighted, abs=1e-12)
    assert [got.weights[i] for i in IDS] == w and sum(w) == 15 and all(0 <= x <= 5 for x in w)


def test_a_hand_worked_sheet() -> None:
    # ratings 10..60; "effort" wins every pair it is in (weight 5), then mental 4, physical 3, temporal 2,
    # performance 1, frustration 0 (a strict order: the earlier in this list wins)
    ratings = dict(zip(IDS, [10.0, 20.0, 30.0, 40.0, 50.0, 60.0], strict=True))
    order = ["effort", "mental", "physical", "temporal", "performance", "frustration"]
    choices = {tlx.pair_id(a, b): min(a, b, key=order.index) for a, b in tlx.pairs()}
    s = tlx.score(ratings, choices)
    assert s.weights == {"mental": 4, "physical": 3, "temporal": 2, "performance": 1, "effort": 5, "frustration": 0}
    assert s.raw == pytest.approx(35.0, abs=1e-12)  # (10+20+30+40+50+60)/6
    assert s.weighted == pytest.approx((4 * 10 + 3 * 20 + 2 * 30 + 1 * 40 + 5 * 50 + 0 * 60) / 15, abs=1e-12)  # 30


def test_equal_ratings_give_that_rating_whatever_the_weights_and_raw_needs_no_pairs() -> None:
    ratings = dict.fromkeys(IDS, 45.0)
    choices = {tlx.pair_id(a, b): b for a, b in tlx.pairs()}
    s = tlx.score(ratings, choices)
    assert s.raw == pytest.approx(45.0, abs=1e-12) and s.weighted == pytest.approx(45.0, abs=1e-12)
    assert tlx.score(ratings).weighted is None


@pytest.mark.parametrize(("ratings", "choices", "expect"), [
    ({**dict.fromkeys(IDS, 50.0), "effort": 52.0}, None, "rating effort = 52.0: must be 0 to 100 in steps of 5"),
    ({**dict.fromkeys(IDS, 50.0), "mental": 105.0}, None, "rating mental = 105.0"),
    ({i: 50.0 for i in IDS[:5]}, None, "rating frustration = None"),
    (dict.fromkeys(IDS, 50.0), {"mental|physical": "effort"}, "pair mental|physical = 'effort': must be 'mental' or"),
])
def test_a_sheet_off_the_scale_is_refused_naming_the_item(ratings, choices, expect) -> None:
    with pytest.raises(ValueError, match=expect.replace("|", r"\|").replace("(", r"\(")):
        tlx.score(ratings, choices)
