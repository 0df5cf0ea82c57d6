"""The simulated pool of ``power --simulated``: simulated once, kept beside the output, reused only when it is sound.

A pool is an ordinary study database, ``DIR/pool-N-seedS.db``, run by the
headless study runner (``simulate``, given by the caller: ``haptic-study power``
passes :func:`study_app.headless.run_study`, the paper's protocol, participants
in parallel on the usable cores).  Beside it,
``pool-N-seedS.db.json`` records what it is: pool size, study seed, the
protocol's identity (SHA-256 of its JSON), the software that simulated it and
the simulated participant model's version (``participant_model``, given by the
caller: :data:`pipeline.sim.participant_params.MODEL_VERSION`, which changes whenever
the model's behaviour does, while the software's version may not), whether the
simulation finished, and then the pool's SHA-256.

Reuse is trusted only when that record says so:

* a complete pool whose parameters match and whose bytes still hash to the
  recorded SHA-256 is opened read-only and reused;
* a pool whose record says another size, seed, protocol, software or participant
  model (a record from before the model had a version says none), or whose
  hash differs (the file changed since), or a pool file with no record, is
  refused in one line: it is never used silently, and never deleted;
* a pool whose simulation was interrupted (Ctrl-C, a kill, a failed worker;
  its record says ``complete: false``) is never used as it is: the next call
  completes it (``continue_study``), keeping what was simulated.  Participants
  not yet started then run exactly as in an uninterrupted pool; a participant
  whose session was cut is resumed as the study runner resumes any session
  (the cut trial is kept as aborted and run again), so that participant's
  numbers differ from an uninterrupted pool's -- another draw of the same
  simulated person.  The record lists such participants
  (``resumed_participants``);
* a larger complete pool of the same seed, protocol and software serves a
  smaller request as its first N participants: participant k of a simulated
  study derives from the study seed and k alone, not from the study's size
  (tests/analysis/test_power_pool.py checks that), so the first N
  participants of a pool of M are the pool of N -- unless one of them was
  resumed after an interruption, in which case the pool of N is simulated.

Before simulating, the free disk space is checked against
:data:`POOL_MB_PER_PARTICIPANT` per participant still to simulate.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from analysis.reading.errors import AnalysisError
from foundation.outdir import ensure_output_folder
from foundation.outfs import close_folder, open_folder, os_error_line, write_bytes_at
from foundation.outmarker import sha256_file
from protocol.storage import StorageError, StudyDatabase, StudyReader

__all__ = ["POOL_MB_PER_PARTICIPANT", "PoolError", "SimulatedPool", "is_pool_file", "pool_name", "pool_parameters",
           "simulated_pool"]

#: Size of a pool database per simulated participant (the paper's protocol, training included), measured:
#: pool-200-seed0.db takes 1,995.7 MB (a study of 2 participants, seed 123, 18.9 MB).  The disk check asks for
#: this plus a quarter (WAL, growth).
POOL_MB_PER_PARTICIPANT = 10.0
_MARGIN = 1.25
_POOL_RE = re.compile(r"pool-(\d+)-seed(\d+)\.db")
_POOL_FILE_RE = re.compile(r"pool-\d+-seed\d+\.db(\.json|-wal|-shm|-journal)?")
_KIND = "haptic-study simulated pool"


class PoolError(AnalysisError):
    """A simulated pool cannot be used or made; the message says which file and why."""


def is_pool_file(name: str) -> bool:
    """Whether a file of the output folder (relative path) belongs to a simulated pool: never replaced or deleted."""
    return _POOL_FILE_RE.fullmatch(name) is not None


def pool_name(participants: int, seed: int) -> str:
    """The pool's file name."""
    return f"pool-{participants}-seed{seed}.db"


def pool_parameters(participants: int, seed: int, protocol: Any, participant_model: str) -> dict[str, Any]:
    """What a pool's record must say for it to serve a request (besides being complete and unchanged)."""
    from foundation.version import software_version

    return {"kind": _KIND, "participants": int(participants), "seed": int(seed),
            "protocol_sha256": hashlib.sha256(protocol.to_json().encode("utf-8")).hexdigest(),
            "protocol_name": getattr(protocol, "name", ""), "software_version": software_version(),
            "participant_model": participant_model}


