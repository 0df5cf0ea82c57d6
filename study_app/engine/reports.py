"""What the study engine says about itself: the rig it runs (``EngineReady``), its state and loop timing
(``Health``), and the loop's faults as the window shows them (``EngineFault``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.assembly.engine_view import EngineView
from pipeline.force.frames import as_mat3
from pipeline.force.payload_compensator import PayloadCalibration
from pipeline.runtime.loop_messages import LoopEvent
from pipeline.settings.hardware import HardwareConfig
from protocol.runner.session import SessionRunner
from study_app.engine import messages as m
from study_app.engine.latency_report import LatencyReport
from study_app.engine.period_stats import PeriodStats
from study_app.engine.setup import HostConfig

__all__ = ["HealthReport", "device_summary", "engine_ready", "fault_event"]


def engine_ready(eng: EngineView, config: HostConfig, driver: str, calibration: PayloadCalibration,
                 hardware: HardwareConfig | None) -> m.EngineReady:
    """The engine's announcement: its rings, rig and clock, the calibration in use, where the simulated rig's
    surface and tip are, the sensor mounts and the devices opened."""
    assert eng.ring is not None
    if eng.simulated:
        rc = eng.rig.config
        surface_z_m, tip_home_m, rot_tip_sensor = rc.surface_z_m, tuple(rc.tip_home_m), rc.rot_tip_sensor
    else:
        surface_z_m, tip_home_m = math.nan, (math.nan, math.nan, math.nan)
        rot_tip_sensor = eng.framework.config.rot_tip_sensor
    return m.EngineReady(
        ring_name=eng.ring.segment, rig=config.rig, clock=config.clock,
        calibration=calibration.to_dict(), surface_z_m=surface_z_m,
        tip_home_m=tip_home_m, driver=driver,
        rot_tip_sensor=as_mat3(rot_tip_sensor),
        devices=device_summary(hardware),
        arm_rings=tuple((n, r.segment) for n, r in eng.rings.items() if r is not None)
        if len(eng.rings) > 1 else (),
        arm_mounts=tuple((n, as_mat3(fw.config.rot_tip_sensor)) for n, fw in eng.frameworks.items())
        if len(eng.frameworks) > 1 else (),
    )


def device_summary(hardware: HardwareConfig | None) -> list[str]:
    """The devices the engine opened, one line each (the simulated rig's twins: one line)."""
    hw = hardware
    if hw is None:
        return ["simulated rig (F/T sensor, UR3, Touch twins)"]
    out = [f"F/T sensor: Net F/T at {hw.sensor.host}:{hw.sensor.port}",
           f"robot: UR over RTDE at {hw.robot.host} ({hw.robot.mode})",
           f"haptic device: {hw.haptic.device_name}"]
    if hw.jaw is not None:
        out.append(f"jaw actuator: {hw.jaw.port}")
    return out


def fault_event(ev: LoopEvent, runner: SessionRunner | None, several_arms: bool) -> m.EngineFault:
    """A loop event as the window shows it, at its time on the running session's clock (what the events table says).

    Called from the loop thread: reads the runner, never changes it."""
    session_t = math.nan
    if runner is not None and not runner.done and runner.clock is not None:
        session_t = runner.session_time_s(ev.t_ns)  # what the events table will say
    # a rig of several arms: the arm named, as the events table stores it (protocol.runner.session)
    detail = f"arm {ev.arm}: {ev.detail}" if several_arms else ev.detail
    return m.EngineFault(ev.t_ns * 1e-9, ev.kind, int(ev.faults), detail, session_t)


class HealthReport:
    """The engine's :class:`study_app.engine.messages.Health`: its state and the loop's timing since the last reset.

    Parameters
    ----------
    eng
        The assembled rig: its loop's counters, its haptic device's heat and limits, each arm's ring.
    clock
        ``"real"`` or ``"virtual"`` (how the loop thread is scheduled is said only on the real clock).
    stats
        The loop's timing, as the engine reads it from the ring.
    tracer
        Explains the late periods (real clock, ``trace_jitter``): a
        :class:`pipeline.runtime.jitter_trace.LateTickTracer` or its stand-in in the loop's own process; or None.
    loop_pid
        The loop's own process's id (0: the loop is a thread of the engine's process).
    latency
        The end-to-end latency's breakdown (real clock), or None.
    """

    def __init__(self, eng: EngineView, clock: str, stats: PeriodStats, tracer: Any, loop_pid: int = 0,
                 latency: LatencyReport | None = None) -> None:
        self.eng = eng
        self.clock = clock
        self.stats = stats
        self.tracer = tracer
        self.loop_pid = loop_pid
        self.latency = latency

    def health(self, runner: SessionRunner | None, *, driver: str, loop_dead: str) -> m.Health:
        """The engine's state and loop timing since the last stats reset."""
        s = self.stats.summary()
        loop = self.eng.loop
        return m.Health(
            loop_rate_hz=s["rate_hz"], period_p50_us=s["period_p50_us"], period_p99_us=s["period_p99_us"],
            abs_dev_p99_us=s["abs_dev_p99_us"], periods_over_2ms=int(s["periods_over_2ms"]),
            missed_slots=int(loop.stats.missed_slots), ticks=int(s["ticks"]), faults=int(loop.faults),
            haptic_on=bool(loop.haptic_on), driver=driver,
            session_running=runner is not None and not runner.done, paused=bool(runner is not None and runner.paused),
            abs_dev_p50_us=s["abs_dev_p50_us"], period_max_us=s["period_max_us"],
            late_periods=None if self.tracer is None else self.tracer.summary(),
            waiting=runner.state.waiting if runner is not None and not runner.done else "",
            scheduling=loop.scheduling if self.clock == "real" else "virtual clock",
            loop_dead=loop_dead, **self._haptic(), arms=self._arms(), loop_pid=self.loop_pid,
            latency=self.latency.latency().to_dict() if self.latency is not None else None,
        )

    def _haptic(self) -> dict[str, Any]:
        haptic = self.eng.rig.haptic
        st = haptic.read_state()
        return {"haptic_heat_fraction": float(st.heat_fraction), "haptic_force_limit_n": float(st.force_limit_n),
                "haptic_peak_force_n": float(haptic.peak_force_n),
                "haptic_continuous_force_n": float(haptic.continuous_force_n)}

    def _arms(self) -> tuple[tuple[str, float, int], ...]:
        """A rig of several arms: each arm's largest task force over its newest 50 ms and its latched faults."""
        if len(self.eng.calibrations) < 2:
            return ()
        out = []
        for name, ring in self.eng.rings.items():
            rows = ring.latest(50) if ring is not None else None
            force = float(np.nanmax(np.abs(rows["force_n"]))) if rows is not None and len(rows) else math.nan
            out.append((name, force, int(self.eng.loop.arm(name).faults)))
        return tuple(out)
