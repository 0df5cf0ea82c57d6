"""The calibration steps that drive the rig themselves, run with the loop paused, wherever the loop runs.

Each is ``job(engine, progress, **kwargs)`` on an assembled :class:`pipeline.assembly.engine.Engine`, called with
its loop paused (every arm's force ramped to zero, no tick running): by the study engine itself when the loop
runs in its process, by the loop's own process when it runs there (:class:`pipeline.runtime.loop_link.Job`,
:mod:`pipeline.assembly.loop_host`).  Their results are plain data, so they travel between the processes.  Both
are the simulated rig's: on the real rig the experimenter records each pose from the ring.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.assembly.engine import Engine, arm_devices
from pipeline.commissioning.frame_check import FrameCheck
from pipeline.commissioning.payload_identification import CalibrationPose
from pipeline.force.frames import Mat3

__all__ = ["JOBS", "LoopJob", "measure_poses", "push_axes"]

Progress = Callable[[int, int], None]


def measure_poses(eng: Engine, progress: Progress, *, arm: str, rotations: Sequence[Mat3]) -> list[CalibrationPose]:
    """The simulated robot turns ``arm``'s instrument through ``rotations`` (``rot_base_sensor``) and the wrench is
    averaged at each (:func:`pipeline.sim.calibration.measure_poses`), on the engine's clock."""
    from pipeline.sim.calibration import measure_poses as measure

    return measure(arm_devices(eng, arm), eng.clock, list(rotations), progress=progress)


def push_axes(eng: Engine, progress: Progress, *, arm: str) -> FrameCheck:
    """The simulated experimenter pushes ``arm``'s free tip along each axis while the loop runs ticks itself
    (feedback off), and the directions are checked (:func:`pipeline.sim.commissioning.push_axes`)."""
    from pipeline.sim.commissioning import push_axes as push

    ring = eng.rings[arm]
    assert ring is not None
    return push(arm_devices(eng, arm), eng.loop, ring, framework=eng.frameworks[arm])


@dataclass(frozen=True)
class LoopJob:
    """A job, and whether it runs the loop's ticks itself (then, on the virtual clock, nothing else need pause the
    loop: it is the job that ticks it; on the real clock the loop's own run stops first either way)."""

    run: Callable[..., Any]
    ticks_the_loop: bool


#: The jobs by the name a :class:`pipeline.runtime.loop_link.Job` gives.
JOBS: dict[str, LoopJob] = {"measure_poses": LoopJob(measure_poses, False), "push_axes": LoopJob(push_axes, True)}
