"""The Net F/T client against a fake box on loopback (RDT over UDP + netftapi2.xml over HTTP)."""

from __future__ import annotations

import time

import pytest
from fake_netft import RECORD, FakeNetFT
from hypothesis import given
from hypothesis import strategies as st

from pipeline.backends.netft import (
    NetFTCalibration,
    NetFTError,
    NetFTForceSensor,
    NetFTStats,
    RdtSequencer,
    parse_netft_xml,
)
from pipeline.core.clock import VirtualClock
from pipeline.devices.interfaces import Fault, ForceSensor
from pipeline.force.framework import FrameworkConfig, HapticFramework
from pipeline.runtime.loop import HapticLoop
from pipeline.runtime.loop_messages import ResetFaults
from pipeline.sim.robot import TOOL_DOWN, SimRobot
from pipeline.sim.touch import SimTouch

WAIT_S = 2.0  # upper bound of every socket wait; each returns as soon as the datagram is in


def open_sensor(fake: FakeNetFT, **kw: object) -> NetFTForceSensor:
    kw.setdefault("connect_timeout_s", 1.0)
    return NetFTForceSensor("127.0.0.1", port=fake.udp_port, http_port=fake.http_port, **kw)


def push(sensor: NetFTForceSensor, fake: FakeNetFT, *datagrams: bytes) -> None:
    """Send datagrams and wait until the receive thread has processed them."""
    n = sensor.stats.datagrams + len(datagrams)
    for d in datagrams:
        fake.send_raw(d)
    assert sensor.wait_for_datagrams(n, WAIT_S)


def test_reads_calibration_streams_and_scales_counts() -> None:
    with FakeNetFT() as fake:
        s = open_sensor(fake, clock=VirtualClock(5_000))
        try:
            assert isinstance(s, ForceSensor)
            assert fake.http_requests == ["/netftapi2.xml"]
            assert fake.requests[0] == (0x1234, 0x0002, 0)  # start real-time streaming, count 0 = forever
            assert s.calibration.counts_per_force == 1e6 and s.calibration.source.endswith("/netftapi2.xml")
            assert s.range_n == (130.0, 130.0, 400.0, 10.0, 10.0, 10.0)
            w = s.read_wrench()
            assert w[:7] == (5_000, 1.5, -2.0, 3.25, 0.1, -0.05, 0.025)
            assert (w.status, w.rdt_sequence, w.ft_sequence) == (0, 1, 7)
        finally:
            s.close()
        assert fake.requests[-1] == (0x1234, 0x0000, 0)  # stop on close


def test_units_other_than_newtons_are_converted() -> None:
    with FakeNetFT(cpf=1000, cpt=2000, force_unit="lbf", torque_unit="lbf-in", ranges="30;30;90;90;90;90") as fake:
        s = open_sensor(fake, clock=VirtualClock())
        try:
            w = s.read_wrench()
            assert w.fx == pytest.approx(1500 * 4.4482216152605, rel=1e-12)
            assert w.tx == pytest.approx(50 * 0.1129848290276167, rel=1e-12)
            assert s.range_n[2] == pytest.approx(90 * 4.4482216152605)
            assert s.range_n[5] == pytest.approx(90 * 0.1129848290276167)
        finally:
            s.close()


def test_manual_calibration_needs_no_http_page() -> None:
    with FakeNetFT(http=False) as fake:
        cal = NetFTCalibration(1e6, 1e3, "N", "Nmm")
        s = open_sensor(fake, calibration=cal, clock=VirtualClock())
        try:
            assert s.read_wrench()[1:7] == (1.5, -2.0, 3.25, 0.1, -0.05, 0.025)
            assert fake.http_requests == []
        finally:
            s.close()


def test_no_http_page_is_a_clear_error_fast() -> None:
    with FakeNetFT(http=False) as fake:
        t0 = time.monotonic()
        with pytest.raises(NetFTError,
                           match=r"cannot read the Net F/T calibration from http://127\.0\.0\.1:\d+/netftapi2\.xml: "
                                 r".*refused.*counts_per_force"):
            open_sensor(fake)
        assert time.monotonic() - t0 < 1.0


