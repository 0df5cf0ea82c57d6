"""ATI Net F/T over RDT (UDP port 49152), with the calibration read over HTTP.

Our own client (docs/hardware.md §3a): the PyPI ``NetFT`` package returns raw
counts, drops the status word, breaks on buffered packets and can block
forever.  Here:

* requests are ``!HHI`` (header 0x1234, command, sample count); records are
  36-byte ``!IIIiiiiii`` (rdt_sequence, ft_sequence, status, 6 × counts) and a
  datagram may carry several of them (buffered mode);
* counts become N and N·m with ``cfgcpf``/``cfgcpt`` and the units read from
  ``/netftapi2.xml``, unless the configuration overrides them;
* a receive thread hands the newest record to the loop through one slot (an
  attribute assignment is atomic), so :meth:`NetFTForceSensor.read_wrench`
  never blocks;
* lost, late (reordered) and duplicate records are counted from
  ``rdt_sequence`` (modulo 2³²); garbage datagrams are counted and skipped;
* faults reach the loop's watchdog through the :class:`WrenchSample` fields it
  already reads: a non-zero status word is passed through in ``status``
  (``SENSOR_STATUS``), and a record whose ``ft_sequence`` did not advance is
  not fresh data, so the slot keeps the previous timestamp and the sample goes
  stale (``SENSOR_STALE`` after 5 ms) -- as it does when the box falls silent.
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import urllib.error
import urllib.request
import xml.etree.ElementTree as ET
from collections import deque
from dataclasses import dataclass

from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, WrenchSample

__all__ = [
    "CMD_SET_SOFTWARE_BIAS",
    "CMD_START_BUFFERED",
    "CMD_START_REALTIME",
    "CMD_STOP",
    "DEFAULT_RANGE",
    "RDT_HEADER",
    "RDT_PORT",
    "RECORD",
    "REQUEST",
    "NetFTCalibration",
    "NetFTError",
    "NetFTForceSensor",
    "NetFTStats",
    "RdtSequencer",
    "force_unit_to_n",
    "parse_netft_xml",
    "read_netft_calibration",
    "torque_unit_to_nm",
]

RDT_PORT = 49152
RDT_HEADER = 0x1234
CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_START_BUFFERED = 0x0003
CMD_SET_SOFTWARE_BIAS = 0x0042
#: Request: header, command, sample count (0 = stream until STOP).
REQUEST = struct.Struct("!HHI")
#: Record: rdt_sequence, ft_sequence, status, Fx, Fy, Fz, Tx, Ty, Tz (counts).
RECORD = struct.Struct("!IIIiiiiii")
#: ATI Gamma SI-130-10 full scale (N, N, N, N·m, N·m, N·m).
DEFAULT_RANGE: tuple[float, float, float, float, float, float] = (130.0, 130.0, 400.0, 10.0, 10.0, 10.0)
_SEQ_MOD = 1 << 32
_SEQ_HALF = 1 << 31
_RECENT = 256  # rdt sequences remembered to tell a duplicate from a late record

# Net F/T unit names (scfgfu / scfgtu), normalised to lower case without spaces.
_FORCE_UNITS = {"lbf": 4.4482216152605, "n": 1.0, "klbf": 4448.2216152605, "kn": 1000.0, "kgf": 9.80665,
                "gf": 0.00980665, "g": 0.00980665}
_TORQUE_UNITS = {
    "lbf-in": 0.1129848290276167, "lbfin": 0.1129848290276167, "lbf-ft": 1.3558179483314004,
    "lbfft": 1.3558179483314004,
    "nm": 1.0, "n-m": 1.0, "nmm": 0.001, "n-mm": 0.001, "kgf-cm": 0.0980665, "kgfcm": 0.0980665, "knm": 1000.0,
    "kn-m": 1000.0,
}


class NetFTError(DeviceError):
    """The Net F/T could not be reached or answered nonsense; the message says what to check."""


def force_unit_to_n(unit: str) -> float:
    """Newtons per Net F/T force unit (``scfgfu``: N, lbf, klbf, kN, kgf, gf)."""
    key = unit.strip().lower().replace(" ", "")
    if key not in _FORCE_UNITS:
        raise NetFTError(f"force unit {unit!r} is not known; allowed: N, lbf, klbf, kN, kgf, gf")
    return _FORCE_UNITS[key]


def torque_unit_to_nm(unit: str) -> float:
    """Newton-metres per Net F/T torque unit (``scfgtu``: Nm, Nmm, lbf-in, lbf-ft, kgf-cm, kNm)."""
    key = unit.strip().lower().replace(" ", "").replace("·", "-")
    if key not in _TORQUE_UNITS:
        raise NetFTError(f"torque unit {unit!r} is not known; allowed: Nm, Nmm, lbf-in, lbf-ft, kgf-cm, kNm")
    return _TORQUE_UNITS[key]


@dataclass(frozen=True, slots=True)
class NetFTCalibration:
    """How to turn counts into N and N·m, and what the box says about itself.

    Attributes
    ----------
    counts_per_force, counts_per_torque
        ``cfgcpf`` and ``cfgcpt``: counts per force/torque unit.
    force_unit, torque_unit
        ``scfgfu`` and ``scfgtu``.
    rdt_rate_hz
        ``comrdtrate``, the RDT output rate (0 when unknown).
    range_n
        Full scale per channel in N and N·m (from ``cfgmr`` when the box reports it).
    source
        Where the numbers came from (``"http://…/netftapi2.xml"`` or ``"configuration"``).
    """

    counts_per_force: float
    counts_per_torque: float
    force_unit: str = "N"
    torque_unit: str = "Nm"
    rdt_rate_hz: float = 0.0
    range_n: tuple[float, float, float, float, float, float] = DEFAULT_RANGE
    source: str = "configuration"

    def __post_init__(self) -> None:
        for name in ("counts_per_force", "counts_per_torque"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise NetFTError(f"{name} = {v!r}: must be a finite number of counts > 0")
        force_unit_to_n(self.force_unit)
        torque_unit_to_nm(self.torque_unit)

    @property
    def force_scale(self) -> float:
        """Newtons per count."""
        return force_unit_to_n(self.force_unit) / self.counts_per_force

    @property
    def torque_scale(self) -> float:
        """Newton-metres per count."""
        return torque_unit_to_nm(self.torque_unit) / self.counts_per_torque


def parse_netft_xml(text: str | bytes, source: str = "netftapi2.xml") -> NetFTCalibration:
    """Read cpf, cpt, units, RDT rate and ranges from the box's ``netftapi2.xml``.

    Raises
    ------
    NetFTError
        When the page is not XML or lacks ``cfgcpf``/``cfgcpt``.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise NetFTError(f"{source} is not the Net F/T configuration page (not XML: {exc})") from None

    def tag(name: str) -> str | None:
        el = root if root.tag == name else root.find(f".//{name}")
        return None if el is None or el.text is None else el.text.strip()

    def number(name: str) -> float:
        raw = tag(name)
        if raw is None:
            raise NetFTError(f"{source} has no <{name}>: is this a Net F/T box?")
        try:
            return float(raw)
        except ValueError:
            raise NetFTError(f"{source}: <{name}> = {raw!r} is not a number") from None

    cpf = number("cfgcpf")
    cpt = number("cfgcpt")
    fu = tag("scfgfu") or "N"
    tu = tag("scfgtu") or "Nm"
    rate = 0.0
    raw_rate = tag("comrdtrate")
    if raw_rate:
        try:
            rate = float(raw_rate)
        except ValueError:
            rate = 0.0
    rng = DEFAULT_RANGE
    raw_mr = tag("cfgmr")
    if raw_mr:
        parts = [p for p in raw_mr.replace(",", ";").replace(" ", ";").split(";") if p]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            vals = []
        if len(vals) == 6 and all(math.isfinite(v) and v > 0 for v in vals):
            kf, kt = force_unit_to_n(fu), torque_unit_to_nm(tu)
            rng = (vals[0] * kf, vals[1] * kf, vals[2] * kf, vals[3] * kt, vals[4] * kt, vals[5] * kt)
    return NetFTCalibration(cpf, cpt, fu, tu, rate, rng, source)


