"""Where the guides and the hardware file's template are on this machine, for the help and the window to name.

In a checkout they are ``docs/*.md`` and ``hardware.example.toml`` at its root; an installed wheel ships them
inside the package (``study_app/guide/``, ``study_app/guide/template/``: pyproject.toml), where a lab that never
cloned the source finds them by the path these functions give.
"""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent

__all__ = ["guide", "hardware_template"]


def _first(*candidates: Path, fallback: str) -> str:
    return next((str(p) for p in candidates if p.is_file()), fallback)


def guide(name: str) -> str:
    """The path of the guide ``name`` (e.g. ``"gui.md"``): the installed copy, else the checkout's ``docs/``;
    ``docs/NAME`` if neither is there."""
    return _first(_HERE / "guide" / name, _HERE.parent / "docs" / name, fallback=f"docs/{name}")


def hardware_template() -> str:
    """The path of ``hardware.example.toml``, the template of a real rig's hardware file."""
    return _first(_HERE / "guide" / "template" / "hardware.example.toml", _HERE.parent / "hardware.example.toml",
                  fallback="hardware.example.toml")
