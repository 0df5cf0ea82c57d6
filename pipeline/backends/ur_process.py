"""A UR's pose stream in a process of its own, so that ur_rtde never holds the 1 kHz loop's interpreter lock.

ur_rtde holds the interpreter lock for the whole of its ``RTDEReceiveInterface`` constructor: 40 ms against a
loopback fake, half a second when it dials a controller that is slow to answer (measured: a Python thread beside
it does not run meanwhile).  In the loop's process every reconnect of the pose stream therefore froze the loop
long enough to latch ``LOOP_STALLED`` -- a fault of the loop's timing, for what was a network hiccup.  Here the
monitor (:class:`pipeline.backends.ur.UrRtdeRobot`: its thread, its probes, its reconnects with backoff) runs in
a small process of its own, started when the robot is opened, and publishes every new pose into a shared-memory
ring of :data:`POSE_DTYPE` records; :class:`UrPoseProcess` -- the robot the loop reads -- copies the newest one
when the ring's count moves (a load of one word per tick otherwise).

The pose process dies with its parent (``PR_SET_PDEATHSIG``, or it notices its parent gone); the loop's watchdog
sees its poses stop (``POSE_STALE``) like any silent controller.  Run as ``python -m pipeline.backends.ur_process``
by :class:`UrPoseProcess` only.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
from typing import Any

import numpy as np

from foundation.platform_support.processes import die_with
from pipeline.backends.ur import RtdeLink, UrRtdeRobot
from pipeline.core.clock import Clock, MonotonicClock
from pipeline.core.ring import RingBuffer
from pipeline.devices.interfaces import DeviceError, PoseSample
from pipeline.devices.registry import robot_model
from pipeline.force.frames import Vec3

__all__ = ["POSE_DTYPE", "STATES", "UrPoseProcess"]

_POSE = ("x", "y", "z", *(f"r{i}" for i in range(9)), "controller_time_s", *(f"q{i}" for i in range(6)))
#: One pose of the pose process: when it came (its monotonic clock), the TCP position and rotation, the controller's
#: time, the joints; the monitor's state (an index of :data:`STATES`), reconnects and poses so far.
POSE_DTYPE = np.dtype([("t_ns", "<i8"), *((n, "<f8") for n in _POSE), ("state", "<i8"), ("reconnects", "<i8"),
                       ("samples", "<i8")])
#: The monitor's states (:attr:`pipeline.backends.ur.UrRtdeRobot.state`), by their index in a record.
STATES = ("connecting", "connected", "stale", "disconnected", "reconnecting", "closed")


class UrPoseProcess:
    """A :class:`pipeline.devices.interfaces.Robot` whose RTDE pose stream runs in a process of its own.

    Parameters are :class:`pipeline.backends.ur.UrRtdeRobot`'s (the process opens one with them); the poses are
    moved by ``tcp_correction_m`` here, in the reader.

    Raises
    ------
    DeviceError
        The controller cannot be reached or sends no state (the pose process's own line), or the process did not
        answer in time.
    """

    def __init__(self, link: RtdeLink, *, stale_after_s: float = 0.05, reconnect_after_s: float = 0.5,
                 min_backoff_s: float = 0.2, max_backoff_s: float = 5.0, tcp_correction_m: Vec3 = (0.0, 0.0, 0.0),
                 ) -> None:
        self.link = link
        self.host = link.host
        self.clock: Clock = link.clock
        self.tcp_correction_m: Vec3 = tuple(float(v) for v in tcp_correction_m)  # type: ignore[assignment]  # three items: mypy cannot count a generator
        # the process's poses are on the monotonic clock: the loop's own when it is that clock; else stamped here
        self._same_clock = isinstance(self.clock, MonotonicClock)
        self.ring = RingBuffer.create(POSE_DTYPE, 64, shared=True)
        args = [link.host, repr(link.frequency_hz), link.model.key, repr(link.connect_timeout_s), str(link.port),
                repr(stale_after_s), repr(reconnect_after_s), repr(min_backoff_s), repr(max_backoff_s)]
        self._proc = subprocess.Popen([sys.executable, "-m", "pipeline.backends.ur_process", str(os.getpid()),
                                       self.ring.segment, *args], stdout=subprocess.PIPE, text=True)
        self._seen = 0
        self._pose = PoseSample(self.clock.now_ns() - 10**12, (math.nan, math.nan, math.nan), (math.nan,) * 9, 0.0)
        self._row: Any = None
        answer = self._first_line(link.connect_timeout_s + 30.0)
        if answer != "READY":
            self.close()
            raise DeviceError(answer.removeprefix("ERROR ") if answer.startswith("ERROR ") else
                              f"the UR pose process for {self.host} did not start ({answer or 'no answer'})")

    def _first_line(self, timeout_s: float) -> str:
        out: list[str] = []
        reader = threading.Thread(target=lambda: out.append(self._proc.stdout.readline().strip()
                                                            if self._proc.stdout else ""), daemon=True)
        reader.start()
        reader.join(timeout_s)
        return out[0] if out else ""

    # -- Robot --------------------------------------------------------------------------------------------------
    def read_pose(self) -> PoseSample:
        """The newest TCP pose (never blocks: one load of the ring's count unless a new pose came)."""
        c = self.ring.write_count
        if c != self._seen:
            self._seen = c
            row = self.ring.latest(1)[0]
            self._row = row
            rot = tuple(float(row[f"r{i}"]) for i in range(9))
            x, y, z = float(row["x"]), float(row["y"]), float(row["z"])
            cx, cy, cz = self.tcp_correction_m
            if cx or cy or cz:  # the calibrated tip, not the pendant's TCP
                x += rot[0] * cx + rot[1] * cy + rot[2] * cz
                y += rot[3] * cx + rot[4] * cy + rot[5] * cz
                z += rot[6] * cx + rot[7] * cy + rot[8] * cz
            t_ns = int(row["t_ns"]) if self._same_clock else self.clock.now_ns()
            self._pose = PoseSample(t_ns, (x, y, z), rot, float(row["controller_time_s"]))  # type: ignore[arg-type]  # nine items: mypy cannot count a generator
        return self._pose

    def _field(self, name: str) -> int:
        self.read_pose()
        return 0 if self._row is None else int(self._row[name])

    @property
    def state(self) -> str:
        """The monitor's state (``connected``, ``stale``, ``reconnecting``, ...) as its newest record says."""
        if self._proc.poll() is not None:
            return "closed"
        return STATES[self._field("state")] if self._row is not None else "connecting"

    @property
    def reconnects(self) -> int:
        """Reconnects of the pose stream so far."""
        return self._field("reconnects")

    @property
    def samples(self) -> int:
        """Poses published so far."""
        return self._field("samples")

    @property
    def q_rad(self) -> tuple[float, ...]:
        """The joints of the newest pose, rad."""
        self.read_pose()
        return tuple(float(self._row[f"q{i}"]) for i in range(6)) if self._row is not None else (math.nan,) * 6

    @property
    def pid(self) -> int:
        """The pose process's id."""
        return int(self._proc.pid)

    def close(self) -> None:
        """End the pose process (it disconnects) and free the ring."""
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait(5.0)
        if self._proc.stdout is not None:
            self._proc.stdout.close()
        self.ring.close()


def _serve(parent_pid: int, ring_name: str, args: list[str]) -> int:
    """The pose process: open the stream, say READY (or one ERROR line), copy every new pose into the ring."""
    die_with(parent_pid)
    host, freq, model, timeout, port, stale, reconnect, lo, hi = args
    ring = RingBuffer.attach(ring_name)
    link = RtdeLink(host, float(freq), robot_model(model), MonotonicClock(), float(timeout), int(port))
    try:
        robot = UrRtdeRobot(link, stale_after_s=float(stale), reconnect_after_s=float(reconnect),
                            min_backoff_s=float(lo), max_backoff_s=float(hi))
    except DeviceError as exc:
        print(f"ERROR {exc}", flush=True)
        return 1
    seen, state = -1, ""
    while True:
        robot.wait_for_samples(max(1, seen + 1), 0.05)
        n = robot.samples
        if n == seen and robot.state == state:
            if os.getppid() != parent_pid:  # the parent went (where the kernel cannot tell us)
                robot.close()
                return 0
            continue
        first = seen < 0
        seen, state = n, robot.state
        p = robot.read_pose()
        q = robot.q_rad
        ring.write((p.t_ns, *p.position_m, *p.rot_base_tip, p.controller_time_s, *q, STATES.index(state)
                    if state in STATES else 0, robot.reconnects, n))
        if first:  # READY only once a pose is in the ring: the opener's first read is never an empty one
            print("READY", flush=True)


if __name__ == "__main__":
    sys.exit(_serve(int(sys.argv[1]), sys.argv[2], sys.argv[3:]))