def test_http_404_and_a_page_that_is_not_the_box() -> None:
    with FakeNetFT(xml_status=404) as fake, pytest.raises(NetFTError, match="HTTP 404"):
        open_sensor(fake)
    with (FakeNetFT(xml_body="<html><body>router login</body></html>") as fake,
          pytest.raises(NetFTError, match="has no <cfgcpf>: is this a Net F/T box")):
        open_sensor(fake)
    with pytest.raises(NetFTError, match="not XML"):
        parse_netft_xml("{json: 1}")
    with pytest.raises(NetFTError, match=r"force unit 'stone' is not known; allowed: N, lbf"):
        parse_netft_xml("<netft><cfgcpf>1</cfgcpf><cfgcpt>1</cfgcpt><scfgfu>stone</scfgfu></netft>")


def test_closed_rdt_port_is_a_clear_error_fast() -> None:
    with FakeNetFT() as fake:
        cal = NetFTCalibration(1e6, 1e6)
        # a UDP port nobody listens on: the kernel answers ICMP port unreachable
        fake_port = fake.udp_port
    t0 = time.monotonic()
    with pytest.raises(NetFTError,
                       match=rf"no RDT data from the Net F/T at 127\.0\.0\.1:{fake_port} within 0\.3 s.*check the IP"):
        NetFTForceSensor("127.0.0.1", port=fake_port, calibration=cal, connect_timeout_s=0.3)
    assert time.monotonic() - t0 < 1.0


def test_wrong_host_is_a_clear_error_fast() -> None:
    with pytest.raises(NetFTError, match=r"host 'no-such-box\.invalid' cannot be resolved"):
        NetFTForceSensor("no-such-box.invalid", calibration=NetFTCalibration(1e6, 1e6), connect_timeout_s=0.3)
    t0 = time.monotonic()
    with pytest.raises(NetFTError):  # TEST-NET-1: never answers (or no route at all)
        NetFTForceSensor("192.0.2.1", http_port=80, connect_timeout_s=0.3)
    assert time.monotonic() - t0 < 1.5


def test_lost_reordered_duplicate_and_garbage_are_counted() -> None:
    with FakeNetFT() as fake:
        clock = VirtualClock(1_000)
        s = open_sensor(fake, clock=clock)
        try:
            r2, r3, r4, r5 = (fake.record() for _ in range(4))
            clock.advance(1_000)
            push(s, fake, r2, r4)  # r3 late
            assert (s.stats.lost, s.read_wrench().rdt_sequence) == (1, 4)
            push(s, fake, r3)  # arrives after r4: reordered, not lost, not published
            assert (s.stats.lost, s.stats.reordered, s.read_wrench().rdt_sequence) == (0, 1, 4)
            push(s, fake, r4, r3)  # copies of records already seen
            assert s.stats.duplicate == 2 and s.read_wrench().rdt_sequence == 4
            push(s, fake, b"\x00" * 35, b"", b"garbage!" * 5)  # wrong lengths
            assert s.stats.corrupt == 3
            push(s, fake, r5)
            assert s.read_wrench().rdt_sequence == 5
            assert s.stats.records == 7 and s.stats.datagrams == 10
        finally:
            s.close()


def test_buffered_datagram_with_several_records() -> None:
    with FakeNetFT() as fake:
        s = open_sensor(fake, clock=VirtualClock(), buffered=True)
        try:
            assert fake.requests[0] == (0x1234, 0x0003, 0)
            recs = [fake.record(counts=(i * 1000, 0, 0, 0, 0, 0)) for i in range(1, 5)]
            push(s, fake, b"".join(recs))
            assert s.stats.records == 5 and s.stats.lost == 0
            assert s.read_wrench().fx == pytest.approx(0.004)  # the newest record of the datagram
            # per-packet numbering: records of one datagram share rdt_sequence, ft advances
            same = [RECORD.pack(9, 100 + i, 0, i, 0, 0, 0, 0, 0) for i in range(3)]
            push(s, fake, b"".join(same))
            assert s.read_wrench()[1] == pytest.approx(2e-6) and s.stats.duplicate == 0
            assert s.stats.lost == 9 - 5 - 1
        finally:
            s.close()


def test_sequence_wraps_modulo_2_32() -> None:
    with FakeNetFT() as fake:
        s = open_sensor(fake, clock=VirtualClock())
        try:
            # from rdt 1 (the first record) in two half-range jumps to 2³²−1, then across the wrap
            push(s, fake, fake.record(rdt=2**31), fake.record(rdt=2**32 - 1), fake.record(rdt=0), fake.record(rdt=1))
            assert (s.stats.lost, s.stats.reordered, s.stats.duplicate) == (2**32 - 4, 0, 0)
            assert s.read_wrench().rdt_sequence == 1
        finally:
            s.close()


