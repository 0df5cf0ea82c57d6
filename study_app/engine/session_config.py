"""What a session stores of the rig it ran on (``sessions.config_json``), for the headless runner and the GUI engine."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from pipeline.assembly.engine_view import EngineView
from pipeline.commissioning.qualification import read_record
from pipeline.force.pipeline_settings import non_default_settings, settings_of
from pipeline.settings.hardware import HardwareConfig
from protocol.study.groups import GroupDesign, simulated_profile

__all__ = ["config_record", "qualification_record", "real_config_record", "with_profile"]


def config_record(eng: EngineView, clock: str, rig_seed: int, participant_seed: int) -> dict[str, Any]:
    """The ``config_json`` of a simulated-rig session: rig, framework and watchdog settings, seeds; on a rig of
    several arms also ``arms``: their names (the task arm, whose records the session holds, first), and each arm's
    calibration (the session's ``calibration_json`` is the task arm's).

    ``pipeline_settings`` repeats, from ``framework``, the settings ``run --set`` chooses that are not the paper's
    (:mod:`pipeline.force.pipeline_settings`; ``{}`` for the paper's), so that analysis can say so without
    knowing the pipeline's defaults.
    """
    fw = eng.framework.config
    arms = {"arms": {"names": list(eng.calibrations),
                     "calibrations": {name: cal.to_dict() for name, cal in eng.calibrations.items()}}}
    return {
        **(arms if len(eng.calibrations) > 1 else {}),
        "rig": "sim",
        "clock": clock,
        "rig_seed": rig_seed,
        "participant_seed": participant_seed,
        "sim": _plain(eng.rig.config.record()),
        "framework": _plain(dataclasses.asdict(fw)),
        "pipeline_settings": non_default_settings(settings_of(fw)),
        "watchdog": _plain(dataclasses.asdict(eng.loop.watchdog)),
    }


def with_profile(config: dict[str, Any], groups: GroupDesign | None, covariates: Mapping[str, object]
                 ) -> dict[str, Any]:
    """A simulated-rig session's config record naming the simulated participant's profile where it is not the
    calibrated one (``participant_profile``; :mod:`pipeline.sim.experience`), from the participant's covariates
    (its group, ``[groups]``): the record of a study without groups is as before.  The headless runner's and the
    GUI's sessions both record it so."""
    profile = simulated_profile(groups, covariates)
    return config if profile == "novice" else {**config, "participant_profile": profile}


def real_config_record(hw: HardwareConfig, hardware_text: str, eng: EngineView) -> dict[str, Any]:
    """The ``config_json`` of a real-rig session: the hardware file as written and as validated, framework, watchdog."""
    return {
        "rig": "real",
        "clock": "real",
        "participant": "person",
        "hardware_file": hw.source,
        "hardware_toml": hardware_text,
        "hardware": _plain(dataclasses.asdict(hw)),
        "framework": _plain(dataclasses.asdict(eng.framework.config)),
        "pipeline_settings": non_default_settings(settings_of(eng.framework.config)),
        "watchdog": _plain(dataclasses.asdict(eng.loop.watchdog)),
        **qualification_record(hw),
    }


def qualification_record(hw: HardwareConfig) -> dict[str, Any]:
    """``qualification``: each arm's record of ``haptic-study qualify`` as it stood when the session started (an
    unreadable one as its reason); nothing when no arm was ever qualified (docs/qualify.md)."""
    out: dict[str, Any] = {}
    for arm in hw.arms:
        try:
            record = read_record(arm.calibration_file)
        except (OSError, ValueError) as exc:
            record = {"verdict": "UNREADABLE", "why": str(exc)}
        if record is not None:
            out[arm.name] = record
    return {"qualification": out} if out else {}


def _plain(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _plain(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [_plain(v) for v in d]
    return d
