"""A schedule of visits above the parts (``[[visits]]``, protocol/study/visits.py): validated in one line, each
participant's plan visit after visit (counterbalanced within a visit), the visit stored beside the part, and a
participant's schedule with each visit's state (protocol/runner/visit_schedule.py)."""

from __future__ import annotations

import datetime as dt
import json

import pytest

from protocol.runner.study_rules import StoredSession
from protocol.runner.visit_schedule import visit_refusal, visit_schedule
from protocol.study.config import ProtocolError, load_protocol, protocol_from_dict
from tests.parts_plan import PLAN

VISITS = """
[[visits]]
name = "baseline"
day = 0
parts = ["practice", "regulation", "tracking", "firm"]
role = "baseline"
[[visits]]
name = "train"
day = 1
parts = ["regulation"]
role = "training"
[[visits]]
name = "post"
day = 3
window_days = 1
parts = ["regulation", "tracking", "firm"]
role = "post"
[[visits]]
name = "keep"
day = 10
window_days = 2
parts = ["regulation"]
role = "retention"
"""


def _load(tmp_path, text: str):
    path = tmp_path / "p.toml"
    path.write_text(text, encoding="utf-8")
    return load_protocol(path)


def test_a_file_without_visits_reads_as_before(tmp_path) -> None:
    p = _load(tmp_path, PLAN)
    assert p.visits == () and "visits" not in json.loads(p.to_json())
    assert all(q.part is not None and q.part.visit is None and "visit" not in json.loads(q.to_json())["part"]
               for q in p.plan_for(2, 0))


def test_the_plan_goes_visit_after_visit_counterbalanced_within_each(tmp_path) -> None:
    p = _load(tmp_path, PLAN + VISITS)
    assert protocol_from_dict(json.loads(p.to_json())) == p  # the stored study reads back the same
    for n in (1, 2, 3, 4):
        plan = p.plan_for(n, 0)
        names = [(q.part.visit.name, q.part.name) for q in plan]  # type: ignore[union-attr]
        assert [v for v, _ in names] == ["baseline"] * 4 + ["train"] + ["post"] * 3 + ["keep"]
        base = [q.part.name for q in plan[:4]]  # type: ignore[union-attr]
        post = [q.part.name for q in plan[5:8]]  # type: ignore[union-attr]
        assert base[0] == "practice" and base[1:] == post  # the participant's row, in each visit that holds them
        assert [q.part.position for q in plan[5:8]] == [1, 2, 3]  # type: ignore[union-attr]
        assert all(q.part.trained_by == ("practice",) for q in plan[5:])  # type: ignore[union-attr]
        keep = plan[-1].part
        assert keep is not None and keep.visit is not None
        assert (keep.visit.number, keep.visit.day, keep.visit.gap_days, keep.visit.role) == (4, 10, 7, "retention")
        stored = protocol_from_dict(json.loads(plan[-1].to_json()), "stored")
        assert stored.part == keep  # the visit read back from the session's record
    with pytest.raises(KeyError, match="no visit 'later'"):
        p.part_of("regulation", 1, 0, "later")
    assert p.part_of("regulation", 1, 0, "keep").part.visit.name == "keep"  # type: ignore[union-attr]


@pytest.mark.parametrize(("old", "new", "said"), [
    ('parts = ["regulation"]\nrole = "training"', 'parts = ["regulation", "nope"]\nrole = "training"',
     "visits[2].parts = ['regulation', 'nope']: names no part 'nope'"),
    ('day = 3\nwindow_days = 1', 'day = 1\nwindow_days = 0', "visits[3].day = 1: days must increase"),
    ('name = "keep"', 'name = "train"', "visits[4].name = 'train': names must be unique"),
    ('day = 10\nwindow_days = 2\nparts = ["regulation"]\nrole = "retention"',
     'day = 10\nwindow_days = 2\nparts = ["regulation"]\nrole = "post"', "visits[4].role = 'post': at most one post"),
    ('role = "post"', 'role = "training"', "visits[4].role = 'retention': a retention visit needs a post visit"),
    ('day = 3\nwindow_days = 1', 'day = 2\nwindow_days = 1', "visits[3].window_days = 1: the window (days 1–3)"),
    ('name = "baseline"\nday = 0', 'name = "baseline"\nday = 1', "visits[1].day = 1: the first visit's day must be 0"),
    ('role = "retention"', 'role = "later"', "visits[4].role = 'later'"),
])
def test_a_bad_schedule_is_refused_in_one_line(tmp_path, old, new, said) -> None:
    assert old in VISITS
    with pytest.raises(ProtocolError) as err:
        _load(tmp_path, PLAN + VISITS.replace(old, new, 1))
    assert said in str(err.value) and "\n" not in str(err.value)


