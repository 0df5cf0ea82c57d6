"""Scheduling of the loop's process: the loop thread and the threads that share its GIL.

Each call runs in a throwaway thread, so the test process's own threads keep their policy.
"""

from __future__ import annotations

import os
import threading

import pytest

from pipeline.core.clock import (
    HELPER_PRIORITY,
    REALTIME_ENV,
    REALTIME_PRIORITY,
    prepare_helper_thread,
    prepare_realtime_thread,
)


def in_thread(fn):
    out = {}

    def run() -> None:
        out["result"] = fn()
        if hasattr(os, "sched_getscheduler"):
            out["policy"] = os.sched_getscheduler(0)
            out["priority"] = os.sched_getparam(0).sched_priority

    t = threading.Thread(target=run)
    t.start()
    t.join()
    return out


@pytest.mark.parametrize("fn", [prepare_helper_thread, prepare_realtime_thread])
def test_realtime_off_keeps_normal_scheduling(monkeypatch, fn):
    monkeypatch.setenv(REALTIME_ENV, "0")
    out = in_thread(fn)
    assert out["result"] == f"normal ({REALTIME_ENV}=0)"
    if "policy" in out:
        assert out["policy"] == os.SCHED_OTHER


@pytest.mark.skipif(not hasattr(os, "sched_getscheduler"), reason="no real-time scheduling on this platform")
def test_helpers_run_below_the_loop_or_report_why_not(monkeypatch):
    monkeypatch.delenv(REALTIME_ENV, raising=False)
    assert HELPER_PRIORITY < REALTIME_PRIORITY
    out = in_thread(prepare_helper_thread)
    if out["result"].startswith("normal ("):  # no CAP_SYS_NICE / rtprio limit here: nothing changed
        assert out["policy"] == os.SCHED_OTHER
    else:
        assert out["result"] == f"SCHED_FIFO/{HELPER_PRIORITY}"
        assert (out["policy"], out["priority"]) == (os.SCHED_FIFO, HELPER_PRIORITY)
