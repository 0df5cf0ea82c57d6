"""The simulated rig's configuration, as every command builds it: one builder.

The GUI's study engine, the headless study runner, the database-less runner of
simulated participants, ``haptic-study sim``, ``haptic-study calibrate --rig sim``
and the benchmarks all simulate the same rig; what a command chooses of it --
the seed, a mounting mistake to rehearse, the device models -- becomes a
:class:`pipeline.sim.rig.SimRigConfig` here, so a new choice (another haptic
device, a UR e-Series) is made in one place and every command simulates it.
A choice the registry does not know is refused in one line naming it.
"""

from __future__ import annotations

import math

from pipeline.devices.registry import (
    DEFAULT_HAPTIC_MODEL,
    DEFAULT_ROBOT_MODEL,
    haptic_model,
    haptic_models,
    robot_model,
    robot_models,
)
from pipeline.sim.rig import SimRigConfig

__all__ = ["sim_rig_config"]


def sim_rig_config(
    seed: int = 0,
    *,
    sensor_z_mount_deg: float = 0.0,
    haptic: str = DEFAULT_HAPTIC_MODEL,
    robot: str = DEFAULT_ROBOT_MODEL,
) -> SimRigConfig:
    """The simulated rig of a command: the paper's scene with ``seed``'s noise, on the devices ``haptic`` and
    ``robot`` (keys of :mod:`pipeline.devices.registry`; their twins carry the models' limits).

    Parameters
    ----------
    seed
        Seed of every random process of the rig (noise, drift, packet loss).
    sensor_z_mount_deg
        A mounting mistake to rehearse: the sensor turned about its own z axis, unknown to the pipeline.
    haptic, robot
        The device models simulated.

    Raises
    ------
    ValueError
        One line naming the choice, its value and what is allowed.
    """
    if haptic not in haptic_models():
        allowed = ", ".join(f"{k!r} ({haptic_model(k).name})" for k in haptic_models())
        raise ValueError(f"simulated haptic device = {haptic!r}: allowed values: {allowed}")
    if robot not in robot_models():
        allowed = ", ".join(f"{k!r} ({robot_model(k).name})" for k in robot_models())
        raise ValueError(f"simulated robot = {robot!r}: allowed values: {allowed}")
    if not (isinstance(sensor_z_mount_deg, (int, float)) and math.isfinite(sensor_z_mount_deg)
            and abs(sensor_z_mount_deg) <= 180.0):
        raise ValueError(f"sensor_z_mount_deg = {sensor_z_mount_deg!r}: must be a number of degrees from -180 to 180")
    return SimRigConfig(seed=seed, sensor_z_mount_deg=sensor_z_mount_deg, haptic_model=haptic, robot_model=robot)
