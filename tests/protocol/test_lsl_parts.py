"""The parts of a session on the Lab Streaming Layer, each alone: the protocol's ``[lsl]`` table, the clock link
with a known offset, the outlets (on a recording stand-in for pylsl: the band entry, the markers, a failure that is
an event), and the refusals before anything is stored (virtual clock, parallel jobs, a stream not found, pylsl
missing).  The real library on this machine is ``test_lsl_session.py``'s."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.core.tick_record import TICK_DTYPE
from protocol.lsl.bus import ClockLink, LslUnavailable, measure_link, pylsl
from protocol.lsl.outlets import FORCE_CHANNELS, SessionIds, SessionOutlets, marker_text
from protocol.study.config import ProtocolError, default_protocol, protocol_from_dict
from protocol.study.design import TrialSpec
from protocol.study.lsl_settings import parse_selector
from protocol.study.trial import PHASE_CODES, TrialPhase
from study_app.cli.main import main


def _with_lsl(table: object) -> dict:
    d = default_protocol().to_dict()
    d["lsl"] = table
    return d


def test_a_protocol_without_lsl_stores_what_it_always_stored() -> None:
    p = default_protocol()
    assert not p.lsl.on and "lsl" not in json.loads(p.to_json())
    q = protocol_from_dict(_with_lsl({"outlets": True, "record": [{"name": "EMG forearm"}, {"type": "EEG"}]}))
    assert q.lsl.outlets and [s.words() for s in q.lsl.record] == ["name = 'EMG forearm'", "type = 'EEG'"]
    assert protocol_from_dict(json.loads(q.to_json())).lsl == q.lsl  # (a resume reads back what ran)
    assert p.lsl.with_outlets().to_dict() == {"outlets": True, "resolve_timeout_s": 5.0, "record": []}


@pytest.mark.parametrize(("table", "words"), [
    ({"record": [{"nam": "EMG"}]}, "lsl.record[0].nam"),
    ({"record": [{"name": "EMG", "type": "EMG"}]}, "lsl.record[0]"),
    ({"record": [{"name": ""}]}, "lsl.record[0].name"),
    ({"record": [{"name": "EMG"}, {"name": "EMG"}]}, "each stream named once"),
    ({"outlets": "yes"}, "lsl.outlets"),
    ({"resolve_timeout_s": 0}, "lsl.resolve_timeout_s"),
    ({"resolve_timeout_s": 600}, "lsl.resolve_timeout_s"),
    ({"inlets": []}, "lsl.inlets"),
])
def test_a_bad_lsl_table_is_one_line_naming_the_field(table: dict, words: str) -> None:
    with pytest.raises(ProtocolError) as err:
        protocol_from_dict(_with_lsl(table))
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_selector_on_the_command_line() -> None:
    assert parse_selector("type=EEG").words() == "type = 'EEG'"
    with pytest.raises(ValueError, match="name=STREAM or type=TYPE"):
        parse_selector("source=x")


def test_the_clock_link_with_a_known_offset() -> None:
    """Two clocks 12.5 s apart, each read 1 µs after the other: the link is the offset plus the loop's zero, to half
    the bracket (LSL's reading lies between the loop clock's two)."""
    loop_ns = iter(range(5_000_000_000, 6_000_000_000, 1000))
    now = 0

    def now_ns() -> int:
        nonlocal now
        now = next(loop_ns)
        return now

    def local_clock() -> float:
        return (now + 500) * 1e-9 + 12.5

    link = measure_link(4_000_000_000, local_clock, now_ns, rounds=10)
    assert link.uncertainty_s == pytest.approx(500e-9, abs=1e-12)  # half the 1 µs bracket (exact integers, so 1e-12)
    assert link.records_to_lsl_s == pytest.approx(4.0 + 12.5, abs=1e-9)  # (float seconds of ~16 s: 1 ns is generous)
    assert link.lsl_s(1_000_000) == pytest.approx(16.501, abs=1e-9)
    assert link.records_ns(link.lsl_s(123_456_789)) == pytest.approx(123_456_789, abs=1.0)


class _FakeOutlet:
    def __init__(self, info: object, *args: object) -> None:
        self.info, self.pushed, self.fail = info, [], False

    def push_chunk(self, chunk: np.ndarray, stamps: list[float]) -> None:
        if self.fail:
            raise RuntimeError("the network went away")
        self.pushed.append((chunk, stamps))

    def push_sample(self, sample: list[str], stamp: float) -> None:
        self.pushed.append((json.loads(sample[0]), stamp))

    def have_consumers(self) -> bool:
        return False


class _FakeLib:
    """pylsl's surface the outlets use, recording what is pushed."""

    IRREGULAR_RATE = 0.0
    StreamOutlet = _FakeOutlet

    class StreamInfo:
        def __init__(self, *args: object) -> None:
            self.args = args

        def desc(self) -> _FakeLib.StreamInfo:
            return self

        def append_child(self, name: str) -> _FakeLib.StreamInfo:
            return self

        def append_child_value(self, name: str, value: str) -> None:
            pass


