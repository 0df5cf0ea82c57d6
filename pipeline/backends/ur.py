"""UR3 (CB3) pose over RTDE via ``ur_rtde``'s ``RTDEReceiveInterface`` -- read only.

The robot stays under its own teleoperation program; this backend only
listens (docs/hardware.md §3b).  A monitor thread polls ur_rtde's cached state
at twice the controller rate, and publishes a new :class:`PoseSample` whenever
the controller timestamp advances -- the TCP position (m, base frame) and the
rotation vector turned into ``rot_base_tip``.  When the controller falls
silent the sample simply stops being refreshed, so the loop's watchdog latches
``POSE_STALE`` after 50 ms; when the link is lost the thread reconnects with
exponential backoff.

Why every connection attempt is preceded by a plain TCP probe: ur_rtde holds
the GIL while it connects (40 ms on loopback, half a second against a slow
controller), so dialling a dead address from ur_rtde would freeze every
Python thread of its process until the TCP timeout.  (The rig runs this
monitor in a process of its own, :mod:`pipeline.backends.ur_process`, so its
connects never stall the 1 kHz loop.)
The probe (``socket.create_connection`` with a timeout releases the GIL) makes
sure the controller answers before ur_rtde is asked to.  Reconnects also wait
at least ``min_backoff_s`` (200 ms) after the loss, by which time the watchdog
has already ramped the rendered force to zero.

Also here: the UR3 CB3 forward kinematics from the DH table (§3c), for tests,
the simulated rig and as a cross-check of the reported TCP pose.
"""

from __future__ import annotations

import importlib
import math
import socket
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pipeline.core.clock import Clock, MonotonicClock
from pipeline.devices.interfaces import DeviceError, PoseSample
from pipeline.devices.registry import DEFAULT_ROBOT_MODEL, RobotModel, robot_model
from pipeline.force.frames import IDENTITY, Mat3, Vec3, mat_mul, mat_vec, rotvec_to_matrix

__all__ = [
    "RTDE_PORT",
    "UR3_DH",
    "RtdeLink",
    "UrRtdeRobot",
    "check_rtde_frequency",
    "probe_tcp",
    "require_reachable",
    "rtde_interface",
    "ur3_flange_pose",
    "ur3_tcp_pose",
]

RTDE_PORT = 30004
#: UR3 (CB3) standard DH parameters (a [m], d [m], alpha [rad]) per joint, urcontrol.conf values.
UR3_DH: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.1519, math.pi / 2),
    (-0.24365, 0.0, 0.0),
    (-0.21325, 0.0, 0.0),
    (0.0, 0.11235, math.pi / 2),
    (0.0, 0.08535, -math.pi / 2),
    (0.0, 0.0819, 0.0),
)


def ur3_flange_pose(q_rad: Sequence[float]) -> tuple[Vec3, Mat3]:
    """Flange position (m) and ``rot_base_flange`` of a UR3 CB3 at joint angles ``q_rad``.

    Standard DH: ``T = Π Rz(θᵢ) Tz(dᵢ) Tx(aᵢ) Rx(αᵢ)`` with :data:`UR3_DH`.
    Real robots carry per-robot calibration, so prefer the controller's TCP
    pose for the loop; this is for simulation and cross-checks.
    """
    if len(q_rad) != 6:
        raise ValueError(f"q_rad = {list(q_rad)!r}: a UR3 has 6 joints")
    rot: Mat3 = IDENTITY
    p = (0.0, 0.0, 0.0)
    for (a, d, alpha), th in zip(UR3_DH, q_rad, strict=True):
        ct, st = math.cos(th), math.sin(th)
        ca, sa = math.cos(alpha), math.sin(alpha)
        # rotation and translation of one DH link
        r_i: Mat3 = (ct, -st * ca, st * sa, st, ct * ca, -ct * sa, 0.0, sa, ca)
        t_i = (a * ct, a * st, d)
        dp = mat_vec(rot, t_i)
        p = (p[0] + dp[0], p[1] + dp[1], p[2] + dp[2])
        rot = mat_mul(rot, r_i)
    return p, rot