def test_retention_before_the_post_test_is_refused(tmp_path) -> None:
    swapped = VISITS.replace('role = "post"', 'role = "RET"').replace('role = "retention"', 'role = "post"')
    with pytest.raises(ProtocolError, match=r"visits\[3\]\.role = 'retention': a retention visit must come after"):
        _load(tmp_path, PLAN + swapped.replace('role = "RET"', 'role = "retention"'))


def test_a_part_in_no_visit_and_visits_without_parts_are_refused(tmp_path) -> None:
    with pytest.raises(ProtocolError, match="no visit holds the part 'tracking'"):
        _load(tmp_path, PLAN + VISITS.replace('"regulation", "tracking", "firm"]', '"regulation", "firm"]').replace(
            '"practice", "regulation", "firm"', '"practice", "regulation", "firm"'))
    with pytest.raises(ProtocolError, match=r"visits = .*: a schedule of visits sequences the study's \[\[parts\]\]"):
        _load(tmp_path, 'name = "x"\n[[targets]]\nlabel = "A"\nforce_n = 1.0\n' + VISITS)


def _sessions(p, visits_done: dict[str, str]) -> list[StoredSession]:
    """P01's stored sessions: every part of the named visits with the given status."""
    out, sid = [], 0
    for q in p.plan_for(1, 0):
        v = q.part.visit.name
        if v in visits_done:
            sid += 1
            out.append(StoredSession(sid, "P01", q.part.session, visits_done[v], 0, q.part.name, v))
    return out


def test_the_schedule_says_what_is_done_due_overdue_and_next(tmp_path) -> None:
    p = _load(tmp_path, PLAN + VISITS)
    first = dt.date(2026, 3, 2)
    fresh = visit_schedule(p, 1, 0, [], "P01", None, first)
    assert [v.state for v in fresh.visits] == ["due", "not yet", "not yet", "not yet"]
    assert fresh.next == ("baseline", "practice")
    done = _sessions(p, {"baseline": "completed", "train": "completed"})
    on_day_3 = visit_schedule(p, 1, 0, done, "P01", first, first + dt.timedelta(days=3))
    assert [v.state for v in on_day_3.visits] == ["done", "done", "due", "not yet"]
    post = on_day_3.visit("post")
    assert (post.earliest, post.latest) == (first + dt.timedelta(days=2), first + dt.timedelta(days=4))
    assert on_day_3.next is not None and on_day_3.next[0] == "post"
    late = visit_schedule(p, 1, 0, done, "P01", first, first + dt.timedelta(days=5))
    assert late.visit("post").state == "overdue"
    assert visit_refusal(on_day_3, "post", 3) == ""
    assert "outside its window: held on study day 6, planned for day 3 ± 1" in visit_refusal(late, "post", 6)
    assert "out of order: the earlier visit 'post' is not done" in visit_refusal(on_day_3, "keep", 10)
    assert "is done" in visit_refusal(on_day_3, "train", 1)
    partly = _sessions(p, {"baseline": "completed", "train": "running"})
    resumed = visit_schedule(p, 1, 0, partly, "P01", first, first + dt.timedelta(days=1))
    assert resumed.visit("train").parts == (("regulation", "interrupted"),) and resumed.next == ("train", "regulation")
