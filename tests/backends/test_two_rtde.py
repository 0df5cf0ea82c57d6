"""Two UR controllers at once (both arms of the rig): each RTDE connection reads its own robot, and closing one
leaves the other streaming.

Two fake controllers (:class:`fake_rtde.FakeRtde`) on two loopback addresses, read by ``ur_rtde``'s real
``RTDEReceiveInterface``.
"""

from __future__ import annotations

import time

from fake_rtde import FakeRtde

from pipeline.backends.ur import RtdeLink, UrRtdeRobot
from pipeline.core.clock import MonotonicClock

WAIT_S = 3.0


def _open(fake: FakeRtde) -> UrRtdeRobot:
    return UrRtdeRobot(RtdeLink(fake.host, clock=MonotonicClock(), connect_timeout_s=2.0), min_backoff_s=0.05,
                       max_backoff_s=0.2)


def _reads(robot: UrRtdeRobot, position_m: tuple[float, float, float]) -> bool:
    """Whether the robot comes to report ``position_m`` (waiting on its samples, not on the wall clock)."""
    deadline = time.monotonic() + WAIT_S
    while robot.read_pose().position_m != position_m and time.monotonic() < deadline:
        robot.wait_for_samples(robot.samples + 1, WAIT_S)
    return robot.read_pose().position_m == position_m


def test_two_controllers_stream_to_two_robots_independently() -> None:
    with FakeRtde() as right_ur, FakeRtde() as left_ur:
        assert right_ur.host != left_ur.host
        right_ur.send("pose 0.31 -0.12 0.205 0.1 -2.0 0.3")
        left_ur.send("pose -0.28 0.15 0.19 0.0 3.0 0.0")
        right, left = _open(right_ur), _open(left_ur)
        try:
            assert _reads(right, (0.31, -0.12, 0.205)) and _reads(left, (-0.28, 0.15, 0.19))
            left_ur.send("pose -0.25 0.1 0.3 0.0 3.0 0.0")  # one robot moves; the other does not
            assert _reads(left, (-0.25, 0.1, 0.3))
            assert right.read_pose().position_m == (0.31, -0.12, 0.205)
            right.close()
            # the other stays connected (waited for: on a busy machine its fake controller may have starved for a
            # moment, which reads "stale" until its next sample -- a state of its own, not the one closed)
            assert right.state == "closed" and left.wait_for_state("connected", WAIT_S), left.state
            left_ur.send("pose -0.2 0.1 0.3 0.0 3.0 0.0")
            assert _reads(left, (-0.2, 0.1, 0.3))
        finally:
            right.close()
            left.close()