def ur3_tcp_pose(
    q_rad: Sequence[float], tcp_offset_m: Vec3 = (0.0, 0.0, 0.0), tcp_rotvec: Vec3 = (0.0, 0.0, 0.0)
) -> tuple[Vec3, Mat3]:
    """TCP position (m) and ``rot_base_tip`` for a TCP at ``tcp_offset_m`` / ``tcp_rotvec`` in the flange frame."""
    p, rot = ur3_flange_pose(q_rad)
    off = mat_vec(rot, tcp_offset_m)
    return (p[0] + off[0], p[1] + off[1], p[2] + off[2]), mat_mul(rot, rotvec_to_matrix(*tcp_rotvec))


def check_rtde_frequency(frequency_hz: float) -> None:
    """Refuse an RTDE rate ur_rtde cannot use: -1 (the controller's own) or (0, 500] Hz (125 on a CB3)."""
    if not (frequency_hz == -1 or (math.isfinite(frequency_hz) and 0 < frequency_hz <= 500)):
        raise ValueError(f"frequency_hz = {frequency_hz!r}: must be -1 (automatic) or in (0, 500]")


def probe_tcp(host: str, port: int, timeout_s: float) -> str | None:
    """None if ``host:port`` accepts a TCP connection within ``timeout_s``, else the reason."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return None
    except TimeoutError:
        return f"no answer within {timeout_s:g} s"
    except (OSError, UnicodeError) as exc:
        # a UnicodeError (a host name IDNA cannot encode) has no strerror
        return (exc.strerror if isinstance(exc, OSError) else None) or str(exc)


def require_reachable(host: str, port: int, timeout_s: float, purpose: str = "") -> None:
    """Raise :class:`DeviceError` unless ``host:port`` accepts a TCP connection within ``timeout_s``.

    Asked before ur_rtde dials (it holds the GIL while it connects: see the module docstring).  ``purpose``
    (e.g. ``" for teleoperation"``) follows the address in the message.
    """
    why = probe_tcp(host, port, timeout_s)
    if why is not None:
        raise DeviceError(
            f"cannot reach the UR controller at {host}:{port}{purpose} ({why}); "
            "check the IP address, the cable and that the robot is powered on"
        )


def rtde_interface(module: str, interface: str, host: str, frequency_hz: float, needed_by: str) -> Any:
    """ur_rtde's ``module.interface(host, frequency_hz)``, its module imported only now.

    Lazily: the simulated rig must not need ur_rtde, and only teleoperation takes control of the robot.
    ``needed_by`` names what needs it in the error when ur-rtde is missing.
    """
    try:
        sdk = importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - ur-rtde is a base dependency
        raise DeviceError(f"{needed_by} needs the ur-rtde package ({exc}); pip install ur-rtde") from None
    return getattr(sdk, interface)(host, frequency_hz)


def _default_model() -> RobotModel:
    return robot_model(DEFAULT_ROBOT_MODEL)


@dataclass(frozen=True, slots=True)
class RtdeLink:
    """One UR controller over RTDE: where it is and the rate asked of it (the pose stream and the servo each open one).

    Attributes
    ----------
    host
        Controller IP address.
    frequency_hz
        RTDE rate asked of the controller: up to 125 Hz on a CB3, 500 on an e-Series; -1 lets ur_rtde ask for the
        controller's own rate.
    model
        The robot (:class:`pipeline.devices.registry.RobotModel`): what ``-1`` means on it (:attr:`rate_hz`).
    clock
        The loop's clock (sample timestamps, target ages).
    connect_timeout_s
        Bound of the TCP probe (and of the wait for the first pose).
    port
        Port of the TCP probe (ur_rtde itself always uses 30004).
    """

    host: str
    frequency_hz: float = 125.0
    model: RobotModel = field(default_factory=_default_model)
    clock: Clock = field(default_factory=MonotonicClock)
    connect_timeout_s: float = 2.0
    port: int = RTDE_PORT

    def __post_init__(self) -> None:
        check_rtde_frequency(self.frequency_hz)

    @property
    def rate_hz(self) -> float:
        """The rate the controller publishes at: ``frequency_hz``, or with -1 the model's control rate."""
        return self.model.rate_hz(self.frequency_hz)

    def require_reachable(self, purpose: str = "") -> None:
        """:func:`require_reachable` of this controller's RTDE port."""
        require_reachable(self.host, self.port, self.connect_timeout_s, purpose)