def read_netft_calibration(host: str, http_port: int = 80, timeout_s: float = 2.0) -> NetFTCalibration:
    """Fetch ``http://host:port/netftapi2.xml`` and parse it (bounded by ``timeout_s``).

    Raises
    ------
    NetFTError
        Naming the URL and the reason (refused, timed out, HTTP error, not a Net F/T page).
    """
    url = f"http://{host}:{http_port}/netftapi2.xml"
    hint = "set [sensor] counts_per_force and counts_per_torque in hardware.toml to skip it"
    try:
        with urllib.request.urlopen(url, timeout=timeout_s) as resp:  # a lab device on the LAN
            body = resp.read(1 << 20)
    except urllib.error.HTTPError as exc:
        raise NetFTError(f"cannot read the Net F/T calibration from {url}: HTTP {exc.code} {exc.reason}; "
                         f"{hint}") from None
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise NetFTError(f"cannot read the Net F/T calibration from {url}: {reason}; {hint}") from None
    return parse_netft_xml(body, url)


@dataclass(slots=True)
class NetFTStats:
    """Counters of the receive thread (read from any thread; plain ints)."""

    datagrams: int = 0
    records: int = 0
    lost: int = 0
    reordered: int = 0
    duplicate: int = 0
    corrupt: int = 0
    stalled: int = 0
    bad_status: int = 0
    timeouts: int = 0
    last_status: int = 0
    last_error: str = ""

    def as_dict(self) -> dict[str, int | str]:
        """Plain data for JSON output."""
        return {k: getattr(self, k) for k in self.__slots__}


