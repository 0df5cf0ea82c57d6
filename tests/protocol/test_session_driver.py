"""The one session driver (ring -> runner): what a block holds, and what waits for the next one.

The runner's side (records lost, a rehearsed kill fired at its record) runs through the engine's and the headless
runner's tests (tests/gui/test_engine_host.py, tests/protocol/test_rehearsal_exact.py), which both use this driver.
"""

from __future__ import annotations

from collections import deque

from pipeline.runtime.loop_messages import LoopEvent
from pipeline.runtime.ring import RingBuffer
from protocol.runner.session_driver import SessionDriver


def _ring(capacity: int = 8) -> RingBuffer:
    return RingBuffer.create(("tick", "t_ns"), capacity, shared=False)


def test_a_block_holds_the_new_records_then_the_entries_of_their_ticks() -> None:
    with _ring() as ring:
        ring.write((0.0, 0.0))  # before the driver: not the session's to read
        log: deque[tuple[int, str, object]] = deque()
        driver = SessionDriver(ring, log)
        ring.write((1.0, 1e6))
        ring.write((2.0, 2e6))
        driver.on_loop_event(LoopEvent(2_000_000, "fault", 1, "x"))
        log.append((2, "reset", None))
        block = driver.take()
        assert block.rows["tick"].tolist() == [1.0, 2.0] and block.lost == 0
        assert [ev.kind for ev in block.loop_events] == ["fault"] and block.replay_log == [(2, "reset", None)]
        assert not driver.loop_events and not log  # taken: the next block does not repeat them


def test_without_records_the_entries_wait_for_the_next_block() -> None:
    with _ring() as ring:
        log: deque[tuple[int, str, object]] = deque()
        driver = SessionDriver(ring, log)
        driver.on_loop_event(LoopEvent(0, "faults_reset", 0, ""))
        log.append((0, "zero", "late_tick"))
        empty = driver.take()
        assert len(empty.rows) == 0 and empty.loop_events == [] and empty.replay_log == []
        ring.write((0.0, 0.0))
        block = driver.take()
        assert len(block.rows) == 1 and len(block.loop_events) == 1 and block.replay_log == [(0, "zero", "late_tick")]


def test_records_the_ring_lapped_are_counted() -> None:
    with _ring(4) as ring:
        driver = SessionDriver(ring, deque())
        for k in range(10):
            ring.write((float(k), k * 1e6))
        block = driver.take()
        assert block.lost + len(block.rows) == 10 and block.lost > 0
        assert block.rows["tick"][-1] == 9.0 and driver.cursor == 10
