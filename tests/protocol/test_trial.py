"""Tests of the trial state machine, fed synthetic sample blocks ``(t_ns, force_n, mark)``.

Times are on a loop clock that does not start at 0; samples are 1 ms apart unless stated.
"""

from __future__ import annotations

import math

import pytest

from protocol.study.config import TrialTiming
from protocol.study.design import TrialSpec
from protocol.study.trial import (
    PHASE_CODES,
    TRANSITIONS,
    PhaseChanged,
    TrialFinished,
    TrialMachine,
    TrialMachineError,
    TrialPhase,
)
from protocol.tasks.force_regulation import trial_metrics

MS = 1_000_000
S = 1_000_000_000
T0 = 7_777 * S + 123_456  # loop clock at the start of the test session (arbitrary, not aligned)
IDLE, CUED, ACTIVE, PAUSE = TrialPhase.IDLE, TrialPhase.CUED, TrialPhase.ACTIVE, TrialPhase.PAUSE
ANSWER = TrialPhase.ANSWER
SPEC = TrialSpec(3, "GENTLE", 0.6, "on")
PRE = 4  # samples the loop stamps before it applies the trial's mark


def _samples(force_of_ms, n_ms: int, *, pre: int = PRE, mark: int = 3, period_ns: int = MS, prev_mark: int = -1):
    """``pre`` unmarked samples, then marked samples k = 0 … n_ms−1 with force_of_ms(k·period/1 ms)."""
    out = [(T0 + i * period_ns, 5.0, prev_mark) for i in range(pre)]
    cue = T0 + pre * period_ns
    out += [(cue + k * period_ns, force_of_ms(k * period_ns / MS), mark) for k in range(n_ms)]
    return cue, out


def _machine() -> TrialMachine:
    return TrialMachine(TrialTiming())


def _run(samples, block: int | None = None, spec: TrialSpec = SPEC) -> list:
    m = _machine()
    events = list(m.start(spec, T0 - 10 * MS))
    if block is None:
        events += m.feed(samples)
    else:
        for i in range(0, len(samples), block):
            events += m.feed(iter(samples[i : i + block]))  # any iterable
    return events


def _success_trace(k_ms: float) -> float:
    # ramp 0 → 0.5 N in the first 500 ms (out of band), 0.6 N from 500 ms on
    return k_ms / 1000 if k_ms < 500 else 0.6


# -- the table ------------------------------------------------------------------------------------
def test_transitions_table_matches_the_phases():
    assert set(TRANSITIONS) == set(TrialPhase)
    assert {
        IDLE: frozenset({CUED}),
        CUED: frozenset({ACTIVE, PAUSE}),
        ACTIVE: frozenset({PAUSE, ANSWER}),
        ANSWER: frozenset({PAUSE}),  # a task that asks a question (force discrimination)
        PAUSE: frozenset({IDLE}),
    } == TRANSITIONS
    assert {str(p) for p in TrialPhase} == {"idle", "cued", "active", "pause", "answer"}
    assert PHASE_CODES == {IDLE: 0, CUED: 1, ACTIVE: 2, PAUSE: 3, ANSWER: 4}


def test_a_new_machine_is_idle():
    m = _machine()
    assert (m.phase, m.spec, m.cue_ns, m.elapsed_ns) == (IDLE, None, None, 0)
    assert m.feed([(T0, 0.6, 3)]) == []  # samples while idle are ignored
    assert m.phase is IDLE