class RdtSequencer:
    """Accounting of ``rdt_sequence`` / ``ft_sequence`` (both modulo 2³²) into :class:`NetFTStats`.

    :meth:`classify` returns :data:`FRESH` (publish it), :data:`STALLED` (newer
    packet but the same ``ft_sequence``: the box repeats a frozen measurement),
    :data:`DUPLICATE` (a copy of a record already seen) or :data:`LATE` (older
    than the newest: it arrived out of order; it was counted as lost when the
    gap appeared and is now counted as reordered instead).
    """

    FRESH, STALLED, DUPLICATE, LATE = 0, 1, 2, 3

    def __init__(self, stats: NetFTStats) -> None:
        self.stats = stats
        self.last_rdt: int | None = None
        self.last_ft: int | None = None
        self._recent: deque[int] = deque(maxlen=_RECENT)
        self._recent_set: set[int] = set()

    def _remember(self, rdt: int) -> None:
        if rdt in self._recent_set:
            return
        if len(self._recent) == self._recent.maxlen:
            self._recent_set.discard(self._recent[0])
        self._recent.append(rdt)
        self._recent_set.add(rdt)

    def classify(self, rdt: int, ft: int) -> int:
        """Account for one record and say what it is."""
        st = self.stats
        st.records += 1
        if self.last_rdt is not None:
            d = (rdt - self.last_rdt) % _SEQ_MOD
            if d == 0 and ft == self.last_ft:
                st.duplicate += 1
                return self.DUPLICATE
            if d >= _SEQ_HALF:
                if rdt in self._recent_set:
                    st.duplicate += 1
                    return self.DUPLICATE
                st.reordered += 1
                if st.lost:
                    st.lost -= 1
                self._remember(rdt)
                return self.LATE
            if d > 1:
                st.lost += d - 1
        self._remember(rdt)
        # d == 0 with a new ft_sequence: the next record of the same buffered packet
        stalled = self.last_ft is not None and ft == self.last_ft
        self.last_rdt, self.last_ft = rdt, ft
        if stalled:
            st.stalled += 1
            return self.STALLED
        return self.FRESH


