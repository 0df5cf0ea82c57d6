"""The session runner's parts alone: the experimenter's request queue and the delivery bookkeeping (what the
runner's end-to-end tests exercise through a whole session, here each rule by itself)."""

from __future__ import annotations

import threading

import pytest

from protocol.runner.deliveries import MAX_FAILED_IN_A_ROW, Deliveries
from protocol.runner.requests import Request, Requests
from protocol.study.delivery import DeliveryLimits
from protocol.study.records import AbortCause


def test_a_request_of_an_unknown_kind_is_refused_naming_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match=r"request 'stop': allowed are pause, resume, abort_trial, abort_session"):
        Request("stop")


def test_requests_from_many_threads_are_all_taken_once_each_in_each_threads_order() -> None:
    queue = Requests()

    def put(k: int) -> None:
        for i in range(200):
            queue.put(Request("abort_trial", f"{k}:{i}"))

    threads = [threading.Thread(target=put, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    taken = queue.take()
    assert len(taken) == 800 and queue.take() == []
    for k in range(4):
        assert [r.detail for r in taken if r.detail.startswith(f"{k}:")] == [f"{k}:{i}" for i in range(200)]


def test_trials_not_delivered_in_a_row_stop_the_cueing_and_a_counted_trial_resets_the_count() -> None:
    d = Deliveries(DeliveryLimits())
    for index, cause in enumerate((AbortCause.FAULT, AbortCause.GAP)):
        d.aborting(index, cause)
        assert d.settle(index, aborted=True) is cause
    assert d.failed_in_a_row == 2 and not d.too_many_failed
    assert d.settle(2, aborted=False) is None and d.failed_in_a_row == 0  # a trial that counted
    d.aborting(3, AbortCause.EXPERIMENTER)  # the experimenter's abort is no failure of the loop's
    assert d.settle(3, aborted=True) is AbortCause.EXPERIMENTER and d.failed_in_a_row == 0
    for index in range(4, 4 + MAX_FAILED_IN_A_ROW):
        d.aborting(index, AbortCause.FEEDBACK)
        d.settle(index, aborted=True)
    assert d.too_many_failed


def test_lost_records_are_one_gap_taken_once() -> None:
    d = Deliveries(DeliveryLimits())
    assert d.take_gap() == ""
    d.lost(7)
    assert d.take_gap() == "7 loop records were lost before they could be stored" and d.take_gap() == ""
