"""A study as a sequence of task blocks (``[[parts]]``, :mod:`protocol.study.parts`): the file read, each part
validated as a protocol, the counterbalanced order over participants, bad input one line."""

from __future__ import annotations

import itertools
import json
from collections import Counter
from pathlib import Path

import pytest

from protocol.study.config import ProtocolError, default_protocol, load_protocol, protocol_from_dict
from protocol.study.parts import Counterbalance, balanced_rows, order_of
from tests.parts_plan import PLAN

ROOT = Path(__file__).resolve().parents[2]
BATTERY = ROOT / "docs" / "examples" / "battery.toml"

def _load(tmp_path: Path, text: str) -> object:
    path = tmp_path / "p.toml"
    path.write_text(text, encoding="utf-8")
    return load_protocol(path)


def _error(tmp_path: Path, text: str) -> str:
    with pytest.raises(ProtocolError) as info:
        _load(tmp_path, text)
    message = str(info.value)
    assert "\n" not in message  # one line
    return message


def test_a_file_without_parts_stores_what_it_always_stored() -> None:
    d = default_protocol().to_dict()
    assert not {"parts", "part", "counterbalance"} & set(d)
    assert default_protocol().parts == () and default_protocol().plan_for(1, 0) == ()


def test_each_part_is_a_protocol_of_its_own_over_the_study_tables(tmp_path: Path) -> None:
    p = _load(tmp_path, PLAN)
    assert p.part_names == ("practice", "regulation", "tracking", "firm")
    by = {q.part.name: q for q in p.parts}
    assert by["practice"].part.session == "training" and by["practice"].task.kind == "force_regulation"
    assert by["tracking"].task.kind == "force_tracking" and by["tracking"].trial.max_trial_s == 3.0
    assert by["tracking"].trial.pause_s == 0.3  # the study's timing, under the part's own fields
    assert [t.label for t in by["firm"].targets] == ["FIRM"] and by["firm"].trial.max_trial_s == 2.0
    # a stored part reads back as itself (its place in a participant's order with it)
    for part in p.plan_for(3, 7):
        assert protocol_from_dict(json.loads(part.to_json())) == part
    assert protocol_from_dict(json.loads(p.to_json())) == p


def test_the_battery_example_loads() -> None:
    p = load_protocol(BATTERY)
    assert [q.task.kind for q in p.parts] == ["force_regulation", "force_regulation", "force_tracking",
                                              "force_discrimination"]
    assert p.counterbalance == Counterbalance(("regulation", "tracking", "discrimination"), "latin_square")


@pytest.mark.parametrize("seed", [0, 1, 12345])
def test_each_order_equally_often_over_the_square_rows(tmp_path: Path, seed: int) -> None:
    p = _load(tmp_path, PLAN)
    orders = [tuple(q.part.name for q in p.plan_for(n, seed)) for n in range(1, 13)]
    assert all(o[0] == "practice" for o in orders)  # not counterbalanced: stays in its place
    counts = Counter(o[1:] for o in orders)
    # three parts: the balanced square's 6 rows are the 6 orders, each twice in 12 participants
    assert set(counts) == set(itertools.permutations(("regulation", "tracking", "firm")))
    assert set(counts.values()) == {2}
    # each part in each place equally often
    for place in range(1, 4):
        assert set(Counter(o[place] for o in orders).values()) == {4}


def test_the_seed_deals_the_rows_and_fixes_them() -> None:
    names = ("a", "b", "c", "d")
    balance = Counterbalance(names, "latin_square")
    firsts = {order_of(names, balance, seed, 1)[0] for seed in range(20)}
    assert len(firsts) > 1  # which participant gets which row is drawn from the seed
    assert order_of(names, balance, 5, 3) == order_of(names, balance, 5, 3)


@pytest.mark.parametrize("k", [2, 3, 4, 5, 6])
def test_williams_square_is_latin_and_carryover_balanced(k: int) -> None:
    rows = balanced_rows(k)
    assert len(rows) == (k if k % 2 == 0 else 2 * k)
    for row in rows:
        assert sorted(row) == list(range(k))
    for place in range(k):  # each treatment in each place equally often
        assert len(set(Counter(r[place] for r in rows).values())) == 1
    pairs = Counter((r[i], r[i + 1]) for r in rows for i in range(k - 1))
    assert len(pairs) == k * (k - 1) and len(set(pairs.values())) == 1  # each ordered pair equally often