class NetFTForceSensor:
    """A :class:`pipeline.devices.interfaces.ForceSensor` reading an ATI Net F/T box over RDT.

    Parameters
    ----------
    host
        The box's IP address or name.
    port
        RDT UDP port (49152).
    http_port
        Port of the box's web server (80), for ``netftapi2.xml``.
    calibration
        Manual counts-per-unit override; None reads the box's XML (and fails
        with a clear error if that page cannot be read).
    clock
        Time source for the sample timestamps -- the loop's clock.
    connect_timeout_s
        How long to wait for the calibration page and for the first record.
    receive_timeout_s
        Socket timeout of the receive thread; each expiry is counted in
        :attr:`stats` and lets the thread notice :meth:`close`.
    buffered
        Use buffered streaming (several records per datagram) instead of real-time.
    range_n
        Full scale per channel; None takes it from the calibration.
    """

    def __init__(
        self,
        host: str,
        *,
        port: int = RDT_PORT,
        http_port: int = 80,
        calibration: NetFTCalibration | None = None,
        clock: Clock | None = None,
        connect_timeout_s: float = 2.0,
        receive_timeout_s: float = 0.1,
        buffered: bool = False,
        range_n: tuple[float, float, float, float, float, float] | None = None,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.clock: Clock = clock or MonotonicClock()
        self.calibration = calibration or read_netft_calibration(host, http_port, connect_timeout_s)
        self._range = tuple(range_n) if range_n is not None else self.calibration.range_n
        cal = self.calibration
        self._cpf, self._cpt = float(cal.counts_per_force), float(cal.counts_per_torque)
        self._uf, self._ut = force_unit_to_n(cal.force_unit), torque_unit_to_nm(cal.torque_unit)
        #: Counts per N and per N·m when a reading is exactly ``counts / counts_per_unit`` (the box reports in
        #: N and N·m), so a recording can keep the counts; None otherwise.
        self.counts_per_unit = (self._cpf, self._cpt) if self._uf == 1.0 and self._ut == 1.0 else None
        self.stats = NetFTStats()
        self._seq = RdtSequencer(self.stats)
        self._latest = WrenchSample(self.clock.now_ns() - 10**12, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0)
        self._fresh = threading.Condition()
        self._stop = threading.Event()
        self._collect: list[WrenchSample] | None = None
        self._start_cmd = CMD_START_BUFFERED if buffered else CMD_START_REALTIME
        try:
            addr = socket.getaddrinfo(host, self.port, socket.AF_INET, socket.SOCK_DGRAM)[0][4]
        except (socket.gaierror, UnicodeError) as exc:
            raise NetFTError(f"Net F/T host {host!r} cannot be resolved ({exc}); give its IP address") from None
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(("", 0))
            # connect() filters datagrams from anyone but the box and surfaces ICMP "port unreachable"
            self._sock.connect(addr)
            self._sock.settimeout(receive_timeout_s)
            self._send(self._start_cmd, 0)
        except OSError as exc:
            self._sock.close()
            raise NetFTError(f"cannot talk to the Net F/T at {host}:{self.port}: {exc}") from None
        self._thread = threading.Thread(target=self._receive_loop, name="netft-rdt", daemon=True)
        self._thread.start()
        if not self.wait_for_records(1, connect_timeout_s):
            err = self.stats.last_error
            self.close()
            raise NetFTError(
                f"no RDT data from the Net F/T at {host}:{self.port} within {connect_timeout_s:g} s"
                + (f" ({err})" if err else "")
                + "; check the IP address, the cable and that RDT is enabled on the box"
            )

    # -- ForceSensor --------------------------------------------------------------------------
    @property
    def range_n(self) -> tuple[float, float, float, float, float, float]:
        """Full-scale range per channel (N, N, N, N·m, N·m, N·m)."""
        return self._range  # type: ignore[return-value]  # six items, counted where it is set

    def read_wrench(self) -> WrenchSample:
        """The newest fresh record (never blocks)."""
        return self._latest

    def close(self) -> None:
        """Stop streaming, end the receive thread and release the socket."""
        if self._stop.is_set():
            return
        self._stop.set()
        try:
            self._send(CMD_STOP, 0)
        except OSError:
            pass
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(2.0)
        self._sock.close()

    # -- extras -------------------------------------------------------------------------------
    def set_hardware_bias(self) -> None:
        """Ask the box to tare (``SET_SOFTWARE_BIAS``): only at a known no-load pose."""
        self._send(CMD_SET_SOFTWARE_BIAS, 1)

    def collect(self, n: int, timeout_s: float) -> list[WrenchSample]:
        """The next ``n`` fresh samples (fewer if ``timeout_s`` passes first); for probes, not the loop."""
        samples: list[WrenchSample] = []
        with self._fresh:
            self._collect = samples
            self._fresh.wait_for(lambda: len(samples) >= n, timeout_s)
            self._collect = None
        return samples[:n]

    def wait_for_records(self, n: int, timeout_s: float) -> bool:
        """Block until ``stats.records >= n`` (any record, fresh or not) or the timeout; True if reached."""
        with self._fresh:
            return self._fresh.wait_for(lambda: self.stats.records >= n, timeout_s)

    def wait_for_datagrams(self, n: int, timeout_s: float) -> bool:
        """Block until ``n`` datagrams (valid or garbage) have been processed; True if reached."""
        with self._fresh:
            return self._fresh.wait_for(lambda: self.stats.datagrams >= n, timeout_s)

    # -- internals ----------------------------------------------------------------------------
    def _send(self, command: int, count: int) -> None:
        self._sock.send(REQUEST.pack(RDT_HEADER, command, count))

    def _receive_loop(self) -> None:
        sock = self._sock
        while not self._stop.is_set():
            try:
                data = sock.recv(65536)
            except TimeoutError:
                self.stats.timeouts += 1
                continue
            except OSError as exc:
                if self._stop.is_set():
                    return
                # ICMP port unreachable arrives as ECONNREFUSED on a connected UDP socket
                self.stats.last_error = str(exc)
                self.stats.timeouts += 1
                self._stop.wait(0.05)
                continue
            self.ingest(data, self.clock.now_ns())

    def ingest(self, data: bytes, now_ns: int) -> None:
        """Account for one datagram and publish its newest fresh record (receive thread)."""
        st = self.stats
        n = len(data)
        if n == 0 or n % RECORD.size:
            st.corrupt += 1
        else:
            for off in range(0, n, RECORD.size):
                self._record(RECORD.unpack_from(data, off), now_ns)
        with self._fresh:
            st.datagrams += 1
            self._fresh.notify_all()

    def _record(self, rec: tuple[int, ...], now_ns: int) -> None:
        kind = self._seq.classify(rec[0], rec[1])
        if kind >= RdtSequencer.DUPLICATE:
            return
        st = self.stats
        status = rec[2]
        st.last_status = status
        if status:
            st.bad_status += 1
        cpf, cpt, uf, ut = self._cpf, self._cpt, self._uf, self._ut
        # a stalled record is not fresh data: it keeps the previous timestamp and goes stale
        t_ns = self._latest.t_ns if kind == RdtSequencer.STALLED else now_ns
        # divide by counts-per-unit (correctly rounded: 100000 counts / 1e6 is exactly 0.1), then convert units
        self._latest = WrenchSample(
            t_ns, rec[3] / cpf * uf, rec[4] / cpf * uf, rec[5] / cpf * uf,
            rec[6] / cpt * ut, rec[7] / cpt * ut, rec[8] / cpt * ut, status, rec[0], rec[1],
        )
        sink = self._collect
        if sink is not None and kind == RdtSequencer.FRESH:
            sink.append(self._latest)
