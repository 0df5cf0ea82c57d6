"""The output policy without the ``*at`` calls (Windows' path-checking fallback, foundation.outpath), forced on Linux.

Every test of tests/analysis/test_outdir.py runs again here with
``DIR_FD_CALLS`` False, so each step goes by path with ``lstat`` checks; then
the output cases of tests/bad_outputs_corpus.py that need no mount and no
second user are fed to the policy functions in-process (no subprocess): the
same one line, and every file that was there unchanged.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from bad_outputs_corpus import CASES as OUTPUT_CASES
from test_outdir import *  # noqa: F403  (every test of the descriptor path, collected again here)
from test_outdir import MARKER, _fill, _no_temporaries, _write

from analysis.planning.power_pool import is_pool_file
from foundation import outfs, outpath
from foundation.outdir import check_output_folder, write_output_folder
from foundation.outfile import write_output_file
from foundation.outfs import OutputError
from foundation.platform_support import files


@pytest.fixture(autouse=True)
def _no_dir_fd_calls(monkeypatch):
    monkeypatch.setattr(outfs, "DIR_FD_CALLS", False)


def test_the_fallback_is_in_force(tmp_path):
    from foundation.outpath import PathFolder

    assert isinstance(outfs.open_folder(str(tmp_path), follow=True), PathFolder)


def test_a_crash_between_two_renames_leaves_a_folder_force_can_replace(tmp_path, monkeypatch):
    """As in test_outdir (whose version this replaces here), the crash put in ``os.replace``, the fallback's rename."""
    out = tmp_path / "o"
    _write(out, {"a.csv": "1", "b.csv": "2"})
    real = os.replace

    def replace_then_die(src, dst):
        if os.path.basename(dst) == "b.csv":
            raise KeyboardInterrupt  # killed after a.csv was moved in, before b.csv
        return real(src, dst)

    monkeypatch.setattr(outpath.os, "replace", replace_then_die)
    with pytest.raises(KeyboardInterrupt):
        _write(out, {"a.csv": "new", "b.csv": "new"}, force=True)
    monkeypatch.setattr(outpath.os, "replace", real)
    assert (out / "a.csv").read_text() == "new" and (out / "b.csv").read_text() == "2"
    check_output_folder(out, command="test", marker=MARKER, force=True)
    _write(out, {"a.csv": "3", "b.csv": "3"}, force=True)
    assert (out / "a.csv").read_text() == (out / "b.csv").read_text() == "3"
    _no_temporaries(out, MARKER)


# -- what only the fallback has: a check right before each step ------------------------------------------------
def test_a_folder_turned_into_a_link_after_it_was_opened_is_not_written_through(tmp_path):
    (tmp_path / "o" / "figures").mkdir(parents=True)
    (tmp_path / "elsewhere").mkdir()
    root = outfs.open_folder(str(tmp_path / "o"), follow=True)
    figures = outfs.open_folder("figures", root)
    (tmp_path / "o" / "figures").rmdir()
    (tmp_path / "o" / "figures").symlink_to(tmp_path / "elsewhere")  # another process swaps it for a link
    with pytest.raises(OSError) as err:
        outfs.write_bytes_at(figures, "a.png", b"x")
    assert err.value.errno == errno.ELOOP
    with pytest.raises(OSError):
        outfs.unlink_at(figures, "a.png")
    assert list((tmp_path / "elsewhere").iterdir()) == []


def test_the_named_folder_replaced_after_it_was_opened_is_refused(tmp_path):
    (tmp_path / "o").mkdir()
    root = outfs.open_folder(str(tmp_path / "o"), follow=True)
    (tmp_path / "o").rename(tmp_path / "old")
    (tmp_path / "o").mkdir()
    with pytest.raises(OSError, match="replaced while the command ran"):
        outfs.write_bytes_at(root, "a.csv", b"x")
    assert list((tmp_path / "o").iterdir()) == [] and list((tmp_path / "old").iterdir()) == []


def test_a_file_swapped_between_the_look_and_the_open_is_not_read(tmp_path, monkeypatch):
    (tmp_path / "mine.csv").write_text("mine")
    (tmp_path / "other.csv").write_text("someone's")
    root = outfs.open_folder(str(tmp_path), follow=True)
    real = os.open

    def swap_then_open(path, flags, *args):
        if os.path.basename(path) == "mine.csv":
            os.replace(tmp_path / "other.csv", tmp_path / "mine.csv")  # after the lstat, before the open
        return real(path, flags, *args)

    monkeypatch.setattr(outpath.os, "open", swap_then_open)
    with pytest.raises(OSError, match="replaced while the command opened it"):
        outpath.open_at(root, "mine.csv", os.O_RDONLY)
    assert outfs.sha256_at(root, "mine.csv") is None  # the same answer as for a link: not the command's file


