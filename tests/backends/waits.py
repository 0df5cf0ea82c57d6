"""The one bounded wait of the backend tests: for what a fake's own thread makes true (the fakes run in real time,
as the devices they stand for do, so these waits are on the wall clock; bounded, never a fixed sleep)."""

from __future__ import annotations

import time
from collections.abc import Callable


def until(pred: Callable[[], object], timeout_s: float = 2.0) -> bool:
    """Poll ``pred`` every ~2 ms until it is true or ``timeout_s`` has passed; whether it became true."""
    deadline = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.002)
    return True
