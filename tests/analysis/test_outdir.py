"""The one output policy of every command that writes files (foundation.outdir): folders, single files, links,
permissions, and the file system failing."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
from contextlib import contextmanager

import pytest
from mounts import can_mount, tmpfs

from foundation import outdir
from foundation.outdir import check_output_folder, write_output_folder
from foundation.outfile import check_output_file, write_output_file
from foundation.outfs import OutputError
from foundation.outmarker import sha256_file

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


def _no_temporaries(folder, *allowed):
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".") and p.name not in allowed], \
        list(folder.iterdir())


def test_a_new_folder_gets_the_files_and_a_marker_with_their_hashes(tmp_path):
    out = tmp_path / "o"
    assert _write(out, {"a.csv": "1", "figures/b.png": "2"}) == ["a.csv", "figures/b.png"]
    marker = json.loads((out / MARKER).read_text())
    assert marker["files"] == {"a.csv": sha256_file(out / "a.csv"), "figures/b.png": sha256_file(out / "figures/b.png")}
    assert "pending" not in marker
    _no_temporaries(tmp_path)
    _no_temporaries(out, MARKER)


def test_an_existing_non_empty_folder_needs_force(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    before = _snapshot(out)
    with pytest.raises(OutputError, match=r"the folder exists and holds a.csv; choose another folder, or pass "
                       r"--force to replace a folder test wrote before \(--force replaces only test's own unedited "
                       r"files\)"):
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
    _no_temporaries(out, MARKER)


def test_force_refuses_an_edited_file_naming_it_and_touches_nothing(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    (out / "b.csv").write_text("2, with my correction")
    before = _snapshot(out)
    with pytest.raises(OutputError) as err:
        _write(out, {"a.csv": "new"}, force=True)
    assert str(err.value) == (f"--out {out}: b.csv was changed since test wrote it; keep your edits elsewhere or "
                              "choose another folder (nothing was deleted)")
    assert _snapshot(out) == before
    _no_temporaries(tmp_path)
    _no_temporaries(out, MARKER)


def test_force_refuses_a_foreign_file_naming_it_and_touches_nothing(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    (out / "sub").mkdir()
    (out / "sub" / "notes.md").write_text("mine")
    before = _snapshot(out)
    with pytest.raises(OutputError) as err:
        _write(out, {"a.csv": "new"}, force=True)
    assert str(err.value) == (f"--out {out}: holds sub/notes.md, which test did not write; move it or choose another "
                              "folder (nothing was deleted)")
    assert _snapshot(out) == before


def test_force_refuses_a_folder_without_marker(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "a.csv").write_text("someone's")
    with pytest.raises(OutputError, match=r"not a folder test wrote .no readable .haptic-study-test in it."):
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
    with pytest.raises(OutputError, match="holds the input database"):
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
    _no_temporaries(out, MARKER)
    # also into a folder that did not exist: nothing is left
    with pytest.raises(RuntimeError):
        write_output_folder(tmp_path / "new", crash, command="test", marker=MARKER)
    assert not (tmp_path / "new").exists()
    _no_temporaries(tmp_path)


def test_a_crash_between_two_renames_leaves_a_folder_force_can_replace(tmp_path, monkeypatch):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    real = os.rename

    def rename_then_die(src, dst, **kw):
        if str(dst) == "b.csv":
            raise KeyboardInterrupt  # killed after a.csv was moved in, before b.csv
        return real(src, dst, **kw)

    monkeypatch.setattr(outdir.os, "rename", rename_then_die)
    with pytest.raises(KeyboardInterrupt):
        _write(out, {"a.csv": "new", "b.csv": "new"}, force=True)
    monkeypatch.setattr(outdir.os, "rename", real)
    assert (out / "a.csv").read_text() == "new" and (out / "b.csv").read_text() == "2"  # a mixture ...
    check_output_folder(out, command="test", marker=MARKER, force=True)  # ... that is still ours to replace
    _write(out, {"a.csv": "3", "b.csv": "3"}, force=True)
    assert (out / "a.csv").read_text() == (out / "b.csv").read_text() == "3"
    assert "pending" not in json.loads((out / MARKER).read_text())
    _no_temporaries(out, MARKER)


def test_kept_files_are_never_touched_and_do_not_make_the_folder_non_empty(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "pool.db").write_text("pool")

    def keep(name):
        return name == "pool.db"

    _write(out, {"a.csv": "1"}, keep=keep)  # only the kept file there: no --force needed
    assert (out / "pool.db").read_text() == "pool" and (out / "a.csv").read_text() == "1"
    with pytest.raises(OutputError, match="pass --force"):
        _write(out, {"a.csv": "2"}, keep=keep)
    _write(out, {"a.csv": "2"}, keep=keep, force=True)
    assert (out / "pool.db").read_text() == "pool" and (out / "a.csv").read_text() == "2"
    assert "pool.db" not in json.loads((out / MARKER).read_text())["files"]


def test_a_file_not_a_folder_and_a_missing_parent_are_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputError, match="exists and is not a folder"):
        _write(tmp_path / "f", {"a": "1"})
    with pytest.raises(OutputError, match="does not exist"):
        _write(tmp_path / "no" / "o", {"a": "1"})


# -- the policy of issue 22: links, permissions, single files, the file system failing -----------------------------


@contextmanager
def _umask(mask):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def _mode(p):
    return stat.S_IMODE(os.lstat(p).st_mode)


def test_a_link_inside_the_folder_is_never_followed_even_with_force(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "b.png").write_text("the user's own figure")
    (tmp_path / "notes.txt").write_text("the user's notes")
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "figures/b.png": "2"})
    (out / "figures" / "b.png").unlink()
    (out / "figures").rmdir()
    (out / "figures").symlink_to(mine)  # R/figures is a link to the user's folder
    with pytest.raises(OutputError, match=r"holds figures \(a symbolic link\), which test did not write"):
        _write(out, {"a.csv": "new", "figures/b.png": "new"}, force=True)
    assert (mine / "b.png").read_text() == "the user's own figure"
    # a listed file replaced by a link to the user's file, even one whose bytes hash as listed: not ours
    (out / "figures").unlink()
    (tmp_path / "notes-copy.txt").write_text("1")
    (out / "a.csv").unlink()
    (out / "a.csv").symlink_to(tmp_path / "notes-copy.txt")
    with pytest.raises(OutputError, match=r"holds a.csv \(a symbolic link\)"):
        _write(out, {"a.csv": "new"}, force=True)
    assert (tmp_path / "notes-copy.txt").read_text() == "1"


def test_a_link_as_the_marker_is_no_marker(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (tmp_path / "fake").write_text(json.dumps({"files": {"a.csv": hashlib.sha256(b"someone's").hexdigest()}}))
    (out / MARKER).symlink_to(tmp_path / "fake")
    (out / "a.csv").write_text("someone's")
    with pytest.raises(OutputError, match="no readable"):
        _write(out, {"a.csv": "new"}, force=True)
    assert (out / "a.csv").read_text() == "someone's"


def test_an_existing_folder_keeps_its_permissions_and_new_files_are_private(tmp_path):
    out = tmp_path / "private"
    out.mkdir(mode=0o700)
    out.chmod(0o700)
    inode = out.stat().st_ino
    with _umask(0o022):
        _write(out, {"a.csv": "1", "figures/b.png": "2"})
    assert out.stat().st_ino == inode and _mode(out) == 0o700
    assert _mode(out / "a.csv") == _mode(out / "figures/b.png") == _mode(out / MARKER) == 0o600
    assert _mode(out / "figures") == 0o700
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o775)
    with _umask(0o000):  # a permissive umask does not make the outputs world-readable
        _write(shared, {"a.csv": "1"})
        _write(tmp_path / "new", {"a.csv": "1"})
    assert _mode(shared) == 0o775 and _mode(shared / "a.csv") == 0o600
    assert _mode(tmp_path / "new") == 0o700 and _mode(tmp_path / "new" / "a.csv") == 0o600
    with _umask(0o277):  # a stricter umask is followed
        _write(tmp_path / "strict", {"a.csv": "1"})
    assert _mode(tmp_path / "strict" / "a.csv") == 0o400


def test_a_full_disk_while_writing_is_one_line_and_leaves_nothing(tmp_path):
    def full(folder):
        (folder / "a.csv").write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "o"
    with pytest.raises(OutputError) as err:
        write_output_folder(out, full, command="test", marker=MARKER)
    assert err.value.status == 1
    assert str(err.value) == (f"--out {out}: cannot write test's outputs: no space left on the device; free some "
                              "space or write to another disk (nothing was written)")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    existing = tmp_path / "e"
    _write(existing, {"a.csv": "1"})
    before = _snapshot(existing)
    with pytest.raises(OutputError, match="no space left"):
        write_output_folder(existing, full, command="test", marker=MARKER, force=True)
    assert _snapshot(existing) == before
    _no_temporaries(existing, MARKER)


def test_a_stale_temporary_folder_of_a_killed_run_is_neither_output_nor_in_the_way(tmp_path):
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    stale = out / f"{MARKER}.tmp-999999999-abcd"  # no such process
    stale.mkdir()
    (stale / "a.csv").write_text("half")
    check_output_folder(out, command="test", marker=MARKER, force=True)
    _write(out, {"a.csv": "2"}, force=True)
    assert not stale.exists() and (out / "a.csv").read_text() == "2"


def _png(text):
    def fill(path):
        path.write_text(text)
    return fill


def test_one_file_is_written_private_and_whole(tmp_path):
    with _umask(0o000):
        write_output_file(tmp_path / "x.png", _png("figure"), command="plot-trial")
    assert (tmp_path / "x.png").read_text() == "figure" and _mode(tmp_path / "x.png") == 0o600
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]


@pytest.mark.parametrize("what", ["file", "link to a database", "dangling link", "fifo"])
def test_one_file_never_replaces_anything(tmp_path, what):
    db = tmp_path / "study.db"
    db.write_bytes(b"SQLite format 3\x00 the study")
    out = tmp_path / "x.png"
    if what == "file":
        out.write_text("the user's figure")
    elif what == "link to a database":
        out.symlink_to(db)
    elif what == "dangling link":
        out.symlink_to(tmp_path / "nowhere.png")
    else:
        os.mkfifo(out)
    with pytest.raises(OutputError, match=r"x.png: exists.*plot-trial writes a new file only"):
        write_output_file(out, _png("figure"), command="plot-trial")
    assert db.read_bytes() == b"SQLite format 3\x00 the study"
    assert not (tmp_path / "nowhere.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.db", "x.png"]


def test_one_file_that_appears_while_the_command_runs_is_not_overwritten(tmp_path):
    out = tmp_path / "x.png"

    def meanwhile(path):
        path.write_text("figure")
        out.write_text("the user saved this meanwhile")

    with pytest.raises(OutputError, match="appeared while plot-trial ran; it was not overwritten") as err:
        write_output_file(out, meanwhile, command="plot-trial")
    assert err.value.status == 1
    assert out.read_text() == "the user saved this meanwhile"
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]


def test_one_file_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path):
    def full(path):
        path.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OutputError) as err:
        write_output_file(tmp_path / "x.csv", full, command="export")
    assert err.value.status == 1 and "no space left on the device" in str(err.value)
    assert list(tmp_path.iterdir()) == []


_MOUNT = can_mount()
needs_mount = pytest.mark.skipif(bool(_MOUNT), reason=_MOUNT or "mounting works")


@needs_mount
def test_the_root_of_a_mount_point_is_an_output_folder_like_any_other(tmp_path):
    with tmpfs(tmp_path / "m", 1024, mode=0o750) as root:
        _write(root, {"a.csv": "1", "figures/b.png": "2"})
        assert _mode(root) == 0o750 and (root / "figures" / "b.png").read_text() == "2"
        _write(root, {"a.csv": "3"}, force=True)
        assert sorted(p.name for p in root.iterdir()) == [MARKER, "a.csv"]


@needs_mount
def test_a_read_only_or_full_file_system_is_refused_before_the_work(tmp_path):
    work = []
    with tmpfs(tmp_path / "ro", 64, read_only=True) as ro:
        for call in (lambda: write_output_folder(ro / "o", work.append, command="test", marker=MARKER),
                     lambda: write_output_folder(ro, work.append, command="test", marker=MARKER),
                     lambda: write_output_file(ro / "x.png", work.append, command="plot-trial")):
            with pytest.raises(OutputError, match="the file system is read-only; write to a folder on a writable "
                                                  r"disk \(nothing was written\)") as err:
                call()
            assert err.value.status == 2
    with tmpfs(tmp_path / "full", 64) as full:
        (full / "filler").write_bytes(b"\0" * (64 << 10))  # every block taken
        with pytest.raises(OutputError, match="no space left on the device"):
            check_output_file(full / "x.png", command="plot-trial")
    assert work == []


@needs_mount
def test_a_disk_that_fills_while_writing_leaves_the_old_output(tmp_path):
    with tmpfs(tmp_path / "m", 256) as root:
        out = root / "o"
        _write(out, {"a.csv": "1"})
        before = _snapshot(out)
        with pytest.raises(OutputError, match="no space left on the device") as err:
            _write(out, {"a.csv": "2", "big.bin": "x" * (400 << 10)}, force=True)
        assert err.value.status == 1
        assert _snapshot(out) == before
        _no_temporaries(out, MARKER)


@pytest.mark.parametrize(("code", "says"), [
    (errno.EIO, "input/output error (a failing disk, a removed drive or a lost network share); check the device, "
                "then write to another disk"),
    (errno.EROFS, "the file system is read-only; write to a folder on a writable disk"),
    (errno.EACCES, "permission denied; choose a folder you may write to"),
])
def test_a_failing_disk_while_the_outputs_are_made_durable_is_one_line(tmp_path, monkeypatch, code, says):
    from foundation import outfs

    def fail(fd):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(outfs.os, "fsync", fail)
    with pytest.raises(OutputError) as err:
        write_output_file(tmp_path / "x.csv", _png("data"), command="export")
    assert err.value.status == 1
    assert str(err.value) == f"--out {tmp_path / 'x.csv'}: cannot write it: {says} (nothing was written)"
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(OutputError, match=says.split(";")[0].replace("(", r"\(").replace(")", r"\)")):
        _write(tmp_path / "o", {"a.csv": "1"})
    assert list(tmp_path.iterdir()) == []
