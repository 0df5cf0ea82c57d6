"""What a session's stored configuration (``sessions.config_json``) tells the analysis: the watchdog's limits it ran
with, the pipeline settings it chose that are not the paper's, and the clock its loop ran on."""

from __future__ import annotations

import json
import math

__all__ = ["config_fields"]


def config_fields(config_json: object) -> dict[str, float | str]:
    """The watchdog's age limits a session ran with, ms (NaN where its configuration does not say), its pipeline
    settings that are not the paper's (``""``: the paper's, or not stored) and its loop's clock (``clock``: virtual,
    the headless runner's; real, the GUI's engine and the real rig's, which run in real time; ``""`` not stored)."""
    try:
        config = json.loads(str(config_json))
    except (ValueError, TypeError):
        config = None
    config = config if isinstance(config, dict) else {}
    try:
        wd = config.get("watchdog", {})
        sensor, pose = float(wd["sensor_max_age_s"]) * 1e3, float(wd["pose_max_age_s"]) * 1e3
    except (ValueError, KeyError, TypeError, AttributeError):
        sensor = pose = math.nan
    try:
        settings = ", ".join(f"{k}={float(v):g}" for k, v in (config.get("pipeline_settings") or {}).items())
    except (ValueError, TypeError, AttributeError):
        settings = ""
    return {"watchdog_sensor_max_age_ms": sensor, "watchdog_pose_max_age_ms": pose, "pipeline_settings": settings,
            "clock": str(config.get("clock") or "")}
