"""The haptic loop's own process on the real clock: how the study engine starts it, and its entry point.

The study engine (:mod:`study_app.engine.host`) runs the session runner, the recorder, the commissioning chain, the
jaws and its messages to the GUI; the rig, Algorithm 1 and the 1 kHz loop run alone in the process started here
(:mod:`pipeline.assembly.loop_host`: the loop ticks in its main thread, pinned to one CPU at ``SCHED_FIFO``; the
device receivers its ticks need are its only other threads).  :func:`start_remote_engine` starts it, hands it the
engine's :class:`study_app.engine.setup.HostConfig` over the link, opens the jaws the engine drives itself, and
returns the stand-in for the assembled engine (:class:`pipeline.assembly.remote_engine.RemoteEngine`).  Where the OS
cannot hand a socket to a new process (Windows) it returns None, and the engine runs the loop in a thread of its
own process as before.

Run as ``python -m study_app.engine.loop_process FD`` by :func:`start_remote_engine` only.
"""

from __future__ import annotations

import socket
import sys
from collections.abc import Callable
from typing import Any

from foundation.platform_support.processes import die_with_parent, ignore_interrupts, socket_handover, spawn_with_socket
from pipeline.assembly.engine import arm_devices
from pipeline.assembly.loop_client import LoopLink
from pipeline.assembly.loop_host import DRIVER, TRACER, LoopHost
from pipeline.assembly.remote_engine import RemoteEngine, connect
from pipeline.core.aim import TrialAim
from pipeline.core.clock import (
    MonotonicClock,
    manual_garbage_collection,
    pin_loop_process,
    prepare_helper_thread,
    prepare_realtime_thread,
)
from pipeline.runtime.loop_link import BuildFailed, FrameReader, FrameWriter, LinkClosed, Opening, wait_readable
from pipeline.settings.hardware import HardwareConfig
from study_app.engine import messages as m
from study_app.engine.setup import MANUAL_Y_RANGE_M, HostConfig, SwitchableDriver, build_engine, hardware_of

__all__ = ["RemoteDriver", "RemoteTracer", "loop_runs_alone", "main", "start_remote_engine"]


def loop_runs_alone(config: HostConfig) -> bool:
    """Whether the engine ``config`` describes runs its loop in a process of its own: on the real clock, unless
    told otherwise (``HostConfig.loop_process``) or the OS cannot start it (Windows)."""
    return config.clock == "real" and config.loop_process and socket_handover()


class RemoteDriver:
    """The simulated stylus's driver in the loop's process, as the engine drives it (the session runner's
    participant, the window's driver switch and mouse): each call goes over the link, the cues without a time (the
    loop's process stamps them with the simulated rig's own)."""

    def __init__(self, link: LoopLink) -> None:
        self.link = link
        self.mode = "autopilot"

    def set_mode(self, mode: str) -> None:
        """Switch who drives (one of :data:`study_app.engine.messages.DRIVER_MODES`)."""
        if mode not in m.DRIVER_MODES:
            raise ValueError(f"driver = {mode!r}: allowed values are {', '.join(m.DRIVER_MODES)}")
        self.mode = mode
        self.link.notify(DRIVER, "set_mode", mode)

    def set_manual_y(self, y_m: float) -> None:
        """The person's equilibrium point (clamped there to :data:`MANUAL_Y_RANGE_M`)."""
        if y_m != y_m or y_m in (float("inf"), float("-inf")):
            raise ValueError(f"manual target = {y_m!r}: must be a finite number of metres")
        lo, hi = MANUAL_Y_RANGE_M
        self.link.notify(DRIVER, "set_manual_y", min(hi, max(lo, float(y_m))))

    def install(self, participant: Any) -> None:
        """Hand the stylus's autopilot to a new simulated participant (it travels to the loop's process)."""
        self.link.notify(DRIVER, "install", participant)

    def begin_trial(self, aim: TrialAim, t_s: float) -> None:
        """Forward the cue, what the trial's task asks (``t_s`` is the loop's process's to say)."""
        self.link.notify(DRIVER, "begin_trial", aim)

    def end_trial(self, t_s: float) -> None:
        """Forward the end of a trial."""
        self.link.notify(DRIVER, "end_trial")


class RemoteTracer:
    """The late-tick tracer in the loop's process (``HostConfig.trace_jitter``), as the engine's health report reads
    it: its report over the link; it re-lists the threads there and closes with that process."""

    def __init__(self, link: LoopLink) -> None:
        self.link = link

    def summary(self) -> dict[str, Any]:
        """Late periods by cause (:meth:`pipeline.runtime.jitter_trace.LateTickTracer.summary`)."""
        out: dict[str, Any] = self.link.call(TRACER, "summary")
        return out

    def refresh(self) -> None:
        """Re-list the loop process's threads."""
        self.link.notify(TRACER, "refresh")

    def reset(self) -> None:
        """Forget the counts."""
        self.link.notify(TRACER, "reset")

    def restart(self) -> None:
        """The next period is not a loop period (the loop paused)."""
        self.link.notify(TRACER, "restart")

    def close(self) -> None:
        """Nothing here: the tracer ends with the loop's process."""