def _rows(t_ns: np.ndarray, force: np.ndarray, trial: int, phase: TrialPhase) -> np.ndarray:
    rows = np.zeros(len(t_ns), dtype=TICK_DTYPE)
    rows["t_ns"], rows["force_n"], rows["trial_index"], rows["phase"] = t_ns, force, trial, PHASE_CODES[phase]
    return rows


def test_the_outlets_stamp_each_tick_and_mark_the_band_entry() -> None:
    task = default_protocol().task
    failures: list[tuple[int, str]] = []
    link = ClockLink(records_to_lsl_s=100.0, uncertainty_s=1e-6)
    out = SessionOutlets(_FakeLib, link, SessionIds("s", "P01", 1, "experiment"), task,
                         lambda t, why: failures.append((t, why)))
    spec = TrialSpec(0, "FIRM", 1.0, "on")
    out.mark(5_000_000, "cue", "trial 1 (index 0): FIRM", spec)
    t = 10_000_000 + np.arange(50) * 1_000_000  # 50 ticks, 1 ms apart
    force = np.linspace(0.0, 1.0, 50)  # into the 10 % band (0.9–1.1 N) part-way
    out.samples(_rows(t, force, 0, TrialPhase.ACTIVE))
    chunk, stamps = out.force.pushed[0]
    assert chunk.shape == (50, len(FORCE_CHANNELS)) and chunk.dtype == np.float32
    assert stamps[0] == pytest.approx(100.010, abs=1e-12) and stamps[1] - stamps[0] == pytest.approx(1e-3, abs=1e-9)
    markers = out.markers.pushed
    assert [m["event"] for m, _ in markers] == ["cue", "band_entry"]
    first_in = int(np.flatnonzero(np.abs(force - 1.0) <= 0.1 + 1e-9)[0])
    assert markers[1][1] == pytest.approx(link.lsl_s(int(t[first_in])), abs=1e-12)
    assert markers[1][0]["trial"] == 1 and markers[1][0]["condition"] == "FIRM 1 N, haptics on"
    out.samples(_rows(t + 50_000_000, force, 0, TrialPhase.ACTIVE))  # (once per trial)
    assert len(out.markers.pushed) == 2
    out.mark(60_000_000, "success", "", spec)
    out.mark(61_000_000, "session_end", "completed: all trials done", spec)
    assert out.markers.pushed[-1][0] == {"event": "session_end", "detail": "completed: all trials done"}
    out.force.fail = True
    out.samples(_rows(t + 90_000_000, force, 0, TrialPhase.PAUSE))
    assert len(failures) == 1 and "LSL outlets stopped" in failures[0][1] and out.closed
    out.mark(99_000_000, "cue", "", spec)  # (closed: nothing more, no error)


def test_marker_text_names_the_trial_from_one() -> None:
    m = json.loads(marker_text("abort", TrialSpec(3, "GENTLE", 0.6, "off"), "gap"))
    assert (m["trial"], m["trial_index"], m["haptics"], m["detail"]) == (4, 3, "off", "gap")


def test_pylsl_missing_is_one_line_saying_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pylsl", None)  # (import pylsl raises ImportError)
    with pytest.raises(LslUnavailable) as err:
        pylsl()
    assert "pip install 'haptic-study[lsl]'" in str(err.value) and "\n" not in str(err.value)


def _run(tmp_path: Path, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    db = tmp_path / "s.db"
    assert main(["run", "--participants", "1", "--db", str(db), *args]) == 2
    assert not db.exists()  # nothing stored
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    return err


def test_the_refusals_before_anything_is_stored(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "--lsl needs --clock real" in _run(tmp_path, capsys, "--lsl")
    assert "--jobs = 2 with --lsl" in _run(tmp_path, capsys, "--lsl", "--clock", "real", "--jobs", "2")
    import tomllib

    p = tmp_path / "p.toml"  # the default protocol with a stream no one publishes, looked for 0.2 s
    d = _with_lsl({"record": [{"name": "no such stream 7f3a"}], "resolve_timeout_s": 0.2})
    p.write_text(_toml(d), encoding="utf-8")
    assert tomllib.loads(p.read_text(encoding="utf-8"))["lsl"]["record"][0]["name"] == "no such stream 7f3a"
    err = _run(tmp_path, capsys, "--protocol", str(p), "--clock", "real")
    assert "no LSL stream with name = 'no such stream 7f3a' was found within 0.2 s" in err


def _toml(d: dict) -> str:
    """A protocol's plain data as a TOML file (the tables this test writes)."""
    lines = [f"name = {json.dumps(d['name'])}"]
    for t in d["targets"]:
        lines += ["[[targets]]", f"label = {json.dumps(t['label'])}", f"force_n = {t['force_n']}"]
    lsl = d["lsl"]
    lines += ["[lsl]", f"resolve_timeout_s = {lsl['resolve_timeout_s']}"]
    lines += [f"[[lsl.record]]\nname = {json.dumps(r['name'])}" for r in lsl["record"]]
    return "\n".join(lines) + "\n"
