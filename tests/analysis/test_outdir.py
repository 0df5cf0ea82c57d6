"""The output-folder policy of ``report --out`` and ``power --out`` (analysis.outdir)."""

from __future__ import annotations

import json
import os

import pytest

from analysis import outdir
from analysis.load import AnalysisError
from analysis.outdir import check_output_folder, sha256_file, write_output_folder

MARKER = ".haptic-study-test"


def _fill(files: dict[str, str]):
    def fill(folder):
        for name, text in files.items():
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text(text)
    return fill


def _write(out, files, **kw):
    return write_output_folder(out, _fill(files), command="test", marker=MARKER, **kw)


def _snapshot(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _no_temporaries(parent):
    assert not [p.name for p in parent.iterdir() if p.name.startswith(".")], list(parent.iterdir())


def test_a_new_folder_gets_the_files_and_a_marker_with_their_hashes(tmp_path):
    out = tmp_path / "o"
    assert _write(out, {"a.csv": "1", "figures/b.png": "2"}) == ["a.csv", "figures/b.png"]
    marker = json.loads((out / MARKER).read_text())
    assert marker["files"] == {"a.csv": sha256_file(out / "a.csv"), "figures/b.png": sha256_file(out / "figures/b.png")}
    assert "pending" not in marker
    _no_temporaries(tmp_path)


def test_an_existing_non_empty_folder_needs_force(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    before = _snapshot(out)
    with pytest.raises(AnalysisError, match=r"the folder exists and holds a.csv; choose another folder, or pass "
                       r"--force to replace a folder test wrote before \(--force replaces only test's own unedited files\)"):
        _write(out, {"a.csv": "2"})
    assert _snapshot(out) == before


def test_force_replaces_own_unedited_files_and_removes_those_no_longer_written(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "old.csv": "x", "figures/b.png": "2"})
    _write(out, {"a.csv": "new", "c.csv": "3"}, force=True)
    assert _snapshot(out).keys() == {"a.csv", "c.csv", MARKER}
    assert (out / "a.csv").read_text() == "new" and not (out / "figures").exists()
    assert json.loads((out / MARKER).read_text())["files"].keys() == {"a.csv", "c.csv"}
    _no_temporaries(tmp_path)


def test_force_refuses_an_edited_file_naming_it_and_touches_nothing(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    (out / "b.csv").write_text("2, with my correction")
    before = _snapshot(out)
    with pytest.raises(AnalysisError) as err:
        _write(out, {"a.csv": "new"}, force=True)
    assert str(err.value) == (f"--out {out}: b.csv was changed since test wrote it; keep your edits elsewhere or "
                              "choose another folder (nothing was deleted)")
    assert _snapshot(out) == before
    _no_temporaries(tmp_path)


def test_force_refuses_a_foreign_file_naming_it_and_touches_nothing(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    (out / "sub").mkdir()
    (out / "sub" / "notes.md").write_text("mine")
    before = _snapshot(out)
    with pytest.raises(AnalysisError) as err:
        _write(out, {"a.csv": "new"}, force=True)
    assert str(err.value) == (f"--out {out}: holds sub/notes.md, which test did not write; move it or choose another "
                              "folder (nothing was deleted)")
    assert _snapshot(out) == before


def test_force_refuses_a_folder_without_marker(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "a.csv").write_text("someone's")
    with pytest.raises(AnalysisError, match="not a folder test wrote .no readable .haptic-study-test in it."):
        _write(out, {"a.csv": "new"}, force=True)
    assert (out / "a.csv").read_text() == "someone's"


@pytest.mark.parametrize("where", ["o/study.db", "o/sub/study.db", "o"])
def test_an_input_database_inside_the_folder_is_refused(tmp_path, where):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    (out / "sub").mkdir()
    for db in ("study.db", "sub/study.db"):
        (out / db).write_bytes(b"SQLite format 3\x00")
    before = _snapshot(out)
    with pytest.raises(AnalysisError, match="holds the input database"):
        _write(out, {"a.csv": "new"}, inputs=[tmp_path / where], force=True)
    assert _snapshot(out) == before


def test_a_crash_while_writing_leaves_the_old_output_intact(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    before = _snapshot(out)

    def crash(folder):
        (folder / "a.csv").write_text("half")
        raise RuntimeError("the figure failed")

    with pytest.raises(RuntimeError, match="the figure failed"):
        write_output_folder(out, crash, command="test", marker=MARKER, force=True)
    assert _snapshot(out) == before
    _no_temporaries(tmp_path)
    # also into a folder that did not exist: nothing is left
    with pytest.raises(RuntimeError):
        write_output_folder(tmp_path / "new", crash, command="test", marker=MARKER)
    assert not (tmp_path / "new").exists()
    _no_temporaries(tmp_path)


def test_a_crash_between_two_renames_leaves_a_folder_force_can_replace(tmp_path, monkeypatch):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    real = os.replace
    calls = []

    def replace_then_die(src, dst):
        calls.append(dst)
        if str(dst).endswith("b.csv"):
            raise KeyboardInterrupt  # killed after a.csv was moved in, before b.csv
        return real(src, dst)

    monkeypatch.setattr(outdir.os, "replace", replace_then_die)
    with pytest.raises(KeyboardInterrupt):
        _write(out, {"a.csv": "new", "b.csv": "new"}, force=True)
    monkeypatch.setattr(outdir.os, "replace", real)
    assert (out / "a.csv").read_text() == "new" and (out / "b.csv").read_text() == "2"  # a mixture ...
    check_output_folder(out, command="test", marker=MARKER, force=True)  # ... that is still ours to replace
    _write(out, {"a.csv": "3", "b.csv": "3"}, force=True)
    assert (out / "a.csv").read_text() == (out / "b.csv").read_text() == "3"
    assert "pending" not in json.loads((out / MARKER).read_text())


def test_kept_files_are_never_touched_and_do_not_make_the_folder_non_empty(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "pool.db").write_text("pool")

    def keep(name):
        return name == "pool.db"

    _write(out, {"a.csv": "1"}, keep=keep)  # only the kept file there: no --force needed
    assert (out / "pool.db").read_text() == "pool" and (out / "a.csv").read_text() == "1"
    with pytest.raises(AnalysisError, match="pass --force"):
        _write(out, {"a.csv": "2"}, keep=keep)
    _write(out, {"a.csv": "2"}, keep=keep, force=True)
    assert (out / "pool.db").read_text() == "pool" and (out / "a.csv").read_text() == "2"
    assert "pool.db" not in json.loads((out / MARKER).read_text())["files"]


def test_a_file_not_a_folder_and_a_missing_parent_are_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(AnalysisError, match="exists and is not a folder"):
        _write(tmp_path / "f", {"a": "1"})
    with pytest.raises(AnalysisError, match="does not exist"):
        _write(tmp_path / "no" / "o", {"a": "1"})
