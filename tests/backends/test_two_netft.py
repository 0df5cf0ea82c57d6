"""Two Net F/T boxes at once (both arms of the rig): each sensor reads its own box, and closing one leaves the other.

Two loopback fakes speaking RDT over UDP and the box's XML page over HTTP, in this process.
"""

from __future__ import annotations

from fake_netft import FakeNetFT

from pipeline.backends.netft import NetFTForceSensor
from pipeline.core.clock import VirtualClock


def test_two_boxes_stream_to_two_sensors_independently() -> None:
    right_counts = (1_500_000, -2_000_000, 3_250_000, 100_000, -50_000, 25_000)
    left_counts = (-700_000, 400_000, 9_000_000, -20_000, 10_000, 0)
    with FakeNetFT(counts=right_counts) as right_box, FakeNetFT(counts=left_counts, cpf=2_000_000) as left_box:
        right = NetFTForceSensor("127.0.0.1", port=right_box.udp_port, http_port=right_box.http_port,
                                 clock=VirtualClock(1_000), connect_timeout_s=1.0)
        left = NetFTForceSensor("127.0.0.1", port=left_box.udp_port, http_port=left_box.http_port,
                                clock=VirtualClock(2_000), connect_timeout_s=1.0)
        try:
            assert right.read_wrench()[:4] == (1_000, 1.5, -2.0, 3.25)
            assert left.read_wrench()[:4] == (2_000, -0.35, 0.2, 4.5)  # its own box's counts per newton
            assert right_box.requests[0] == left_box.requests[0] == (0x1234, 0x0002, 0)
            right.close()
            assert right_box.requests[-1] == (0x1234, 0x0000, 0) and len(left_box.requests) == 1
            n = left.stats.datagrams + 1
            left_box.send_raw(left_box.record())
            assert left.wait_for_datagrams(n, 2.0) and left.read_wrench()[3] == 4.5
        finally:
            right.close()
            left.close()
