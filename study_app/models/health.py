"""Device and loop health: each device's state, update rate and sample age; faults; the loop's timing."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.devices import Fault
from study_app import messages as m
from study_app.models import Emitter

__all__ = ["DeviceStatus", "HealthModel"]

#: Fault bits that belong to each device row.
_DEVICE_FAULTS = {
    "F/T sensor": Fault.SENSOR_STALE | Fault.SENSOR_STATUS | Fault.SENSOR_SATURATION | Fault.NON_FINITE,
    "Robot (pose)": Fault.POSE_STALE,
    "Haptic device": Fault.HAPTIC_DEVICE,
}


@dataclass(frozen=True, slots=True)
class DeviceStatus:
    """One row of the device table."""

    name: str
    state: str
    rate_hz: float
    age_ms: float


@dataclass
class HealthModel:
    """Health from :class:`study_app.messages.Health` events, fault events and the ring's records.

    Device rates are measured in sample time from the records: a new F/T
    sample changes the raw wrench, a new robot pose resets the pose age.
    """

    connected: bool = False
    faults: int = 0
    fault_log: list[str] = field(default_factory=list)
    loop: m.Health | None = None
    devices: list[DeviceStatus] = field(default_factory=list)
    changed: Emitter = field(default_factory=Emitter)

    def apply(self, ev: object) -> None:
        """Update from an engine event."""
        if isinstance(ev, m.EngineReady):
            self.connected = True
        elif isinstance(ev, m.Health):
            self.loop = ev
            self.faults = ev.faults
        elif isinstance(ev, m.EngineFault):
            self.faults = ev.faults
            verb = "fault" if ev.kind == "fault" else "reset"
            self.fault_log.append(f"t = {ev.t_s:8.3f} s  {verb}: {ev.detail}")
            del self.fault_log[:-50]
        elif isinstance(ev, m.EngineStopped):
            self.connected = False
        else:
            return
        self._refresh_states()
        self.changed.emit()

    def update_from_rows(self, rows: np.ndarray) -> None:
        """Measure device rates and ages over a block of records (≥ ~0.2 s gives stable rates)."""
        if len(rows) < 2:
            return
        span = float(rows["t_s"][-1] - rows["t_s"][0])
        if span <= 0:
            return
        raw = np.stack([rows["raw_fx"], rows["raw_fy"], rows["raw_fz"]], axis=1)
        sensor_new = int(np.count_nonzero(np.any(np.diff(raw, axis=0) != 0, axis=1)))
        pose_new = int(np.count_nonzero(np.diff(rows["pose_age_s"]) < 0))
        last = rows[-1]
        ticks = len(rows) - 1
        self.devices = [
            DeviceStatus("F/T sensor", "", sensor_new / span, float(last["sensor_age_s"]) * 1e3),
            DeviceStatus("Robot (pose)", "", pose_new / span, float(last["pose_age_s"]) * 1e3),
            DeviceStatus("Haptic device", "", ticks / span, 0.0),
        ]
        self._refresh_states()
        self.changed.emit()

    def _refresh_states(self) -> None:
        out = []
        for d in self.devices:
            bits = Fault(self.faults & _DEVICE_FAULTS.get(d.name, 0))
            state = "disconnected" if not self.connected else ("FAULT: " + bits.describe() if bits else "ok")
            out.append(DeviceStatus(d.name, state, d.rate_hz, d.age_ms))
        self.devices = out

    def faults_text(self) -> str:
        """Latched faults, or 'none'."""
        return Fault(self.faults).describe()

    def loop_text(self) -> str:
        """Loop rate, p99 |period − 1 ms| and overruns."""
        h = self.loop
        if h is None:
            return "loop: –"
        p99 = "–" if math.isnan(h.abs_dev_p99_us) else f"{h.abs_dev_p99_us:.0f} µs"
        return (f"loop {h.loop_rate_hz:6.0f} Hz · p99 |period − 1 ms| {p99} · "
                f"overruns {h.periods_over_2ms} (> 2 ms), {h.missed_slots} missed slots")