@pytest.mark.parametrize("name", ["", ".", "..", "a/b"])
def test_a_name_is_one_entry_never_a_way_out(tmp_path, name):
    root = outfs.open_folder(str(tmp_path), follow=True)
    with pytest.raises(OSError) as err:
        outpath.lstat_at(root, name)
    assert err.value.errno == errno.EINVAL


@pytest.mark.parametrize(("attributes", "tag", "redirects"), [
    (0x10, 0, False),  # a plain folder
    (0x410, 0xA0000003, True),  # a junction (IO_REPARSE_TAG_MOUNT_POINT)
    (0x410, 0xA000000C, True),  # a directory symbolic link
    (0x420, 0x9000001A, False),  # a OneDrive placeholder: a reparse point that names no other path
])
def test_junctions_count_as_links_on_windows(monkeypatch, attributes, tag, redirects):
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.delattr(os.path, "isjunction", raising=False)
    st = SimpleNamespace(st_mode=stat.S_IFDIR | 0o777, st_file_attributes=attributes, st_reparse_tag=tag)
    assert files.redirects("C:\\out\\figures", st) is redirects  # type: ignore[arg-type]


# -- the output cases of the bad-input corpus, in-process, on both paths ------------------------------------------
def _policy(case, d: Path):
    """(the call the command makes first, its ``--out``) for one corpus case, or None when it is no policy case."""
    args = [a.replace("{d}", str(d)) for a in case.args]
    out = args[args.index("--screenshot" if args[0] == "gui" else "--out") + 1]
    dbs = [args[args.index("--db") + 1]] if "--db" in args else []
    force = "--force" in args
    if args[0] in ("plot-trial", "plot-session", "export"):
        return lambda: write_output_file(out, lambda p: p.write_text("x"), command=args[0])
    folder = {"report": dict(command="report", marker=".haptic-study-report", inputs=dbs, force=force),
              "power": dict(command="power", marker=".haptic-study-power", inputs=dbs, force=force,
                            keep=is_pool_file),
              "replay": dict(command="replay", marker=".haptic-study-replay", inputs=dbs),
              "gui": dict(command="gui --screenshot", marker=".haptic-study-screenshots", force=force,
                          option="--screenshot")}.get(args[0])
    if folder is None:
        return None
    return lambda: write_output_folder(out, _fill({"new.csv": "new"}), **folder)


def _tree(d: Path) -> dict[str, str]:
    out = {}
    for p in sorted(d.rglob("*")):
        st = p.lstat()
        what = (f"link -> {os.readlink(p)}" if stat.S_ISLNK(st.st_mode) else
                hashlib.sha256(p.read_bytes()).hexdigest() if stat.S_ISREG(st.st_mode) else "")
        out[str(p.relative_to(d))] = f"{st.st_mode:o} {what}"
    return out


_CORPUS = [c for c in OUTPUT_CASES if not (c.mounts or c.as_nobody or c.read_only or c.xfail or c.after_work)
           and c.args[0] != "run"]


@pytest.mark.parametrize("case", _CORPUS, ids=[c.id for c in _CORPUS])
def test_the_corpus_output_cases_end_in_the_same_line_without_dir_fd_calls(tmp_path, monkeypatch, case):
    said = {}
    for dir_fd_calls in (True, False):
        monkeypatch.setattr(outfs, "DIR_FD_CALLS", dir_fd_calls)
        d = tmp_path / str(dir_fd_calls)
        d.mkdir()
        (tmp_path / f"good-{dir_fd_calls}.db").write_bytes(b"SQLite format 3\0")
        for name, build in case.files.items():
            build(d / name, tmp_path / f"good-{dir_fd_calls}.db")
        call = _policy(case, d)
        assert call is not None
        before = _tree(d)
        with pytest.raises(OutputError) as err:
            call()
        line = str(err.value)
        assert "\n" not in line and err.value.status == case.exit
        assert case.says.replace("{d}", str(d)) in line
        assert _tree(d) == before  # every file, link and folder as it was; nothing new
        said[dir_fd_calls] = line.replace(str(d), "{d}")
    assert said[True] == said[False]


@pytest.mark.parametrize("dir_fd_calls", [True, False])
def test_a_forged_marker_entry_outside_the_folder_removes_nothing_there(tmp_path, monkeypatch, dir_fd_calls):
    """A marker listing ``../victim.txt`` with its hash: ``--force`` never reaches out of the folder (both paths)."""
    monkeypatch.setattr(outfs, "DIR_FD_CALLS", dir_fd_calls)
    (tmp_path / "victim.txt").write_text("precious")
    out = tmp_path / "o"
    _write(out, {"a.csv": "1"})
    marker = json.loads((out / MARKER).read_text())
    marker["files"]["../victim.txt"] = hashlib.sha256(b"precious").hexdigest()
    (out / MARKER).write_text(json.dumps(marker))
    _write(out, {"a.csv": "2"}, force=True)
    assert (tmp_path / "victim.txt").read_text() == "precious" and (out / "a.csv").read_text() == "2"
