"""Faults a lab meets, injected into the simulated rig at a chosen moment (fault rehearsal).

Each kind drives one of the simulated devices' own fault switches for a
while, so the loop's watchdog sees exactly what it would see from the real
device: no shortcut into the loop.  They rehearse recovery (the
experimenter's reset, the session runner's re-run of the trial) and test it.

========================  ===========================================  ================  =================
kind                      what happens                                 default duration  the watchdog sees
========================  ===========================================  ================  =================
``sensor-stall``          the F/T sensor sends nothing                 20 ms             ``SENSOR_STALE``
``nan-burst``             the F/T sensor sends NaN in ``fx``           5 ms              ``NON_FINITE``
``bad-status``            the F/T status word reports an error         5 ms              ``SENSOR_STATUS``
``stale-pose``            the robot stops publishing its pose          100 ms            ``POSE_STALE``
``device-error``          the Touch raises ``HD_DEVICE_FAULT``         until a reset     ``HAPTIC_DEVICE``
========================  ===========================================  ================  =================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

__all__ = ["BAD_STATUS_WORD", "DEFAULT_DURATION_S", "DEVICE_FAULT_KINDS", "FaultInjector", "SimFault", "latch_delay_s"]

#: The simulated rig's fault kinds (the names used on the command line).
DEVICE_FAULT_KINDS: Final = ("sensor-stall", "nan-burst", "bad-status", "stale-pose", "device-error")
#: How long each lasts unless told otherwise, s (0: until the experimenter's reset re-arms the device).
DEFAULT_DURATION_S: Final[dict[str, float]] = {
    "sensor-stall": 0.020, "nan-burst": 0.005, "bad-status": 0.005, "stale-pose": 0.100, "device-error": 0.0,
}
#: A serious Net F/T status word (any non-zero word but the monitor-condition warning 0x80010000 is serious).
BAD_STATUS_WORD: Final = 0x80020000
#: OpenHaptics' ``HD_DEVICE_FAULT`` (hdDefines.h), as the real backend reports it.
HD_DEVICE_FAULT: Final = 0x0300


def latch_delay_s(kind: str, sensor_max_age_s: float, pose_max_age_s: float, tick_s: float = 0.001) -> float:
    """The longest time from a fault's start to the watchdog's latch, s (0 for ``kill``, which needs no watchdog).

    A stalled sensor is seen once its newest sample is older than ``sensor_max_age_s``, a frozen robot
    once its pose is older than ``pose_max_age_s``; the others at the next sample or status read.  One
    tick more for where in a tick the fault begins, one for the loop to act on it.
    """
    if kind == "kill":
        return 0.0
    if kind not in DEVICE_FAULT_KINDS:
        raise ValueError(f"fault kind = {kind!r}: allowed values are {', '.join(DEVICE_FAULT_KINDS)} and kill")
    age = {"sensor-stall": sensor_max_age_s, "stale-pose": pose_max_age_s}.get(kind, 0.0)
    return age + 2 * tick_s


@dataclass(frozen=True, slots=True)
class SimFault:
    """One fault: ``kind`` at rig time ``at_ns`` (the loop clock) for ``duration_s``."""

    kind: str
    at_ns: int
    duration_s: float

    def __post_init__(self) -> None:
        if self.kind not in DEVICE_FAULT_KINDS:
            raise ValueError(f"fault kind = {self.kind!r}: allowed values are {', '.join(DEVICE_FAULT_KINDS)}")
        if not (self.duration_s >= 0 and self.duration_s < 3600):
            raise ValueError(f"fault duration = {self.duration_s!r} s: must be from 0 to 3600")


class FaultInjector:
    """Scheduled faults of one simulated rig, switched on and off as the rig's clock passes them.

    The rig calls :meth:`apply` at the start of each step only while something
    is scheduled or active (:attr:`busy`), so a rig without faults pays nothing.
    """

    def __init__(self) -> None:
        self._scheduled: list[SimFault] = []
        self._active: list[tuple[SimFault, int]] = []  # (fault, end ns; -1 = until re-armed)
        #: Every fault switched on so far: (kind, rig time ns).
        self.log: list[tuple[str, int]] = []
        #: True while a fault is scheduled or active: a flag kept where the two lists change, read every tick (a
        #: property's call cost ~0.1 µs a tick, most of what a rig without faults paid for them).
        self.busy = False

    def _changed(self) -> None:
        self.busy = bool(self._scheduled or self._active)

    def schedule(self, fault: SimFault) -> None:
        """Switch ``fault`` on when the rig's clock reaches its time (at once if that has passed)."""
        self._scheduled.append(fault)
        self._scheduled.sort(key=lambda f: f.at_ns)
        self.busy = True

    def cancel(self, kind: str, at_ns: int, rig: Any = None) -> bool:
        """Withdraw a scheduled fault that has not started, or (given the ``rig``) end one that has; True if there was
        one.

        Ending a fault early switches its device back at once: the fault of a trial that ended before
        the watchdog latched it does not go on into the pause or the next trial.
        """
        for f in self._scheduled:
            if f.kind == kind and f.at_ns == at_ns:
                self._scheduled.remove(f)
                self._changed()
                return True
        for entry in self._active:
            if rig is not None and entry[0].kind == kind and entry[0].at_ns == at_ns:
                self._active.remove(entry)
                self._changed()
                _switch(rig, kind, False)
                return True
        return False

    def apply(self, rig: Any, now_ns: int) -> None:
        """Switch on what is due and off what has ended (the rig's devices' own fault switches)."""
        while self._scheduled and self._scheduled[0].at_ns <= now_ns:
            f = self._scheduled.pop(0)
            _switch(rig, f.kind, True)
            self.log.append((f.kind, now_ns))
            end = -1 if f.duration_s == 0 and f.kind == "device-error" else now_ns + round(f.duration_s * 1e9)
            self._active.append((f, end))
        still = []
        for f, end in self._active:
            if f.kind == "device-error":
                if rig.haptic.error_code != HD_DEVICE_FAULT:  # re-armed by a reset
                    continue
                if end < 0 or now_ns < end:
                    still.append((f, end))
                    continue
            elif now_ns < end:
                still.append((f, end))
                continue
            _switch(rig, f.kind, False)
        self._active = still
        self._changed()


def _switch(rig: Any, kind: str, on: bool) -> None:
    if kind == "sensor-stall":
        rig.sensor.stalled = on
    elif kind == "nan-burst":
        rig.sensor.inject_nan = on
    elif kind == "bad-status":
        rig.sensor.status_override = BAD_STATUS_WORD if on else 0
    elif kind == "stale-pose":
        rig.robot.frozen = on
    elif kind == "device-error":
        if on:
            rig.haptic.error_code = HD_DEVICE_FAULT
        elif rig.haptic.error_code == HD_DEVICE_FAULT:
            rig.haptic.error_code = 0
