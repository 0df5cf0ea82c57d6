"""A two-arm real rig's network fakes: each arm's Net F/T box (its own address and load) and its UR controller."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from fake_netft import FakeNetFT
from fake_rtde import FakeRtde

#: Each arm's box load, in counts (1 N and 2 N along z), the right arm's first.
COUNTS = {"right": (0, 0, 1_000_000, 0, 0, 0), "left": (0, 0, 2_000_000, 0, 0, 0)}


@contextmanager
def arm_fakes(**netft: Any) -> Iterator[dict[str, tuple[FakeNetFT, FakeRtde]]]:
    """A box (at 127.0.0.2, .3, …; ``netft``: more of its settings) and a controller per arm of :data:`COUNTS`."""
    with ExitStack() as stack:
        out = {}
        for i, arm in enumerate(COUNTS):
            box = stack.enter_context(FakeNetFT(counts=COUNTS[arm], host=f"127.0.0.{i + 2}", **netft))
            out[arm] = (box, stack.enter_context(FakeRtde()))
        yield out