# -- success --------------------------------------------------------------------------------------
def test_success_event_sequence():
    cue, samples = _samples(_success_trace, 4000)
    m = _machine()
    assert m.start(SPEC, T0 - 10 * MS) == [PhaseChanged(T0 - 10 * MS, 3, IDLE, CUED)]
    assert m.phase is CUED
    events = m.feed(samples)
    end = cue + 1500 * MS  # plateau at 500 ms + 1 s hold
    rel = [k * MS for k in range(1501)]
    expected_metrics = trial_metrics(rel, [_success_trace(k) for k in range(1501)], 0.6)
    assert events == [
        PhaseChanged(cue, 3, CUED, ACTIVE),
        TrialFinished(SPEC, "success", cue, end, expected_metrics, ""),
        PhaseChanged(end, 3, ACTIVE, PAUSE),
        PhaseChanged(end + 2 * S, 3, PAUSE, IDLE),
    ]
    assert expected_metrics.success and expected_metrics.n_samples == 1501
    assert expected_metrics["tct_s"] == pytest.approx(1.5, rel=1e-12)  # 1500 ticks × 1 ms, up to its rounding
    assert m.phase is IDLE and m.spec is None


def test_unmarked_samples_before_the_mark_are_ignored():
    # large, in-band forces before the loop applied the mark must not count or start the clock
    cue, samples = _samples(lambda k: 0.6, 1200, pre=300)
    samples[:300] = [(t, 0.6, -1) for t, _, _ in samples[:300]]
    events = _run(samples)
    finished = [e for e in events if isinstance(e, TrialFinished)]
    assert events[1] == PhaseChanged(cue, 3, CUED, ACTIVE)
    assert finished[0].cue_ns == cue == T0 + 300 * MS
    assert finished[0].end_ns == cue + 1 * S
    assert finished[0].metrics.n_samples == 1001


def test_samples_marked_with_the_previous_trial_are_ignored():
    cue, samples = _samples(lambda k: 0.6, 1200, pre=10, prev_mark=2)
    events = _run(samples)
    assert events[1] == PhaseChanged(cue, 3, CUED, ACTIVE)


def test_elapsed_time_follows_the_newest_sample():
    cue, samples = _samples(lambda k: 0.0, 500)
    m = _machine()
    m.start(SPEC, T0)
    m.feed(samples[:PRE])
    assert (m.phase, m.elapsed_ns, m.cue_ns) == (CUED, 0, None)
    m.feed(samples[PRE:])
    assert (m.phase, m.elapsed_ns, m.cue_ns) == (ACTIVE, 499 * MS, cue)


# -- timeout --------------------------------------------------------------------------------------
def test_timeout_at_exactly_cue_plus_12_s():
    cue, samples = _samples(lambda k: 0.0, 15000)
    events = _run(samples)
    end = cue + 12 * S
    metrics = trial_metrics([k * MS for k in range(12001)], [0.0] * 12001, 0.6)
    assert events == [
        PhaseChanged(T0 - 10 * MS, 3, IDLE, CUED),
        PhaseChanged(cue, 3, CUED, ACTIVE),
        TrialFinished(SPEC, "timeout", cue, end, metrics, ""),
        PhaseChanged(end, 3, ACTIVE, PAUSE),
        PhaseChanged(end + 2 * S, 3, PAUSE, IDLE),
    ]
    assert (metrics.success, metrics["tct_s"], metrics.n_samples, metrics.end_s) == (False, None, 12001, 12.0)


def test_timeout_is_at_cue_plus_12_s_when_no_sample_lands_on_it():
    # samples every 7 ms: 12 s falls between the samples at 11998 ms and 12005 ms
    cue, samples = _samples(lambda k: 0.0, 2300, period_ns=7 * MS)
    events = _run(samples)
    finished = [e for e in events if isinstance(e, TrialFinished)]
    assert len(finished) == 1
    assert (finished[0].outcome, finished[0].end_ns) == ("timeout", cue + 12 * S)
    assert finished[0].metrics.n_samples == 1715  # 0, 7, …, 11998 ms
    # the pause ends at the first sample at or after end + 2 s = cue + 14 s → 14000 ms (7 · 2000)
    assert events[-2:] == [PhaseChanged(cue + 12 * S, 3, ACTIVE, PAUSE), PhaseChanged(cue + 14 * S, 3, PAUSE, IDLE)]