def _default_factory(host: str, frequency_hz: float) -> Any:
    return rtde_interface("rtde_receive", "RTDEReceiveInterface", host, frequency_hz, "the UR backend")


class UrRtdeRobot:
    """A :class:`pipeline.devices.interfaces.Robot` reading a UR controller's TCP pose over RTDE.

    Parameters
    ----------
    link
        The controller, the rate asked of it, the loop's clock (the host-side sample timestamps) and the bound of
        the TCP probe and of the wait for the first pose.
    stale_after_s
        The controller timestamp not advancing this long marks the link stale
        (the loop's own 50 ms limit latches the fault; this drives reconnects).
    reconnect_after_s
        Stale this long (or disconnected) → reconnect.
    min_backoff_s, max_backoff_s
        Reconnect backoff, doubling from min to max.
    receive_factory
        ``factory(host, frequency_hz)`` returning an object with the
        ``RTDEReceiveInterface`` methods (default: ur_rtde's).
    tcp_correction_m
        Added to the reported TCP, in the TCP's own (flange-aligned) frame, m: the calibrated tip minus the
        TCP set on the pendant (:mod:`pipeline.commissioning.tcp`), so the poses the app uses are at the instrument tip.
    """

    def __init__(
        self,
        link: RtdeLink,
        *,
        stale_after_s: float = 0.05,
        reconnect_after_s: float = 0.5,
        min_backoff_s: float = 0.2,
        max_backoff_s: float = 5.0,
        receive_factory: Callable[[str, float], Any] | None = None,
        tcp_correction_m: Vec3 = (0.0, 0.0, 0.0),
    ) -> None:
        self.link = link
        self.host = link.host
        self.tcp_correction_m: Vec3 = tuple(float(v) for v in tcp_correction_m)  # type: ignore[assignment]  # three items: mypy cannot count a generator
        self.frequency_hz = float(link.frequency_hz)
        self.clock: Clock = link.clock
        self.connect_timeout_s = link.connect_timeout_s
        self.stale_after_s = stale_after_s
        self.reconnect_after_s = reconnect_after_s
        self.min_backoff_s = min_backoff_s
        self.max_backoff_s = max_backoff_s
        self._factory = receive_factory or _default_factory
        self._pose = PoseSample(self.clock.now_ns() - 10**12, (math.nan, math.nan, math.nan), IDENTITY, 0.0)
        self.q_rad: tuple[float, ...] = (math.nan,) * 6
        self.state = "connecting"
        self.last_error = ""
        self.reconnects = 0
        self.samples = 0
        self._stop = threading.Event()
        self._new = threading.Condition()
        self._rtde = self._connect()
        self._thread = threading.Thread(target=self._monitor, name="ur-rtde-monitor", daemon=True)
        self._thread.start()
        if not self.wait_for_samples(1, self.connect_timeout_s):
            self.close()
            raise DeviceError(
                f"the UR controller at {self.host} accepted RTDE but sent no robot state within "
                f"{self.connect_timeout_s:g} s; "
                "is the robot powered on and the controller booted?"
            )

    # -- Robot --------------------------------------------------------------------------------
    def read_pose(self) -> PoseSample:
        """The newest TCP pose (never blocks)."""
        return self._pose

    def close(self) -> None:
        """Stop the monitor and disconnect."""
        self._stop.set()
        t = getattr(self, "_thread", None)
        if t is not None and t.is_alive() and threading.current_thread() is not t:
            t.join(2.0)
        self._drop_link()
        self.state = "closed"

    def _drop_link(self) -> None:
        """Disconnect the current RTDE interface, if any, and forget it (the link may already be gone)."""
        rtde, self._rtde = self._rtde, None
        if rtde is not None:
            try:
                rtde.disconnect()
            except Exception:  # the link may already be gone
                pass

    # -- extras -------------------------------------------------------------------------------
    def wait_for_samples(self, n: int, timeout_s: float) -> bool:
        """Block until ``n`` poses have been published (or the timeout); True if reached."""
        with self._new:
            return self._new.wait_for(lambda: self.samples >= n, timeout_s)

    def wait_for_state(self, state: str, timeout_s: float) -> bool:
        """Block until :attr:`state` equals ``state`` (or the timeout); True if reached."""
        with self._new:
            return self._new.wait_for(lambda: self.state == state, timeout_s)

    # -- internals ----------------------------------------------------------------------------
    def _connect(self) -> Any:
        self.link.require_reachable()
        try:
            return self._factory(self.host, self.frequency_hz)
        except RuntimeError as exc:
            raise DeviceError(f"ur_rtde could not connect to the UR controller at {self.host}: {exc}") from None

    def _set_state(self, state: str, error: str = "") -> None:
        with self._new:
            self.state = state
            if error:
                self.last_error = error
            self._new.notify_all()

    def _monitor(self) -> None:
        poll_s = 0.5 / self.link.rate_hz  # twice the controller rate: a new state is seen within half a cycle
        clock = self.clock
        last_ts: float | None = None
        last_change_ns = clock.now_ns()
        stale_ns = int(self.stale_after_s * 1e9)
        reconnect_ns = int(self.reconnect_after_s * 1e9)
        self._set_state("connected")
        while not self._stop.wait(poll_s):
            rtde = self._rtde
            now = clock.now_ns()
            try:
                connected = rtde is not None and rtde.isConnected()
                ts = rtde.getTimestamp() if connected else None
            except Exception as exc:  # any failure of the link is a lost link
                connected, ts = False, None
                self.last_error = str(exc)
            if connected and ts is not None and ts != last_ts:
                last_ts = ts
                last_change_ns = now
                self._publish(rtde, ts, now)
                if self.state != "connected":
                    self._set_state("connected")
                continue
            if connected and now - last_change_ns <= stale_ns:
                continue
            if connected and self.state == "connected":
                self._set_state("stale", f"controller time stuck at {last_ts} s for > {self.stale_after_s:g} s")
            if not connected or now - last_change_ns > reconnect_ns:
                if not connected:
                    self._set_state("disconnected", self.last_error or "RTDE connection lost")
                if self._reconnect():
                    last_change_ns = clock.now_ns()

    def _publish(self, rtde: Any, ts: float, now_ns: int) -> None:
        pose = rtde.getActualTCPPose()
        q = rtde.getActualQ()
        if len(pose) != 6:
            return
        try:
            rot = rotvec_to_matrix(pose[3], pose[4], pose[5])
        except (ValueError, OverflowError):
            rot = (math.nan,) * 9
        self.q_rad = tuple(q) if len(q) == 6 else (math.nan,) * 6
        x, y, z = pose[0], pose[1], pose[2]
        cx, cy, cz = self.tcp_correction_m
        if cx or cy or cz:  # the calibrated tip, not the pendant's TCP
            x += rot[0] * cx + rot[1] * cy + rot[2] * cz
            y += rot[3] * cx + rot[4] * cy + rot[5] * cz
            z += rot[6] * cx + rot[7] * cy + rot[8] * cz
        sample = PoseSample(now_ns, (x, y, z), rot, float(ts))
        with self._new:
            self._pose = sample
            self.samples += 1
            self._new.notify_all()

    def _reconnect(self) -> bool:
        """Reconnect with exponential backoff until it works or :meth:`close`; True on success."""
        backoff = self.min_backoff_s
        while not self._stop.wait(backoff):
            self._set_state("reconnecting")
            why = probe_tcp(self.host, self.link.port, min(self.connect_timeout_s, backoff))
            if why is None:
                try:
                    # A fresh interface, never ur_rtde's reconnect(): on a link that is up but silent (a controller
                    # quiet past reconnect_after_s) reconnect() hung for good or crashed the process in rtde_receive.
                    self._drop_link()
                    self._rtde = self._factory(self.host, self.frequency_hz)
                    self.reconnects += 1
                    return True
                except Exception as exc:  # keep trying; the state says why
                    why = str(exc)
            self.last_error = f"reconnect to {self.host}: {why}"
            backoff = min(self.max_backoff_s, backoff * 2.0)
        return False
