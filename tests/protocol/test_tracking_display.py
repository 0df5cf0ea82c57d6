"""What the participant screen shows of a tracked target (issue 43): ``[task] display`` -- the band at present, a
trace of the target's course ahead, or the word only -- validated in the protocol file and drawn so."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from protocol.study.config import ProtocolError, protocol_from_dict
from protocol.tasks.force_tracking import ForceTracking
from protocol.tasks.registry import task_tables
from study_app.engine import messages as m
from study_app.models.participant import ParticipantScreenModel

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "tracking.toml"


def _read(**task: object) -> ForceTracking:
    d = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    d["task"].update(task)
    t = protocol_from_dict(d, "tracking.toml").task
    assert isinstance(t, ForceTracking)
    return t


def test_the_display_is_read_stored_and_read_back() -> None:
    assert _read().display == "present"  # the default: what a protocol without the field always showed
    assert "display" not in task_tables(_read())[0]  # ... and stores what it always stored
    t = _read(display="trace_ahead", ahead_s=3.0)
    stored, _ = task_tables(t)
    assert stored is not None and stored["display"] == "trace_ahead" and stored["ahead_s"] == 3.0
    d = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    assert protocol_from_dict({**d, "task": stored}, "stored").task == t


@pytest.mark.parametrize(("task", "message"), [
    ({"display": "hologram"}, "task.display = 'hologram': "),
    ({"display": "trace_ahead", "ahead_s": 30.0}, "task.ahead_s = 30.0: "),
    ({"ahead_s": 2.0}, "task.ahead_s = 2.0: is read only with task.display = 'trace_ahead'"),
])
def test_a_bad_display_is_refused_in_one_line(task, message) -> None:
    with pytest.raises(ProtocolError) as e:
        _read(**task)
    assert str(e.value).startswith(f"tracking.toml: {message}") and "\n" not in str(e.value)


def _screen(task: ForceTracking, t_s: float) -> ParticipantScreenModel:
    fields = {f: None for f in m.SessionStarted.__dataclass_fields__}
    fields.update(kind="experiment", live_force_aid=False, cue_s=1.0, task=task)
    model = ParticipantScreenModel()
    model.apply(m.SessionStarted(**fields))
    trial = {f: None for f in m.TrialStarted.__dataclass_fields__}
    trial.update(target_label="TRACK", target_force_n=0.8, haptic_mode="off", t_s=10.0)
    model.apply(m.TrialStarted(**trial))
    model.update(t_s, 0.9)
    return model


def test_the_trace_ahead_is_the_bands_course_and_the_word_only_hides_it() -> None:
    ramp = {"profile": "ramp", "from_n": 0.2, "to_n": 1.0, "lead_in_s": 1.0, "duration_s": 4.0, "band_n": 0.1}
    ahead = ForceTracking(**ramp, display="trace_ahead", ahead_s=2.0)
    s = _screen(ahead, 12.0).screen  # 2 s after the cue: the band at 0.4 N, the trace to 4 s (0.8 N)
    assert s.band_n == pytest.approx((0.3, 0.5)) and s.gauge_force_n is None
    first, last = s.trace[0], s.trace[-1]
    assert first == pytest.approx((0.0, 0.3, 0.5)) and last == pytest.approx((1.0, 0.7, 0.9))  # (N: exact ramp)
    assert _screen(ForceTracking(**ramp), 12.0).screen.trace == ()  # at present only: no trace
    word = _screen(ForceTracking(**ramp, display="word"), 12.0).screen
    assert word.band_n is None and not word.show_gauge and word.headline == "TRACK" and word.trace == ()
