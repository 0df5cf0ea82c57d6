"""The haptic loop's watchdog: its limits, and the line that says what tripped it (science.md §5).

The loop checks every tick (:meth:`pipeline.runtime.loop.HapticLoop.tick`) for a
stale F/T sample or robot pose, non-finite values, a bad sensor status, a
saturated channel and a haptic-device error; :class:`WatchdogConfig` holds
the limits and :func:`fault_detail` words a new latch for the study record;
the other ``*_detail`` functions word the loop's other events (a stall, an
output restart, thermal derating).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.devices.interfaces import Fault, HapticState, PoseSample, WrenchSample
from pipeline.devices.touch_output import hd_error_text

__all__ = [
    "WatchdogConfig",
    "derating_detail",
    "derating_ended_detail",
    "fault_detail",
    "ms_beyond",
    "output_restarted_detail",
    "stall_detail",
]


@dataclass(frozen=True, slots=True)
class WatchdogConfig:
    """Age and range limits of the watchdog (science.md §5)."""

    sensor_max_age_s: float = 0.005
    pose_max_age_s: float = 0.050
    saturation_fraction: float = 0.8
    #: No tick for longer than this latches ``LOOP_STALLED`` (the loop's own check on its next tick, and
    #: :class:`pipeline.runtime.supervisor.LoopSupervisor` while it lasts).
    loop_stall_s: float = 0.050

    def __post_init__(self) -> None:
        for name in ("sensor_max_age_s", "pose_max_age_s", "saturation_fraction", "loop_stall_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"watchdog.{name} = {v!r}: must be a finite number > 0")
        if self.saturation_fraction > 1:
            raise ValueError(f"watchdog.saturation_fraction = {self.saturation_fraction!r}: must be ≤ 1")


def ms_beyond(value_ms: float, limit_ms: float) -> str:
    """``value_ms`` beyond ``limit_ms``, in as few decimals (one at least) as show it beyond: ``5.03`` for 5.03 ms
    against a 5 ms limit, where one decimal read ``5.0 ms (limit 5 ms)``, as if within it."""
    for decimals in range(1, 4):
        text = f"{value_ms:.{decimals}f}"
        if float(text) > limit_ms:
            return text
    return f"{value_ms:.4f}"  # (above the limit by less than 0.5 µs)


def fault_detail(
    new: int,
    w: WrenchSample,
    pose: PoseSample,
    hs: HapticState,
    sensor_age_ns: int,
    pose_age_ns: int,
    watchdog: WatchdogConfig,
    saturation_n: tuple[float, ...],
) -> str:
    """What latched and the value that tripped it, e.g. ``SENSOR_STALE: newest F/T sample 7.0 ms old (limit 5 ms)``.

    Only on the fault path: a tick without a new fault never builds it.

    Parameters
    ----------
    new
        The newly latched faults (:class:`pipeline.devices.interfaces.Fault` bits).
    w, pose, hs
        The tick's F/T sample, robot pose and haptic-device state.
    sensor_age_ns, pose_age_ns
        Ages of the F/T sample and the pose at the tick, ns.
    watchdog
        The limits in force.
    saturation_n
        Per channel, the reading (N, N·m) above which it counts as saturated.

    Returns
    -------
    str
        One line per fault, joined with ``"; "``.
    """
    wd = watchdog
    parts = []
    if new & Fault.SENSOR_STALE:
        age = ms_beyond(sensor_age_ns * 1e-6, wd.sensor_max_age_s * 1e3)
        parts.append(f"SENSOR_STALE: newest F/T sample {age} ms old (limit {wd.sensor_max_age_s * 1e3:g} ms)")
    if new & Fault.SENSOR_STATUS:
        parts.append(f"SENSOR_STATUS: status word 0x{int(w.status):08X}")
    if new & Fault.NON_FINITE:
        names = ("fx", "fy", "fz", "tx", "ty", "tz")
        bad = [f"{n} = {v!r}" for n, v in zip(names, w[1:7], strict=True) if not math.isfinite(v)]
        bad += [f"pose {v!r}" for v in (*pose.position_m, *pose.rot_base_tip) if not math.isfinite(v)][:1]
        parts.append(f"NON_FINITE: {', '.join(bad) or 'a non-finite reading'}")
    if new & Fault.SENSOR_SATURATION:
        names = ("fx", "fy", "fz", "tx", "ty", "tz")
        units = ("N", "N", "N", "N·m", "N·m", "N·m")
        over = [(n, v, r, u) for n, v, r, u in zip(names, w[1:7], saturation_n, units, strict=True) if abs(v) > r]
        n, v, r, u = over[0] if over else ("a channel", math.nan, math.nan, "")
        parts.append(f"SENSOR_SATURATION: {n} = {v:.2f} {u} beyond {wd.saturation_fraction:.0%} of its range "
                     f"(±{r:.3g} {u})")
    if new & Fault.POSE_STALE:
        parts.append(f"POSE_STALE: newest robot pose {ms_beyond(pose_age_ns * 1e-6, wd.pose_max_age_s * 1e3)} ms old "
                     f"(limit {wd.pose_max_age_s * 1e3:g} ms)")
    if new & Fault.HAPTIC_DEVICE:
        parts.append(f"HAPTIC_DEVICE: device error {hd_error_text(hs.error_code)}")
    return "; ".join(parts) or Fault(new).describe()


def stall_detail(period_ns: int, watchdog: WatchdogConfig, command_timeout_ns: int) -> str:
    """The ``LOOP_STALLED`` line for a tick ``period_ns`` after the previous one (beyond ``watchdog.loop_stall_s``)."""
    return (f"LOOP_STALLED: no loop tick for {ms_beyond(period_ns * 1e-6, watchdog.loop_stall_s * 1e3)} ms (limit "
            f"{watchdog.loop_stall_s * 1e3:g} ms); the haptic device's command watchdog "
            f"had dropped the force to zero after {command_timeout_ns * 1e-6:g} ms")


def output_restarted_detail(period_ns: int, command_timeout_ns: int) -> str:
    """The line for a tick later than the device's command watchdog but short of a stall."""
    return (f"no loop tick for {period_ns * 1e-6:.1f} ms: the haptic device's command watchdog "
            f"({command_timeout_ns * 1e-6:g} ms) had dropped the force to zero; "
            "feedback ramps in again from zero")


def derating_detail(heat_fraction: float, peak_n: float, continuous_n: float) -> str:
    """The line for the haptic device's thermal derating beginning (``continuous_n`` NaN when unknown)."""
    # at the onset the limit is still a hair below the peak ("3.30 N" of 3.3 N): say what begins
    toward = f"its {continuous_n:g} N continuous rating" if math.isfinite(continuous_n) else "its continuous rating"
    return (f"haptic device motors warm ({100 * heat_fraction:.0f} % of the thermal budget): derating "
            f"begins — the most it may render falls from its {peak_n:g} N peak toward "
            f"{toward} as they heat further, and rises again as they cool")


def derating_ended_detail(heat_fraction: float, limit_n: float) -> str:
    """The line for the device's derating ending (its limit back at its ``limit_n`` peak)."""
    return (f"haptic device motors cooled ({100 * heat_fraction:.0f} % of the thermal budget): derating "
            f"over, its full {limit_n:g} N peak again")
