"""The study engine as a process of its own (the one engine process): start, every record read, stop, timing.

The simulated engine runs on the virtual clock (as fast as the CPU allows), so
these tests wait only for process start-up and exit, with bounded timeouts.
The real rig's start (devices opened one by one, a failing or hanging device
named) is in tests/backends/test_engine_hardware.py.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.runtime.loop_messages import RECORD_FIELDS
from study_app.engine import messages as m
from study_app.engine.client import EngineClient, describe_exit
from study_app.engine.setup import HostConfig

START_TIMEOUT_S = 60.0
EXIT_TIMEOUT_S = 15.0
PERIOD_NS = 1_000_000


def events_until(client: EngineClient, pred, timeout_s: float = EXIT_TIMEOUT_S) -> list[object]:
    """Events read until one satisfies ``pred`` (bounded; nothing sleeps)."""
    seen: list[object] = []
    end = time.monotonic() + timeout_s
    while not (seen and pred(seen[-1])):
        assert time.monotonic() < end, f"timed out; events: {[type(x).__name__ for x in seen]}"
        ev = client.get(0.05)
        if ev is not None:
            seen.append(ev)
    return seen


def test_the_engine_process_runs_the_loop_and_the_gui_side_reads_every_record():
    client = EngineClient(HostConfig(clock="virtual", speed=0))
    try:
        ready, _ = client.wait_ready(START_TIMEOUT_S)
        assert ready.rig == "sim" and ready.clock == "virtual" and "force_bias_n" in str(ready.calibration)
        ring = client.ring
        assert ring is not None and ring.fields == RECORD_FIELDS
        cursor, rows = 0, []
        end = time.monotonic() + EXIT_TIMEOUT_S
        while cursor < 3000:  # the engine writes at CPU speed while we read: nothing may be lost
            assert time.monotonic() < end
            res = ring.read_since(cursor)
            assert res.lost == 0
            cursor = res.cursor
            if len(res.rows):
                rows.append(res.rows)
        client.send(m.Shutdown())
        stopped = events_until(client, lambda ev: isinstance(ev, m.EngineStopped))[-1]
        assert client.join(EXIT_TIMEOUT_S)
        got = np.concatenate(rows)
        np.testing.assert_array_equal(got["tick"], np.arange(len(got), dtype=float))
        t_ns = np.round(got["t_s"] * 1e9).astype(np.int64)
        assert np.all(np.diff(t_ns) == PERIOD_NS)  # t_s increases by exactly 1 ms
        assert np.all(got["faults"] == 0.0) and np.all(np.isfinite(got["render_fy"]))
        last = ring.latest(1)[0]
        assert last["gain"] == 0.0 and last["render_fx"] == last["render_fy"] == last["render_fz"] == 0.0
        assert isinstance(stopped, m.EngineStopped) and stopped.reason == "the experimenter GUI closed"
        assert stopped.stats["ticks"] >= 3000 and stopped.stats["period_max_us"] == 1000.0
        assert stopped.stats["periods_over_2ms"] == 0.0
    finally:
        client.kill()
    assert not client.alive


def test_a_real_clock_engine_explains_late_ticks_when_asked_and_says_how_it_is_scheduled():
    """The real clock for a moment with the tracer on: timing itself is not asserted (``bench pipeline`` is)."""
    client = EngineClient(HostConfig(clock="real", trace_jitter=True, health_period_s=0.1))
    try:
        client.wait_ready(START_TIMEOUT_S)
        health = events_until(client, lambda ev: isinstance(ev, m.Health) and ev.ticks > 50)[-1]
        assert isinstance(health, m.Health) and health.scheduling not in ("", "not started", "virtual clock")
        late = health.late_periods
        assert late is not None
        assert set(late) >= {"late_threshold_us", "ticks", "late_ticks", "causes", "over_2ms", "causes_over_2ms"}
        assert sum(late["causes"].values()) == late["late_ticks"]
        client.send(m.Shutdown())
        events_until(client, lambda ev: isinstance(ev, m.EngineStopped))
        assert client.join(EXIT_TIMEOUT_S)
    finally:
        client.kill()


def test_a_virtual_clock_engine_traces_nothing_and_says_so():
    client = EngineClient(HostConfig(clock="virtual", speed=0, trace_jitter=True, health_period_s=0.05))
    try:
        client.wait_ready(START_TIMEOUT_S)
        health = events_until(client, lambda ev: isinstance(ev, m.Health))[-1]
        assert isinstance(health, m.Health) and health.late_periods is None and health.scheduling == "virtual clock"
    finally:
        client.shutdown()


def test_how_the_engine_ended_is_said_for_a_bug_report() -> None:
    """A crash in a device library (ur_rtde segfaulted in a real window on the fakes) showed only 'exited
    unexpectedly'."""
    assert describe_exit(-11) == "killed by SIGSEGV (signal 11)"
    assert describe_exit(-9) == "killed by SIGKILL (signal 9)"
    assert describe_exit(1) == "exit status 1" and describe_exit(None) == "still running"
