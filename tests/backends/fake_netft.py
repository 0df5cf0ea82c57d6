"""A fake ATI Net F/T box on loopback: RDT over UDP and ``/netftapi2.xml`` over HTTP.

It speaks the real wire formats (``!HHI`` requests, 36-byte ``!IIIiiiiii``
records) on ports the OS picks, and records every request it receives.  Two
ways to produce data:

* scripted: :meth:`FakeNetFT.send_records` / :meth:`send_raw` push exactly the
  datagrams a test wants (drop, reorder, duplicate, corrupt, stall, status);
* free-running: ``rate_hz > 0`` streams records from a thread after START,
  with optional ``drop_every`` / ``duplicate_every`` / ``reorder_every``.

A START with a sample count above 0 is answered with that many records and no stream, as the box does; with
``delay_s`` every datagram leaves that long after it was made (a slow network: ``qualify``'s latency check).
"""

from __future__ import annotations

import queue
import socket
import struct
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

REQUEST = struct.Struct("!HHI")
RECORD = struct.Struct("!IIIiiiiii")

XML_TEMPLATE = """<?xml version="1.0" encoding="utf-8"?>
<netft>
<setcfgsel>0</setcfgsel>
<cfgcalsel>0</cfgcalsel>
<scfgfu>{fu}</scfgfu>
<scfgtu>{tu}</scfgtu>
<cfgcpf>{cpf}</cfgcpf>
<cfgcpt>{cpt}</cfgcpt>
<cfgmr>{mr}</cfgmr>
<comrdtrate>{rate}</comrdtrate>
<comrdtbsiz>1</comrdtbsiz>
<comrdte>Enabled</comrdte>
<runrate>7000</runrate>
<runstat>0x00000000</runstat>
</netft>
"""


