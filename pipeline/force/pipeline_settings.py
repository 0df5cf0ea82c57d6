"""The pipeline's settings a user may choose for a simulated study: names, parsing, and the configuration they make.

``haptic-study run --set NAME=VALUE`` and ``haptic-study sweep --set NAME=V1,V2,...`` name five values of
:class:`pipeline.force.framework.FrameworkConfig` (and its :class:`pipeline.force.safety.SafetyConfig`).  Their
limits are those classes' own: a value is checked by building the configuration with it, so a limit is written
once, where the value is used.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

from pipeline.force.config import FrameworkConfig

__all__ = [
    "ALIASES", "SETTING_NAMES", "canonical_name", "describe", "framework_with", "non_default_settings",
    "paper_settings", "parse_setting", "settings_of", "stored_settings",
]

#: The settings, in the order they are shown; ``filter_window`` is a whole number of samples, the others numbers
#: with the unit their name ends in.
SETTING_NAMES: tuple[str, ...] = ("filter_window", "f_scale_n", "f_max_n", "slew_n_per_s", "ramp_in_s")
#: Short names accepted for the settings.
ALIASES: dict[str, str] = {"f_scale": "f_scale_n", "f_max": "f_max_n", "slew": "slew_n_per_s", "ramp_in": "ramp_in_s"}
_SAFETY = ("slew_n_per_s", "ramp_in_s")


def canonical_name(name: str) -> str:
    """The setting ``name`` stands for; :class:`ValueError` (what is allowed) if it is none."""
    key = ALIASES.get(name, name)
    if key not in SETTING_NAMES:
        allowed = ", ".join(SETTING_NAMES)
        raise ValueError(f"unknown setting {name!r}: allowed are {allowed} (or f_scale, f_max, slew, ramp_in)")
    return key


def framework_with(settings: Mapping[str, float], base: FrameworkConfig | None = None) -> FrameworkConfig:
    """``base`` (default: the paper's configuration) with ``settings`` applied, validated by the classes themselves.

    Raises
    ------
    ValueError
        An unknown name, or a value the configuration refuses (its own message: name, value, what is allowed).
    """
    cfg = base or FrameworkConfig()
    top: dict[str, Any] = {}
    safety: dict[str, Any] = {}
    for name, value in settings.items():
        key = canonical_name(name)
        (safety if key in _SAFETY else top)[key] = value
    new_safety = dataclasses.replace(cfg.safety, **safety) if safety else cfg.safety
    if "f_max_n" in top:  # the framework forces its safety clamp to f_max; set both so the replace validates once
        new_safety = dataclasses.replace(new_safety, f_max_n=top["f_max_n"])
    return dataclasses.replace(cfg, safety=new_safety, **top)


def parse_setting(name: str, text: str) -> float:
    """One value of setting ``name`` from the command line, checked against the configuration's limits.

    Returns an ``int`` for ``filter_window``, a ``float`` otherwise.  :class:`ValueError` says what is allowed.
    """
    key = canonical_name(name)
    value: float
    if key == "filter_window":
        try:
            value = int(text)
        except ValueError:
            raise ValueError(f"{key} = {text!r}: must be a whole number of samples from 1 to 1000") from None
    else:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise ValueError(f"{key} = {text!r}: must be a finite number")
    framework_with({key: value})  # the configuration's own check (its message names the value and the limits)
    return value


def settings_of(cfg: FrameworkConfig) -> dict[str, float]:
    """The five settings of ``cfg``, by name."""
    return {"filter_window": cfg.filter_window, "f_scale_n": cfg.f_scale_n, "f_max_n": cfg.f_max_n,
            "slew_n_per_s": cfg.safety.slew_n_per_s, "ramp_in_s": cfg.safety.ramp_in_s}


def paper_settings() -> dict[str, float]:
    """The settings of the paper's study (the configuration's defaults)."""
    return settings_of(FrameworkConfig())


def stored_settings(stored: Any) -> dict[str, float]:
    """The settings in a stored framework record (``sessions.config_json``'s ``"framework"``, as
    :func:`dataclasses.asdict` of the configuration wrote it); a setting the record lacks is the paper's."""
    rec: Mapping[str, Any] = stored if isinstance(stored, Mapping) else {}
    raw = rec.get("safety")
    safety: Mapping[str, Any] = raw if isinstance(raw, Mapping) else {}
    paper = paper_settings()
    have = {"filter_window": rec.get("filter_window"), "f_scale_n": rec.get("f_scale_n"),
            "f_max_n": rec.get("f_max_n"), "slew_n_per_s": safety.get("slew_n_per_s"),
            "ramp_in_s": safety.get("ramp_in_s")}
    return {k: paper[k] if v is None else v for k, v in have.items()}


def non_default_settings(settings: Mapping[str, float]) -> dict[str, float]:
    """The settings that are not the paper's."""
    paper = paper_settings()
    return {k: v for k, v in settings.items() if v != paper[k]}


def describe(settings: Mapping[str, float]) -> str:
    """``filter_window=50, f_scale_n=3`` (in :data:`SETTING_NAMES` order); ``the paper's`` when empty."""
    parts = [f"{k}={settings[k]:g}" for k in SETTING_NAMES if k in settings]
    return ", ".join(parts) if parts else "the paper's"
