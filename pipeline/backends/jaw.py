"""Host side of the jaw actuator (PQ12-R on an Arduino Uno, ``firmware/jaw_actuator``) over pyserial.

The line protocol is documented in ``firmware/jaw_actuator/README.md``.
Opening the port resets the Uno (DTR); the sketch announces itself with
``READY <version> <closed_us> <open_us> <pos_us>`` once it has booted, so the
host waits for that line (bounded) instead of sleeping a fixed 2 s.  A reader
thread splits incoming lines into command replies (``OK``/``LIMIT``/``ERR``/
``PONG``) and unsolicited button reports (``POS``).  If the port disappears
(USB unplugged), the actuator goes into a visible fault state; commands then
raise :class:`DeviceError` until :meth:`SerialJawActuator.reconnect`
succeeds.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from pipeline.devices.interfaces import DeviceError

__all__ = ["BAUD", "PROTOCOL_VERSION", "JawFault", "JawStatus", "SerialJawActuator"]

BAUD = 115200
PROTOCOL_VERSION = 1


class JawFault(DeviceError):
    """The jaw actuator is in a fault state (port lost, no READY, refused command)."""


class JawStatus:
    """What the experimenter sees: position, limits, last limit hit, fault text."""

    __slots__ = ("at_limit", "button_moves", "closed_us", "fault", "open_us", "pos_us")

    def __init__(self) -> None:
        self.closed_us = 0
        self.open_us = 0
        self.pos_us = 0
        self.at_limit = False
        self.fault = ""
        self.button_moves = 0

    @property
    def fraction_open(self) -> float:
        """Current position as a fraction of the stroke between the firmware limits (0 closed, 1 open)."""
        span = self.open_us - self.closed_us
        return math.nan if span == 0 else (self.pos_us - self.closed_us) / span


def _open_serial(port: str, baud: int, timeout_s: float) -> Any:
    import serial  # lazily: the simulated rig needs no pyserial

    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=timeout_s)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise JawFault(f"cannot open the jaw actuator port {port!r}: {exc}") from None


class SerialJawActuator:
    """A :class:`pipeline.devices.interfaces.JawActuator` talking to the jaw_actuator sketch.

    Parameters
    ----------
    port
        Serial device (``/dev/ttyACM0``, ``COM3``) or a pyserial URL.
    baud
        Must match the sketch (115200).
    ready_timeout_s
        How long to wait for ``READY`` after opening (the Uno's bootloader takes 1–2 s).
    reply_timeout_s
        How long a command waits for its reply.
    open_serial
        ``open_serial(port, baud, read_timeout_s)`` returning a pyserial-like
        object (default: ``serial.serial_for_url``).
    """

    def __init__(
        self,
        port: str,
        *,
        baud: int = BAUD,
        ready_timeout_s: float = 3.0,
        reply_timeout_s: float = 0.5,
        open_serial: Callable[[str, int, float], Any] | None = None,
    ) -> None:
        self.port = port
        self.baud = baud
        self.ready_timeout_s = ready_timeout_s
        self.reply_timeout_s = reply_timeout_s
        self._open_serial = open_serial or _open_serial
        self.status = JawStatus()
        self._lock = threading.Lock()  # one command at a time
        self._replies: queue.Queue[str] = queue.Queue()
        self._ready: queue.Queue[str] = queue.Queue()
        self._ser: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._connect()

    # -- JawActuator --------------------------------------------------------------------------
    def set_position(self, fraction_open: float) -> None:
        """Move to a fraction of the stroke (0 closed, 1 open); the firmware clips to its limits."""
        if not isinstance(fraction_open, (int, float)) or not math.isfinite(fraction_open):
            raise ValueError(f"fraction_open = {fraction_open!r}: must be a finite number from 0 to 1")
        s = self.status
        us = round(s.closed_us + min(1.0, max(0.0, float(fraction_open))) * (s.open_us - s.closed_us))
        self.set_pulse_us(us)

    def close(self) -> None:
        """Release the port (the jaw stays where it is)."""
        self._stop.set()
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # the port may already be gone
                pass
        t = self._thread
        if t is not None and t.is_alive() and threading.current_thread() is not t:
            t.join(1.0)

    # -- commands -----------------------------------------------------------------------------
    def open_jaw(self) -> int:
        """Open fully (to the firmware's open limit); returns the pulse width, µs."""
        return self._command("OPEN")

    def close_jaw(self) -> int:
        """Close fully (to the firmware's closed limit); returns the pulse width, µs."""
        return self._command("CLOSE")

    def step(self, delta_us: int) -> int:
        """Move ``delta_us`` toward open (negative: toward closed); clipped at the limits."""
        if isinstance(delta_us, bool) or not isinstance(delta_us, int) or not -1000 <= delta_us <= 1000:
            raise ValueError(f"delta_us = {delta_us!r}: must be a whole number of µs from -1000 to 1000")
        return self._command(f"STEP {delta_us}")

    def set_pulse_us(self, pulse_us: int) -> int:
        """Command a pulse width, µs (the firmware clips it to its limits)."""
        if isinstance(pulse_us, bool) or not isinstance(pulse_us, int) or not 500 <= pulse_us <= 2500:
            raise ValueError(f"pulse_us = {pulse_us!r}: must be a whole number of µs from 500 to 2500")
        return self._command(f"SET {pulse_us}")

    def ping(self) -> bool:
        """True if the sketch answers PONG."""
        return self._command("PING") == 0

    def reconnect(self) -> None:
        """Re-open the port after a fault and wait for READY again (the experimenter's reset)."""
        self.close()
        self._stop = threading.Event()
        self.status.fault = ""
        self._connect()

    # -- internals ----------------------------------------------------------------------------
    def _connect(self) -> None:
        self._replies = queue.Queue()
        self._ready = queue.Queue()
        self._ser = self._open_serial(self.port, self.baud, 0.05)
        self._thread = threading.Thread(target=self._read_loop, args=(self._ser,), name="jaw-serial", daemon=True)
        self._thread.start()
        try:
            line = self._ready.get(timeout=self.ready_timeout_s)
        except queue.Empty:
            fault = self.status.fault
            self.close()
            raise JawFault(
                f"no READY from the jaw actuator on {self.port} within {self.ready_timeout_s:g} s"
                + (f" ({fault})" if fault else "")
                + f"; check the port, that firmware/jaw_actuator is flashed and the baud rate ({self.baud})"
            ) from None
        w = line.split()
        try:
            version, closed_us, open_us, pos_us = (int(x) for x in w[1:5])
        except ValueError:
            self.close()
            raise JawFault(f"jaw actuator on {self.port} sent a malformed READY line: {line!r}") from None
        if version != PROTOCOL_VERSION:
            self.close()
            raise JawFault(
                f"jaw actuator on {self.port} speaks protocol {version}; this software speaks {PROTOCOL_VERSION}: "
                "flash firmware/jaw_actuator from this version"
            )
        s = self.status
        s.closed_us, s.open_us, s.pos_us, s.at_limit, s.fault = closed_us, open_us, pos_us, False, ""

    def _read_loop(self, ser: Any) -> None:
        buf = b""
        while not self._stop.is_set():
            try:
                chunk = ser.read(256)
            except Exception as exc:  # SerialException/OSError: the port went away
                if not self._stop.is_set():
                    self.status.fault = f"serial port {self.port} lost: {exc}"
                    self._replies.put("")  # wake a waiting command
                return
            if not chunk:
                continue
            buf += chunk
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                line = raw.decode("ascii", "replace").strip()
                if line:
                    self._dispatch(line)

    def _dispatch(self, line: str) -> None:
        s = self.status
        word = line.split(" ", 1)[0]
        if word == "READY":
            self._ready.put(line)
        elif word == "POS":
            w = line.split()
            try:
                s.pos_us = int(w[1])
            except (IndexError, ValueError):
                return
            s.at_limit = len(w) > 2 and w[2] == "LIMIT"
            s.button_moves += 1
        else:
            self._replies.put(line)

    def _command(self, text: str) -> int:
        """Send one command line and parse its reply; the new pulse width (0 for PONG)."""
        with self._lock:
            s = self.status
            if s.fault or self._ser is None:
                raise JawFault(f"jaw actuator is in fault: {s.fault or 'port closed'}; reconnect it")
            while not self._replies.empty():  # a reply that arrived after its command timed out
                self._replies.get_nowait()
            try:
                self._ser.write((text + "\n").encode("ascii"))
            except Exception as exc:  # the port went away
                s.fault = f"serial port {self.port} lost: {exc}"
                raise JawFault(f"jaw actuator: {s.fault}") from None
            deadline = time.monotonic() + self.reply_timeout_s
            try:
                line = self._replies.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise JawFault(f"jaw actuator on {self.port} did not answer {text!r} within "
                               f"{self.reply_timeout_s:g} s") from None
            if not line:
                raise JawFault(f"jaw actuator: {s.fault}")
            w = line.split()
            if w[0] == "PONG":
                return 0
            if w[0] == "ERR":
                raise JawFault(f"jaw actuator refused {text!r}: {line[4:]}")
            if w[0] in ("OK", "LIMIT") and len(w) == 2 and w[1].lstrip("-").isdigit():
                s.pos_us = int(w[1])
                s.at_limit = w[0] == "LIMIT"
                return s.pos_us
            raise JawFault(f"jaw actuator answered {text!r} with {line!r}, which is not in the protocol")