@dataclass(frozen=True, slots=True)
class SimulatedPool:
    """A pool ready to be read.

    Attributes
    ----------
    path
        The pool database.
    participants
        Participant codes to use (the first N of a larger pool, or all).
    status
        ``"simulated"``, ``"resumed"`` (an interrupted simulation completed),
        ``"reused"`` or ``"reused-larger"`` (the first N of a larger pool).
    sha256
        The pool's hash, as verified or recorded.
    """

    path: Path
    participants: tuple[str, ...]
    status: str
    sha256: str


def _record_path(db: Path) -> Path:
    return db.with_name(db.name + ".json")


def _read_record(db: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(_record_path(db).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _write_record(db: Path, record: dict[str, Any]) -> None:
    """Write the pool's record beside it atomically (the output policy's write: fsynced, never through a link)."""
    path = _record_path(db)
    try:
        fd = open_folder(str(path.parent), follow=True)
        try:
            write_bytes_at(fd, path.name, json.dumps(record, indent=1, sort_keys=True).encode("utf-8"))
        finally:
            close_folder(fd)
    except OSError as exc:
        raise PoolError(os_error_line(exc, path, "cannot write the pool's record", written=True)) from None


def _mismatch(record: dict[str, Any], wanted: dict[str, Any], *, size: bool = True) -> str | None:
    """The first recorded parameter that differs from the request, in words (None: all match)."""
    for key, value in wanted.items():
        if key == "participants" and not size:
            continue
        if record.get(key) != value:
            return f"{key} {record.get(key)!r}, not {value!r}"
    return None


def _check_disk(folder: Path, participants_left: int) -> None:
    need_mb = participants_left * POOL_MB_PER_PARTICIPANT * _MARGIN
    free_mb = shutil.disk_usage(folder).free / 1e6
    if free_mb < need_mb:
        raise PoolError(f"--pool: simulating {participants_left} participants needs about {need_mb:,.0f} MB in "
                        f"{folder}, {free_mb:,.0f} MB are free there; free space or choose a smaller --pool")


def _simulated_codes(db: Path) -> int:
    """Participants with a finished experiment session in a (partial) pool, read-only (0 when it cannot be read)."""
    try:
        with StudyReader(db, check=False) as reader:
            return len({s.participant_id for s in reader.sessions()
                        if s.kind == "experiment" and s.status == "completed"})
    except (StorageError, sqlite3.Error):
        return 0


def _cut_participants(db: Path) -> list[str]:
    """Participants with a session that did not complete (an interrupted simulation), read-only."""
    try:
        with StudyReader(db, check=False) as reader:
            codes = {s.code for s in reader.sessions() if s.status != "completed"}
    except (StorageError, sqlite3.Error) as exc:
        raise PoolError(f"{db}: cannot read the interrupted pool ({exc}); it is not used (nor deleted)") from None
    return sorted(codes)


def _verified(db: Path, record: dict[str, Any]) -> str:
    """The pool's hash, checked against its record (refused if the file changed since)."""
    digest = sha256_file(db)
    if digest != record.get("sha256"):
        raise PoolError(f"{db}: its SHA-256 is not the one recorded in {_record_path(db).name} when it was "
                        "simulated (the file changed since); it is not used: move it away or choose another --out")
    return digest


def _larger_pool(folder: Path, participants: int, seed: int, wanted: dict[str, Any]) -> Path | None:
    """The smallest complete pool of more participants with the same seed, protocol and software, if any."""
    found = []
    for p in folder.glob("pool-*-seed*.db"):
        m = _POOL_RE.fullmatch(p.name)
        if m is None or int(m.group(2)) != seed or int(m.group(1)) <= participants:
            continue
        record = _read_record(p)
        if (record is not None and record.get("complete") is True and int(record.get("participants", -1)) ==
                int(m.group(1)) and _mismatch(record, wanted, size=False) is None
                and all(int(code[1:]) > participants for code in record.get("resumed_participants", []))):
            found.append((int(m.group(1)), p))
    return min(found)[1] if found else None


def _reusable(
    out: Path, db: Path, record: dict[str, Any] | None, wanted: dict[str, Any], participants: int, seed: int,
    codes: tuple[str, ...],
) -> SimulatedPool | None:
    """A sound complete pool to reuse (this one, or a larger one of the same parameters), or None to simulate.

    Raises :class:`PoolError` for a pool file without a record, or recorded with other parameters.
    """
    if db.exists() and record is None:
        raise PoolError(f"{db}: no readable record {_record_path(db).name} beside it, so nothing says how it was "
                        "made; it is not used (nor deleted): move it away or choose another --out")
    if record is not None:
        bad = _mismatch(record, wanted)
        if bad is not None:
            raise PoolError(f"{db}: recorded with {bad}; it is not used (nor deleted): move it away or choose "
                            "another --out")
        if record.get("complete") is True:
            return SimulatedPool(db, codes, "reused", _verified(db, record))
    elif out.is_dir():
        larger = _larger_pool(out, participants, seed, wanted)
        if larger is not None:
            return SimulatedPool(larger, codes, "reused-larger", _verified(larger, _read_record(larger) or {}))
    return None


def simulated_pool(
    out_dir: str | os.PathLike[str],
    participants: int,
    seed: int,
    *,
    simulate: Callable[..., Any],
    participant_model: str,
    protocol: Any = None,
    on_progress: Callable[..., None] | None = None,
    jobs: int | None = None,
) -> SimulatedPool:
    """Simulate a pool of participants from the calibrated population, or reuse a sound one (see the module).

    Parameters
    ----------
    out_dir
        Folder that keeps the pool (created if missing; its parent must exist).
    participants, seed
        Pool size and study seed.
    simulate
        The headless study runner, called as ``run_study(db_path, participants=,
        seed=, protocol=, on_progress=, jobs=, continue_study=)``; it raises
        :class:`protocol.storage.StorageError`, :class:`RuntimeError` or
        :class:`ValueError` when the simulation fails (the study floor sits above
        analysis, so it is passed in, not imported).
    participant_model
        The version of the participant model ``simulate`` simulates (recorded; a pool of another is not reused).
    protocol
        The study protocol (default: :func:`protocol.study.config.default_protocol`, the paper's).
    on_progress
        Progress callback of ``simulate``.
    jobs
        Worker processes (default: the usable cores).

    Returns
    -------
    SimulatedPool

    Raises
    ------
    PoolError
        A pool file whose record is missing or does not match, a pool that
        changed since it was simulated, too little free disk, or a failed
        simulation; one line, and no pool file is deleted.
    """
    from protocol.runner.session_setup import participant_code
    from protocol.storage import StorageError
    from protocol.study.config import default_protocol

    if protocol is None:
        protocol = default_protocol()
    out = Path(out_dir)
    wanted = pool_parameters(participants, seed, protocol, participant_model)
    codes = tuple(participant_code(k) for k in range(1, participants + 1))
    db = out / pool_name(participants, seed)
    record = _read_record(db) if db.exists() else None
    reused = _reusable(out, db, record, wanted, participants, seed, codes)
    if reused is not None:
        return reused

    if not out.exists() and not out.resolve().parent.is_dir():
        raise PoolError(f"--out {out}: the folder {out.resolve().parent} does not exist")
    resuming = db.exists()
    _check_disk(out if out.exists() else out.resolve().parent,
                participants - (_simulated_codes(db) if resuming else 0))
    ensure_output_folder(out)  # owner-only, as the policy makes every output folder
    resumed = sorted(set((record or {}).get("resumed_participants", [])) | set(_cut_participants(db) if resuming
                                                                               else []))
    _write_record(db, {**wanted, "complete": False, "resumed_participants": resumed})  # first: an interrupted
    # simulation is known as such
    try:
        simulate(str(db), participants=participants, seed=seed, protocol=protocol, on_progress=on_progress,
                 jobs=jobs, continue_study=resuming)
    except (StorageError, RuntimeError, ValueError) as exc:
        raise PoolError(f"{db}: the simulation failed ({exc}); the next call resumes it") from None
    return SimulatedPool(db, codes, "resumed" if resuming else "simulated", _seal(db, wanted, resumed))


def _seal(db: Path, wanted: dict[str, Any], resumed: list[Any]) -> str:
    """Seal a pool the simulation just completed and record it complete with its SHA-256 (returned)."""
    finished = StudyDatabase(db, check=False)  # just written by the simulation
    try:
        finished.seal()  # its readers (every later power request) leave no -wal/-shm beside it
    finally:
        finished.close()
    digest = sha256_file(db)
    _write_record(db, {**wanted, "complete": True, "sha256": digest, "bytes": db.stat().st_size,
                       "resumed_participants": resumed})
    return digest