class FakeNetFT:
    """Net F/T fake.  Use as a context manager; ports are ``udp_port`` and ``http_port``.

    Parameters
    ----------
    cpf, cpt, force_unit, torque_unit, ranges
        What ``netftapi2.xml`` reports.
    counts
        The 6 counts every generated record carries.
    xml_status
        HTTP status of ``/netftapi2.xml`` (404 = no calibration page); ``xml_body`` overrides the page.
    http
        Start the web server at all (False: the HTTP port is closed).
    host
        The loopback address to serve on (two boxes of two arms need two addresses: 127.0.0.2, ...).
    initial_records
        Records sent at once when a START arrives (scripted mode).
    rate_hz
        Free-running stream rate after START (0 = scripted only).
    """

    def __init__(
        self,
        *,
        cpf: int = 1_000_000,
        cpt: int = 1_000_000,
        force_unit: str = "N",
        torque_unit: str = "Nm",
        ranges: str = "130;130;400;10;10;10",
        counts: tuple[int, int, int, int, int, int] = (1_500_000, -2_000_000, 3_250_000, 100_000, -50_000, 25_000),
        xml_status: int = 200,
        xml_body: str | None = None,
        http: bool = True,
        initial_records: int = 1,
        rate_hz: float = 0.0,
        drop_every: int = 0,
        duplicate_every: int = 0,
        reorder_every: int = 0,
        status: int = 0,
        host: str = "127.0.0.1",
        delay_s: float = 0.0,
    ) -> None:
        self.host = host
        #: Every datagram leaves this long after it was made (a slow network or box: the misbehaving sensor of
        #: ``qualify``'s latency check).
        self.delay_s = delay_s
        self._delayed: queue.Queue[tuple[float, bytes, tuple[str, int]]] = queue.Queue()
        self.counts = counts
        self.status = status
        self.initial_records = initial_records
        self.rate_hz = rate_hz
        self.drop_every = drop_every
        self.duplicate_every = duplicate_every
        self.reorder_every = reorder_every
        self.requests: list[tuple[int, int, int]] = []
        self.bad_requests = 0
        self.rdt_sequence = 0
        self.ft_sequence = 0
        self.client: tuple[str, int] | None = None
        self.streaming = threading.Event()
        self._stop = threading.Event()
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind((host, 0))
        self.udp.settimeout(0.05)
        self.udp_port = self.udp.getsockname()[1]
        self.xml = xml_body if xml_body is not None else XML_TEMPLATE.format(
            fu=force_unit, tu=torque_unit, cpf=cpf, cpt=cpt, mr=ranges, rate=int(rate_hz or 1000)
        )
        self.xml_status = xml_status
        self.http_requests: list[str] = []
        self._http: ThreadingHTTPServer | None = None
        if http:
            fake = self

            class Handler(BaseHTTPRequestHandler):
                def do_GET(self) -> None:  # http.server API
                    fake.http_requests.append(self.path)
                    if self.path.split("?")[0] == "/netftapi2.xml" and fake.xml_status == 200:
                        body = fake.xml.encode()
                        self.send_response(200)
                        self.send_header("Content-Type", "text/xml")
                    else:
                        body = b"not found"
                        self.send_response(fake.xml_status if fake.xml_status != 200 else 404)
                    self.send_header("Content-Length", str(len(body)))
                    self.end_headers()
                    self.wfile.write(body)

                def log_message(self, *args: object) -> None:
                    pass

            self._http = ThreadingHTTPServer((host, 0), Handler)
            self.http_port = self._http.server_address[1]
            threading.Thread(target=self._http.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
        else:
            # a port that is certainly closed: bind, note, close
            s = socket.socket()
            s.bind((host, 0))
            self.http_port = s.getsockname()[1]
            s.close()
        self._threads = [threading.Thread(target=self._serve_udp, daemon=True)]
        if delay_s > 0:
            self._threads.append(threading.Thread(target=self._send_delayed, daemon=True))
        if rate_hz > 0:
            self._threads.append(threading.Thread(target=self._stream, daemon=True))
        for t in self._threads:
            t.start()

    # -- context manager ----------------------------------------------------------------------
    def __enter__(self) -> FakeNetFT:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop every thread and close the sockets."""
        self._stop.set()
        for t in self._threads:
            t.join(1.0)
        self.udp.close()
        if self._http is not None:
            self._http.shutdown()
            self._http.server_close()

    # -- records ------------------------------------------------------------------------------
    def record(
        self,
        counts: tuple[int, ...] | None = None,
        *,
        status: int | None = None,
        rdt: int | None = None,
        ft: int | None = None,
        advance_ft: bool = True,
    ) -> bytes:
        """The next record (advances ``rdt_sequence`` and, unless stalled, ``ft_sequence``)."""
        self.rdt_sequence = (self.rdt_sequence + 1) % (1 << 32) if rdt is None else rdt
        if ft is not None:
            self.ft_sequence = ft
        elif advance_ft:
            self.ft_sequence = (self.ft_sequence + 7) % (1 << 32)  # 7 kHz internal rate, 1 kHz output
        c = self.counts if counts is None else counts
        return RECORD.pack(self.rdt_sequence, self.ft_sequence, self.status if status is None else status, *c)

    def send_raw(self, datagram: bytes) -> None:
        """Send bytes to the streaming client as one datagram."""
        assert self.client is not None, "no client has sent START"
        self.udp.sendto(datagram, self.client)

    def send_records(self, *records: bytes) -> None:
        """Send each record as its own datagram."""
        for r in records:
            self.send_raw(r)

    # -- threads ------------------------------------------------------------------------------
    def _serve_udp(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.udp.recvfrom(1024)
            except (TimeoutError, OSError):
                continue
            if len(data) != REQUEST.size:
                self.bad_requests += 1
                continue
            header, cmd, count = REQUEST.unpack(data)
            if header != 0x1234:
                self.bad_requests += 1
                continue
            self.requests.append((header, cmd, count))
            if cmd in (2, 3) and count > 0:  # so many records, then nothing (the box's single-sample request)
                for _ in range(count):
                    self._sendto(self.record(), addr)
            elif cmd in (2, 3):
                self.client = addr
                self.streaming.set()
                for _ in range(self.initial_records):
                    self._sendto(self.record(), addr)
            elif cmd == 0:
                self.streaming.clear()

    def _sendto(self, datagram: bytes, addr: tuple[str, int]) -> None:
        if self.delay_s > 0:
            self._delayed.put((time.perf_counter() + self.delay_s, datagram, addr))
        else:
            self.udp.sendto(datagram, addr)

    def _send_delayed(self) -> None:
        while not self._stop.is_set():
            try:
                due, datagram, addr = self._delayed.get(timeout=0.05)
            except queue.Empty:
                continue
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            try:
                self.udp.sendto(datagram, addr)
            except OSError:
                pass

    def _stream(self) -> None:
        period = 1.0 / self.rate_hz
        n = 0
        held: bytes | None = None
        next_t = time.perf_counter()
        while not self._stop.is_set():
            if not self.streaming.wait(0.05) or self.client is None:
                continue
            n += 1
            rec = self.record()
            try:
                if self.drop_every and n % self.drop_every == 0:
                    pass
                elif self.reorder_every and n % self.reorder_every == 0:
                    held = rec  # sent after the next one
                else:
                    self._sendto(rec, self.client)
                    if held is not None:
                        self._sendto(held, self.client)
                        held = None
                    if self.duplicate_every and n % self.duplicate_every == 0:
                        self._sendto(rec, self.client)
            except OSError:
                pass
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.perf_counter()