def test_a_late_hold_completing_on_the_last_sample_is_a_success():
    cue, samples = _samples(lambda k: 0.6 if k >= 11000 else 0.0, 13000)
    finished = [e for e in _run(samples) if isinstance(e, TrialFinished)]
    assert [(f.outcome, f.end_ns, f.metrics["tct_s"]) for f in finished] == [("success", cue + 12 * S, 12.0)]


def test_a_gap_over_the_whole_pause_goes_straight_to_idle():
    # a sample gap from 11.5 s to 14.5 s after the cue: timeout at 12 s and the pause is over at 14 s
    cue, samples = _samples(lambda k: 0.0, 11501)
    samples.append((cue + 14_500 * MS, 0.0, 3))
    events = _run(samples)
    assert events[-3:-1] == [
        TrialFinished(SPEC, "timeout", cue, cue + 12 * S, events[-3].metrics, ""),
        PhaseChanged(cue + 12 * S, 3, ACTIVE, PAUSE),
    ]
    assert events[-1] == PhaseChanged(cue + 14_500 * MS, 3, PAUSE, IDLE)
    assert events[-3].metrics.n_samples == 11501


# -- the pause ------------------------------------------------------------------------------------
def test_pause_lasts_exactly_2_s():
    cue, samples = _samples(_success_trace, 3499)  # up to 3498 ms: end (1500 ms) + 2 s − 2 ms
    m = _machine()
    m.start(SPEC, T0)
    m.feed(samples)
    end = cue + 1500 * MS
    assert (m.phase, m.pause_until_ns) == (PAUSE, end + 2 * S)
    assert m.feed([(end + 2 * S - 1, 0.0, 3)]) == []  # 1 ns before the end of the pause
    assert m.phase is PAUSE
    assert m.feed([(end + 2 * S, 0.0, 3), (end + 2 * S + MS, 0.0, 3)]) == [PhaseChanged(end + 2 * S, 3, PAUSE, IDLE)]
    assert m.phase is IDLE


def test_pause_length_follows_the_timing():
    m = TrialMachine(TrialTiming(pause_s=0.25))
    cue, samples = _samples(lambda k: 0.6, 2000)
    m.start(SPEC, T0)
    events = m.feed(samples)
    assert events[-1] == PhaseChanged(cue + 1250 * MS, 3, PAUSE, IDLE)


def test_next_trial_after_the_pause():
    _, samples = _samples(lambda k: 0.6, 3100)
    m = _machine()
    m.start(SPEC, T0)
    m.feed(samples)
    assert m.phase is IDLE
    nxt = TrialSpec(4, "FIRM", 1.2, "off")
    t = samples[-1][0]
    assert m.start(nxt, t) == [PhaseChanged(t, 4, IDLE, CUED)]
    later = [(t + k * MS, 1.2, 3 if k < 3 else 4) for k in range(1, 1010)]
    events = m.feed(later)
    cue2 = t + 3 * MS  # k = 1, 2 still carry the old mark
    assert events[0] == PhaseChanged(cue2, 4, CUED, ACTIVE)
    assert (events[1].spec, events[1].outcome, events[1].cue_ns, events[1].end_ns) == (nxt, "success", cue2, cue2 + S)
    assert events[1].metrics.n_samples == 1001  # nothing carried over from trial 3


# -- block independence ---------------------------------------------------------------------------
@pytest.mark.parametrize("trace", ["success", "timeout", "interrupted"])
def test_decisions_do_not_depend_on_block_size(trace):
    force = {
        "success": _success_trace,
        "timeout": lambda k: 0.3 if int(k) % 900 < 450 else 0.6,
        "interrupted": lambda k: math.nan if k == 2222 else (1.0 if k < 1800 else 0.63),
    }[trace]
    _, samples = _samples(force, 16000, pre=9)
    reference = _run(samples)
    assert any(isinstance(e, TrialFinished) for e in reference)
    assert reference[-1].new is IDLE
    for block in (1, 7, 1000, 2003):
        assert _run(samples, block=block) == reference


