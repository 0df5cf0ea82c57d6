"""A fake UR controller's RTDE server (TCP 30004) for ``ur_rtde``'s real ``RTDEReceiveInterface``.

``ur_rtde`` holds the GIL while it connects, so the fake must live in another
process: :class:`FakeRtde` starts this file as a subprocess on a random
loopback address (127.x.y.z -- ``ur_rtde`` always dials port 30004, and
parallel test runs must not collide) and drives it over stdin/stdout.

Wire format (UR's RTDE guide, protocol version 2): every message is
``!HB`` (size including the 3-byte header, type) + payload.  The fake answers
REQUEST_PROTOCOL_VERSION ('V'), GET_URCONTROL_VERSION ('v', CB3 3.15),
CONTROL_PACKAGE_SETUP_OUTPUTS ('O': frequency + variable names → recipe id +
types) and CONTROL_PACKAGE_START/PAUSE ('S'/'P'), then streams DATA_PACKAGE
('U') messages with the recipe's variables in network byte order.

Commands on stdin (one per line): ``pose x y z rx ry rz``, ``q q1 … q6``,
``stall`` (keep the connection, stop the data), ``resume``, ``drop`` (close
the connection; accept the next one), ``refuse`` (close the listener),
``listen`` (reopen it), ``nan`` (NaN in the pose), ``quit``.
"""

from __future__ import annotations

import random
import select
import socket
import struct
import subprocess
import sys
import threading
import time

VECTOR6D = ("target_q", "target_qd", "target_qdd", "target_current", "target_moment", "actual_q", "actual_qd",
            "actual_current", "joint_control_output", "actual_TCP_pose", "actual_TCP_speed", "actual_TCP_force",
            "target_TCP_pose", "target_TCP_speed", "joint_temperatures", "actual_joint_voltage", "payload_inertia",
            "ft_raw_wrench", "actual_current_window")
TYPES = {
    **{n: "VECTOR6D" for n in VECTOR6D},
    "actual_digital_input_bits": "UINT64", "actual_digital_output_bits": "UINT64",
    "robot_mode": "INT32", "safety_mode": "INT32", "joint_mode": "VECTOR6INT32",
    "actual_tool_accelerometer": "VECTOR3D", "payload_cog": "VECTOR3D",
    "runtime_state": "UINT32", "robot_status_bits": "UINT32", "safety_status_bits": "UINT32",
}
FORMAT = {"DOUBLE": "d", "VECTOR6D": "6d", "VECTOR3D": "3d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I",
          "INT32": "i", "UINT32": "I", "UINT64": "Q", "BOOL": "?", "UINT8": "B"}


def type_of(name: str) -> str:
    if name in TYPES:
        return TYPES[name]
    if name.startswith("output_int_register"):
        return "INT32"
    if name.startswith(("output_bit_register", "output_bit_registers")):
        return "BOOL"
    return "DOUBLE"


def send(conn: socket.socket, typ: str, payload: bytes = b"") -> None:
    conn.sendall(struct.pack("!HB", 3 + len(payload), ord(typ)) + payload)