def test_rotation_gives_each_part_each_place_once() -> None:
    names = ("a", "b", "c")
    balance = Counterbalance(names, "rotation")
    orders = Counter(order_of(names, balance, 0, n)[0] for n in range(1, 7))
    assert set(orders) == {("a", "b", "c"), ("b", "c", "a"), ("c", "a", "b")} and set(orders.values()) == {2}


BAD = [
    ("an unknown task kind in a part", ('name = "tracking"\n[parts.task]\nkind = "force_tracking"',
                                        'name = "tracking"\n[parts.task]\nkind = "juggling"'),
     "part 'tracking' (parts[3]): task.kind = 'juggling': allowed values: force_regulation, force_tracking, "),
    ("a part without trials", ('name = "firm"\n[[parts.targets]]', 'name = "firm"\n[[parts.nothing]]'),
     "parts[4].nothing = [{"),
    ("a part whose targets are none", ('[[parts.targets]]\nlabel = "FIRM"\nforce_n = 1.2\n',
                                       'targets = []\n'),
     "part 'firm' (parts[4]): targets = []: must be a list of 1 to 8 [[targets]] tables"),
    ("a training part without training", ('session = "training"', 'session = "training"\n[parts.training]\n'
                                                                   'enabled = false'),
     "part 'practice' (parts[1]): session = 'training': the part's training.enabled is false"),
    ("a counterbalance group naming an unknown part", ('parts = ["regulation", "tracking", "firm"]',
                                                       'parts = ["regulation", "tracking", "soft"]'),
     "counterbalance.parts = ['regulation', 'tracking', 'soft']: names no part 'soft'"),
    ("a part twice in the group", ('parts = ["regulation", "tracking", "firm"]',
                                   'parts = ["regulation", "tracking", "tracking"]'),
     "each part at most once"),
    ("an unknown counterbalancing method", ('parts = ["regulation", "tracking", "firm"]',
                                            'parts = ["regulation", "tracking", "firm"]\nmethod = "random"'),
     "counterbalance.method = 'random': allowed values: latin_square, rotation"),
    ("two parts of one name", ('name = "firm"', 'name = "regulation"'),
     "parts[4].name = 'regulation': names must be unique among the parts"),
    ("a part name in capitals", ('name = "firm"', 'name = "Firm"'), "parts[4].name = 'Firm': must be a lower-case"),
    ("a session kind of none", ('session = "training"', 'session = "warmup"'),
     "parts[1].session = 'warmup': allowed values: training, experiment"),
    ("a part's own bad value", ("frequency_hz = 0.5", "frequency_hz = 5.0"),
     "part 'tracking' (parts[3]): task.frequency_hz = 5.0"),
    ("a stored place written in a file", ('name = "tiny plan"', 'name = "tiny plan"\npart = {name = "x"}'),
     "part = {'name': 'x'}: is stored with each session of a [[parts]] study, not written in a protocol file"),
]


@pytest.mark.parametrize(("old_new", "expected"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_naming_the_part_and_field(tmp_path: Path, old_new: tuple[str, str],
                                                         expected: str) -> None:
    old, new = old_new
    assert old in PLAN
    assert expected in _error(tmp_path, PLAN.replace(old, new, 1))


def test_a_study_of_practice_only_is_refused(tmp_path: Path) -> None:
    text = PLAN[:PLAN.index('[[parts]]\nname = "regulation"')]
    assert "parts = ['practice']: at least one part must be an experiment session" in _error(tmp_path, text)


def test_counterbalance_without_parts_is_refused(tmp_path: Path) -> None:
    text = PLAN[:PLAN.index("[[parts]]")] + '[counterbalance]\nparts = ["a", "b"]\n'
    assert "counterbalance = " in _error(tmp_path, text) and "the file has none" in _error(tmp_path, text)