def test_interrupted_hold_tct_in_the_machine():
    _, samples = _samples(lambda k: math.nan if k == 2222 else (1.0 if k < 1800 else 0.63), 5000)
    finished = [e for e in _run(samples, block=7) if isinstance(e, TrialFinished)]
    assert [(f.outcome, f.end_ns - f.cue_ns, f.metrics["tct_s"]) for f in finished] == [("success", 3223 * MS, 3.223)]


# -- abort ----------------------------------------------------------------------------------------
def test_abort_while_cued():
    m = _machine()
    m.start(SPEC, T0)
    m.feed([(T0 + MS, 0.0, -1)])
    events = m.abort(T0 + 5 * MS, "participant asked to stop")
    assert len(events) == 2
    done, changed = events
    assert (done.spec, done.outcome, done.cue_ns, done.end_ns, done.reason) == (
        SPEC, "aborted", T0 + 5 * MS, T0 + 5 * MS, "participant asked to stop"
    )
    assert done.metrics.n_samples == 0 and done.metrics.success is False
    assert changed == PhaseChanged(T0 + 5 * MS, 3, CUED, PAUSE)
    assert m.pause_until_ns == T0 + 5 * MS + 2 * S


def test_abort_while_active():
    cue, samples = _samples(lambda k: 0.0 if k < 100 else 0.6, 800)
    m = _machine()
    m.start(SPEC, T0)
    m.feed(samples)
    assert m.phase is ACTIVE
    t_abort = samples[-1][0] + MS
    events = m.abort(t_abort, "probe slipped")
    metrics = trial_metrics([k * MS for k in range(800)], [0.0 if k < 100 else 0.6 for k in range(800)], 0.6)
    assert events == [
        TrialFinished(SPEC, "aborted", cue, t_abort, metrics, "probe slipped"),
        PhaseChanged(t_abort, 3, ACTIVE, PAUSE),
    ]
    assert metrics.n_samples == 800
    # the pause runs as after any other trial
    assert m.feed([(t_abort + 2 * S, 0.6, 3)]) == [PhaseChanged(t_abort + 2 * S, 3, PAUSE, IDLE)]


# -- illegal transitions --------------------------------------------------------------------------
def test_abort_while_idle_is_refused():
    m = _machine()
    with pytest.raises(TrialMachineError, match="no trial to abort in phase idle"):
        m.abort(T0, "x")
    assert m.phase is IDLE


def test_abort_while_paused_is_refused():
    m = _machine()
    m.start(SPEC, T0)
    m.abort(T0 + MS, "first")
    with pytest.raises(TrialMachineError, match="no trial to abort in phase pause"):
        m.abort(T0 + 2 * MS, "second")
    assert m.phase is PAUSE


@pytest.mark.parametrize("phase", [CUED, ACTIVE, PAUSE])
def test_start_outside_idle_is_refused_and_changes_nothing(phase):
    _, samples = _samples(_success_trace, 4000)
    m = _machine()
    m.start(SPEC, T0)
    n = {CUED: PRE, ACTIVE: PRE + 100, PAUSE: PRE + 1600}[phase]
    m.feed(samples[:n])
    assert m.phase is phase
    other = TrialSpec(9, "FIRM", 1.2, "off")
    with pytest.raises(TrialMachineError, match=f"illegal trial transition {phase} → cued"):
        m.start(other, samples[n][0])
    # the running trial carries on as if nothing had been asked
    assert (m.phase, m.spec) == (phase, SPEC)
    rest = m.feed(samples[n:])
    reference = _run(samples)
    assert rest == reference[len(reference) - len(rest) :]
    assert [e.spec for e in rest if isinstance(e, TrialFinished)] == ([SPEC] if phase is not PAUSE else [])
    assert all(e.trial_index == 3 for e in rest if isinstance(e, PhaseChanged))
