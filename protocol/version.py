"""The installed software version, recorded with every session and report (a light import)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["software_version"]


def software_version() -> str:
    """Installed version of haptic-study."""
    try:
        return version("haptic-study")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "0+unknown"
