"""Gravity and bias compensation of the wrist force/torque sensor (science.md §1), by the names its callers import.

The compensation lives in three modules, one job each:

* :mod:`pipeline.payload_compensator` -- the identified model
  (:class:`PayloadCalibration`) and its 1 kHz evaluation (pure Python);
* :mod:`pipeline.payload_identification` -- offline identification from
  static poses (:func:`identify_payload`, NumPy);
* :mod:`pipeline.bias_refinement` -- online refinement of the bias
  (:class:`RlsBias`).

This module only re-exports the names that callers outside those modules
import from ``pipeline.compensation``; new code imports from the module that
defines the name.
"""

from __future__ import annotations

from pipeline.bias_refinement import RlsBias
from pipeline.payload_compensator import NO_PAYLOAD, PayloadCalibration
from pipeline.payload_identification import (
    CalibrationPose,
    DegeneratePoseSetError,
    identify_payload,
    recommended_pose_set,
)

__all__ = [
    "NO_PAYLOAD",
    "CalibrationPose",
    "DegeneratePoseSetError",
    "PayloadCalibration",
    "RlsBias",
    "identify_payload",
    "recommended_pose_set",
]
