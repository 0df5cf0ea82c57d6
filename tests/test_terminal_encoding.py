"""A terminal that is not UTF-8 gets readable look-alikes, never a traceback (issue 42, class 7)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from study_app.cli.main import main
from study_app.cli.terminal import PLAIN_ERRORS
from tests.cli_subprocess import CLI, tiny_protocol


@given(st.text())
def test_any_text_encodes_in_ascii_and_what_ascii_holds_is_kept(text: str) -> None:
    plain = text.encode("ascii", errors=PLAIN_ERRORS).decode("ascii")
    assert all(ord(ch) < 128 for ch in plain)
    if text.isascii():
        assert plain == text


def test_typographic_characters_become_their_look_alikes() -> None:
    assert "0.27 → 0.54 – 3 ≤ 4 × 2 …".encode("ascii", errors=PLAIN_ERRORS) == b"0.27 -> 0.54 - 3 <= 4 x 2 ..."
    assert "× µ →".encode("latin-1", errors=PLAIN_ERRORS) == "× µ ->".encode("latin-1")  # latin-1 holds × and µ
    assert "漢".encode("ascii", errors=PLAIN_ERRORS) == b"?"


def test_help_on_a_latin1_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    raw = io.BytesIO()
    out = io.TextIOWrapper(raw, encoding="latin-1")  # strict, as Python's own stdout is
    monkeypatch.setattr(sys, "stdout", out)
    with pytest.raises(SystemExit) as done:
        main(["report", "--help"])  # its help holds "Hodges–Lehmann"
    assert done.value.code == 0
    out.flush()
    assert "Hodges-Lehmann" in raw.getvalue().decode("latin-1")


@pytest.mark.parametrize("encoding", ["latin-1", "ascii"])
def test_a_run_on_a_terminal_that_is_not_utf8_ends_with_its_summary(tmp_path: Path, encoding: str) -> None:
    (tmp_path / "tiny.toml").write_text(tiny_protocol("enc"), encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if not k.startswith("HAPTIC_STUDY")} | {"PYTHONIOENCODING": encoding}
    done = subprocess.run([*CLI, "run", "--participants", "1", "--protocol", "tiny.toml", "--db", "s.db"],
                          check=False, capture_output=True, timeout=300, cwd=tmp_path, env=env)
    stdout, stderr = done.stdout.decode(encoding), done.stderr.decode(encoding)  # each decodes as it was written
    assert done.returncode == 0, stderr
    assert "Traceback" not in stderr
    assert " -> " in stdout  # the summary's "paper OFF → ON" column, as its look-alike
