"""How long an ATI Net F/T takes to answer: the sensor's sampling and transport to the host, bounded from above.

The box answers an RDT request for one record (``START_REALTIME`` with a sample count of 1: the Net F/T manual's
single-sample request) with one datagram.  The time from sending the request to that record's arrival is the
request's way to the box, the box's wait for its next sample and the record's way back: an upper bound on the one
way a sample travels while the loop streams (``haptic-study qualify``'s latency check; docs/qualify.md).  Software
can time nothing closer to the strain gauges: what happens before the box stamps a record is the tap test's.
"""

from __future__ import annotations

import socket
import time

from pipeline.backends.netft import CMD_START_REALTIME, CMD_STOP, RDT_HEADER, RDT_PORT, RECORD, REQUEST, NetFTError

__all__ = ["sample_round_trips"]


def sample_round_trips(host: str, port: int = RDT_PORT, n: int = 20, timeout_s: float = 1.0) -> list[float]:
    """Ask the box for one record ``n`` times, one request at a time; each answer's round trip, s.

    A request left unanswered for ``timeout_s`` counts as ``timeout_s`` (a box that answers that late is slow, not
    absent).  Raises :class:`NetFTError` when the box answers none (the first unanswered: no more are sent).
    """
    try:
        addr = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4]
    except (socket.gaierror, UnicodeError) as exc:
        raise NetFTError(f"Net F/T host {host!r} cannot be resolved ({exc}); give its IP address") from None
    trips: list[float] = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind(("", 0))
            sock.connect(addr)
            for _ in range(n):
                trips.append(_one(sock, timeout_s))
                if trips[0] >= timeout_s:  # no box answers there: not a slow one (said below, not waited n times)
                    break
            sock.send(REQUEST.pack(RDT_HEADER, CMD_STOP, 0))
        except OSError as exc:
            raise NetFTError(f"cannot talk to the Net F/T at {host}:{port}: {exc}") from None
    if all(t >= timeout_s for t in trips):
        raise NetFTError(f"the Net F/T at {host}:{port} did not answer a single-record request within "
                         f"{timeout_s:g} s")
    return trips


def _one(sock: socket.socket, timeout_s: float) -> float:
    """One request's round trip, s (``timeout_s`` when unanswered); a late answer to an earlier one is skipped."""
    sock.setblocking(False)
    try:
        while True:
            sock.recv(65536)  # what an earlier, unanswered request got late
    except (BlockingIOError, InterruptedError):
        pass
    sock.setblocking(True)
    t0 = time.perf_counter()
    sock.send(REQUEST.pack(RDT_HEADER, CMD_START_REALTIME, 1))
    while True:
        left = timeout_s - (time.perf_counter() - t0)
        if left <= 0:
            return timeout_s
        sock.settimeout(left)
        try:
            data = sock.recv(65536)
        except TimeoutError:
            return timeout_s
        if len(data) and len(data) % RECORD.size == 0:
            return time.perf_counter() - t0