def recv_exact(conn: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        d = conn.recv(n - len(buf))
        if not d:
            raise ConnectionError("peer closed")
        buf += d
    return buf


class Server:
    """The server side, run in the subprocess."""

    def __init__(self, host: str, rate_hz: float) -> None:
        self.host = host
        self.rate_hz = rate_hz
        self.pose = [0.3, -0.1, 0.2, 3.14159, 0.0, 0.0]
        self.q = [0.0, -1.5707963267948966, 0.0, -1.5707963267948966, 0.0, 0.0]
        self.stalled = False
        self.timestamp = 1000.0
        self.lock = threading.Lock()
        self.listener: socket.socket | None = None
        self.conn: socket.socket | None = None

    def say(self, *words: object) -> None:
        print(*words, flush=True)

    def listen(self) -> None:
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, 30004))
        s.listen(4)
        self.listener = s

    def handle(self, conn: socket.socket) -> None:
        names: list[str] = []
        fmt = ""
        started = False
        conn.settimeout(None)
        next_t = time.perf_counter()
        while True:
            r, _, _ = select.select([conn], [], [], 0.0 if started else 0.2)
            if r:
                size, typ = struct.unpack("!HB", recv_exact(conn, 3))
                body = recv_exact(conn, size - 3)
                t = chr(typ)
                if t == "V":
                    self.say("VERSION", struct.unpack("!H", body)[0])
                    send(conn, "V", b"\x01")
                elif t == "v":
                    send(conn, "v", struct.pack("!IIII", 3, 15, 7, 106331))
                elif t == "O":
                    freq = struct.unpack("!d", body[:8])[0]
                    names = [n for n in body[8:].decode().split(",") if n]
                    types = [type_of(n) for n in names]
                    fmt = "!B" + "".join(FORMAT[x] for x in types)
                    self.say("SETUP", freq, len(names), ",".join(names))
                    send(conn, "O", b"\x01" + ",".join(types).encode())
                elif t == "S":
                    started = True
                    self.say("START")
                    send(conn, "S", b"\x01")
                elif t == "P":
                    started = False
                    send(conn, "P", b"\x01")
                else:
                    self.say("UNKNOWN", t)
            if started and time.perf_counter() >= next_t:
                next_t += 1.0 / self.rate_hz
                with self.lock:
                    if self.stalled or self.conn is not conn:
                        if self.conn is not conn:
                            return
                        time.sleep(0.001)
                        next_t = time.perf_counter()
                        continue
                    self.timestamp += 0.008
                    vals: list[object] = [1]
                    for n in names:
                        tp = type_of(n)
                        if n == "timestamp":
                            vals.append(self.timestamp)
                        elif n == "actual_TCP_pose":
                            vals.extend(self.pose)
                        elif n == "actual_q":
                            vals.extend(self.q)
                        elif tp in ("VECTOR6D", "VECTOR6INT32", "VECTOR6UINT32"):
                            vals.extend([0] * 6 if "INT" in tp else [0.0] * 6)
                        elif tp == "VECTOR3D":
                            vals.extend([0.0] * 3)
                        elif tp == "BOOL":
                            vals.append(False)
                        elif tp in ("INT32", "UINT32", "UINT64", "UINT8"):
                            vals.append(7 if n == "robot_mode" else 1 if n == "safety_mode" else 0)
                        else:
                            vals.append(0.0)
                payload = struct.pack(fmt, *vals)
                send(conn, "U", payload)
            elif started:
                time.sleep(max(0.0, min(0.001, next_t - time.perf_counter())))

    def serve(self) -> None:
        while True:
            lst = self.listener
            if lst is None:
                time.sleep(0.01)
                continue
            try:
                conn, _ = lst.accept()
            except OSError:
                continue
            with self.lock:
                self.conn = conn
            self.say("CONNECTED")
            try:
                self.handle(conn)
            except (ConnectionError, OSError):
                pass
            try:
                conn.close()
            except OSError:
                pass
            self.say("DISCONNECTED")

    def command(self, line: str) -> bool:
        w = line.split()
        if not w:
            return True
        with self.lock:
            if w[0] == "pose":
                self.pose = [float(x) for x in w[1:7]]
            elif w[0] == "q":
                self.q = [float(x) for x in w[1:7]]
            elif w[0] == "nan":
                self.pose = [float("nan")] * 6
            elif w[0] == "stall":
                self.stalled = True
            elif w[0] == "resume":
                self.stalled = False
            elif w[0] == "drop":
                c, self.conn = self.conn, None
                if c is not None:
                    c.shutdown(socket.SHUT_RDWR)
            elif w[0] == "refuse":
                if self.listener is not None:
                    self.listener.close()
                    self.listener = None
            elif w[0] == "listen":
                self.listen()
            elif w[0] == "quit":
                return False
        self.say("OK", w[0])
        return True


def main() -> None:
    host, rate = sys.argv[1], float(sys.argv[2])
    srv = Server(host, rate)
    srv.listen()
    threading.Thread(target=srv.serve, daemon=True).start()
    srv.say("LISTENING", host)
    for line in sys.stdin:
        if not srv.command(line):
            break


# -- test-side handle ---------------------------------------------------------------------------
class FakeRtde:
    """Run the fake controller in a subprocess on a fresh loopback address; a context manager."""

    def __init__(self, rate_hz: float = 500.0) -> None:
        self.lines: list[str] = []
        self._cond = threading.Condition()
        for _ in range(20):
            self.host = f"127.{random.randint(1, 254)}.{random.randint(0, 255)}.{random.randint(1, 254)}"
            self.proc = subprocess.Popen(
                [sys.executable, "-u", __file__, self.host, str(rate_hz)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
            )
            first = self.proc.stdout.readline() if self.proc.stdout else ""
            if first.startswith("LISTENING"):
                break
            self.proc.wait(2)
        else:  # pragma: no cover - 20 collisions in a row
            raise RuntimeError("could not start the fake RTDE server")
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(line.strip())
                self._cond.notify_all()

    def send(self, command: str, timeout_s: float = 2.0) -> None:
        """Send a command and wait for its acknowledgement."""
        assert self.proc.stdin is not None
        n = sum(1 for x in self.lines if x == f"OK {command.split()[0]}")
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        self.wait_for(f"OK {command.split()[0]}", n + 1, timeout_s)

    def wait_for(self, line: str, count: int = 1, timeout_s: float = 2.0) -> bool:
        """Wait until ``line`` has been printed ``count`` times."""
        with self._cond:
            return self._cond.wait_for(lambda: sum(1 for x in self.lines if x.startswith(line)) >= count, timeout_s)

    def __enter__(self) -> FakeRtde:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """End the subprocess."""
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
                self.proc.wait(2)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(2)


if __name__ == "__main__":
    main()