class _OneSensorRig:
    """A rig whose sensor is the real Net F/T client; robot and Touch are the simulated twins."""

    def __init__(self, sensor: NetFTForceSensor) -> None:
        self.sensor = sensor
        self.robot = SimRobot((0.3, 0.0, 0.1), TOOL_DOWN)
        self.haptic = SimTouch()

    def advance(self, now_ns: int) -> None:
        self.robot.advance(now_ns, 0.001)
        self.haptic.advance(now_ns, 0.001)

    def true_contact_force(self) -> None:
        return None

    def close(self) -> None:
        self.sensor.close()


def test_status_word_and_stalled_ft_sequence_reach_the_watchdog() -> None:
    with FakeNetFT() as fake:
        clock = VirtualClock(0)
        s = open_sensor(fake, clock=clock)
        try:
            loop = HapticLoop(_OneSensorRig(s), HapticFramework(FrameworkConfig(), device_peak_n=3.3), clock)
            loop.run_ticks(1)
            assert loop.faults == 0
            push(s, fake, fake.record(status=0x80000001))
            loop.run_ticks(1)
            assert loop.faults == Fault.SENSOR_STATUS and s.stats.bad_status == 1
            push(s, fake, fake.record())
            loop.submit(ResetFaults())  # refused: the last tick still saw the bad status
            loop.run_ticks(1)
            assert loop.faults == Fault.SENSOR_STATUS
            loop.submit(ResetFaults())
            loop.run_ticks(1)
            assert loop.faults == 0
            # the box keeps sending but ft_sequence is frozen: no fresh data -> stale after 5 ms
            t_fresh = s.read_wrench().t_ns
            for _ in range(7):
                push(s, fake, fake.record(advance_ft=False))
                loop.run_ticks(1)
            assert s.stats.stalled == 7 and s.read_wrench().t_ns == t_fresh
            assert loop.faults == Fault.SENSOR_STALE
            assert [e.detail.split(":")[0] for e in loop.events if e.kind == "fault"] == ["SENSOR_STATUS",
                                                                                          "SENSOR_STALE"]
            assert next(e.detail for e in loop.events if e.kind == "fault") == "SENSOR_STATUS: status word 0x80000001"
        finally:
            s.close()


def test_hardware_bias_request() -> None:
    with FakeNetFT() as fake:
        s = open_sensor(fake, clock=VirtualClock())
        try:
            s.set_hardware_bias()
            push(s, fake, fake.record())  # the box answers in order; by now the request is in
            deadline = time.monotonic() + WAIT_S
            while (0x1234, 0x0042, 1) not in fake.requests and time.monotonic() < deadline:
                time.sleep(0.001)
            assert (0x1234, 0x0042, 1) in fake.requests and fake.bad_requests == 0
        finally:
            s.close()


def test_free_running_stream_counts_drops_and_duplicates() -> None:
    with FakeNetFT(rate_hz=2000, initial_records=0, drop_every=10, duplicate_every=7) as fake:
        s = open_sensor(fake)
        try:
            assert s.wait_for_records(100, WAIT_S)
        finally:
            s.close()
        st_ = s.stats
        assert st_.lost >= 8 and st_.duplicate >= 10 and st_.corrupt == 0 and st_.reordered == 0


# -- pure sequence accounting ------------------------------------------------------------------
@given(st.lists(st.integers(0, 500), min_size=1, max_size=200, unique=True).map(sorted))
def test_in_order_delivery_counts_every_gap_as_lost(seqs: list[int]) -> None:
    stats = NetFTStats()
    sq = RdtSequencer(stats)
    kinds = [sq.classify(r, r * 7) for r in seqs]
    assert kinds == [RdtSequencer.FRESH] * len(seqs)
    assert stats.lost == seqs[-1] - seqs[0] + 1 - len(seqs)


@given(st.integers(3, 300), st.data())
def test_swapping_neighbours_is_reordered_not_lost(n: int, data: st.DataObject) -> None:
    i = data.draw(st.integers(1, n - 2))
    order = list(range(n))
    order[i], order[i + 1] = order[i + 1], order[i]
    stats = NetFTStats()
    sq = RdtSequencer(stats)
    for r in order:
        sq.classify(r, r * 7)
    assert (stats.lost, stats.reordered, stats.duplicate) == (0, 1, 0)
    for r in order[-5:]:
        sq.classify(r, r * 7)
    assert stats.duplicate == min(5, n)