def start_remote_engine(
    config: HostConfig, on_open: Callable[[str], None] | None = None,
) -> tuple[RemoteEngine, HardwareConfig | None, str, RemoteDriver] | None:
    """Start the loop's process for ``config`` and wait until it has assembled the rig.

    Returns the stand-in for the engine, the validated hardware file and its text (None and "" on the simulated
    rig) and the simulated stylus's driver; None where the loop cannot have a process of its own.

    Raises
    ------
    RuntimeError
        One line: the hardware file is bad, a device could not be opened, or the process failed.
    """
    hardware, text = hardware_of(config) if config.rig == "real" else (None, "")
    ours, theirs = socket.socketpair()
    try:
        proc = spawn_with_socket([sys.executable, "-m", "study_app.engine.loop_process", str(theirs.fileno())], theirs)
    finally:
        theirs.close()
    if proc is None:
        ours.close()
        return None
    link = LoopLink(ours, proc)
    link.send((list(sys.path), config))  # the engine's import path first, as multiprocessing's spawn passes it
    eng = connect(link, on_open=on_open)
    try:
        for name, jaw in _open_jaws(config, hardware, on_open).items():
            arm_devices(eng, name).jaw = jaw
    except BaseException:
        eng.loop.stop(timeout_s=5.0)
        eng.release()
        raise
    if hardware is not None:
        from pipeline.commissioning.rig_calibration import RigCalibrationFile

        first = hardware.arms[0]
        eng.calibration_file = RigCalibrationFile.load(first.calibration_file) if first.calibration_file else None
    return eng, hardware, text, RemoteDriver(link)


def _open_jaws(config: HostConfig, hardware: HardwareConfig | None,
               on_open: Callable[[str], None] | None) -> dict[str, Any]:
    """The jaws the engine drives itself, by arm: the simulated rig's, or the hardware file's actuators."""
    if hardware is None:
        from pipeline.sim.jaw import SimJaw  # the simulated rig only

        return {name: SimJaw() for name in config.sim_arms}
    from pipeline.assembly.real_rig import open_jaw
    from pipeline.devices.interfaces import DeviceError

    out: dict[str, Any] = {}
    several = len(hardware.arms) > 1
    for arm in hardware.arms:
        if arm.jaw is None:
            continue
        label = f"arm {arm.name!r}: jaw actuator" if several else "jaw actuator"
        if on_open is not None:
            on_open(label)
        try:
            out[arm.name] = open_jaw(arm.jaw)
        except DeviceError as exc:
            for jaw in out.values():
                jaw.close()
            raise RuntimeError(f"real rig: {label}: {exc}") from None
    return out


def main(argv: list[str]) -> int:
    """The loop's process: read what to build, build it, tick until told to stop or the engine goes away."""
    ignore_interrupts()  # the engine ends it (or its going away does): a terminal's Ctrl-C is the GUI's to handle
    die_with_parent()  # while it builds (a device may hang in its connect): nothing renders a force yet
    sock = socket.socket(fileno=int(argv[0]))
    writer, reader = FrameWriter(sock), FrameReader(sock)
    first: Any = None
    try:
        while first is None:
            wait_readable(sock, 1.0)
            got = reader.take()
            first = got[0] if got else None
    except LinkClosed:
        return 1
    sys.path[:], config = first  # the engine's import path (a test's stand-ins, a reference tree), what to build
    placement = pin_loop_process()
    prepare_helper_thread()  # the device threads started while building: below the loop, never preempted by others

    def opening(device: str) -> None:  # said at once: should the device hang, the engine names it
        writer.put(Opening(device))
        writer.flush()

    try:
        eng, _, _ = build_engine(config, SwitchableDriver(), shared_ring=True, jaws=False, on_open=opening)
    except Exception as exc:  # one line for the engine (a device that did not open, a bad calibration file)
        writer.put(BuildFailed(str(exc)))
        while not writer.flush():
            wait_readable(sock, 0.01)
        return 1
    die_with_parent(False)  # from now on an engine that goes away closes the link: the force ramps to zero first
    tracer = None
    if config.trace_jitter:
        from pipeline.runtime.jitter_trace import LateTickTracer

        tracer = LateTickTracer(MonotonicClock())
        eng.loop.clock = tracer
    scheduling = f"{prepare_realtime_thread()} on {placement}"
    eng.loop.scheduling = scheduling
    manual_garbage_collection()  # a collector pass runs only between ticks (LoopHost.service)
    host = LoopHost(eng, writer, reader, tracer=tracer)
    writer.put(host.assembled(scheduling))
    host.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
