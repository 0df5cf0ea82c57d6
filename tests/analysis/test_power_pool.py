"""The simulated pool of ``power --simulated``: recorded, verified, reused, resumed (analysis.planning.power_pool).

The pools here run the paper's protocol cut to one trial per cell and no
training (four trials a participant): the same runner, a fraction of the time.
"""

from __future__ import annotations

import dataclasses
import json
from collections import namedtuple

import numpy as np
import pytest

import analysis.planning.power_pool as power_pool
from analysis.planning.paired_pool import load_pool
from analysis.planning.power_pool import PoolError, is_pool_file
from analysis.planning.power_pool import simulated_pool as _simulated_pool
from protocol.study.config import default_protocol
from study_app.headless import run_study
from study_app.headless.sim_trials import MODEL_VERSION

SEED = 5


def simulated_pool(*args, **kwargs):
    """The call ``haptic-study power`` makes: pools of the participant model the runner simulates."""
    return _simulated_pool(*args, participant_model=MODEL_VERSION, **kwargs)


@pytest.fixture(scope="module")
def short():
    paper = default_protocol()
    # short pauses too: the 2 s pause between trials only adds ticks to simulate (0.1 s is above the ramp-out)
    return dataclasses.replace(paper, trials_per_cell=1, training=dataclasses.replace(paper.training, enabled=False),
                               trial=dataclasses.replace(paper.trial, pause_s=0.1))


@pytest.fixture(scope="module")
def pools(tmp_path_factory, short):
    """A pool of 3 and a pool of 2, same seed, each simulated once (in its own folder)."""
    a, b = tmp_path_factory.mktemp("three"), tmp_path_factory.mktemp("two")
    three = simulated_pool(a, 3, SEED, simulate=run_study, protocol=short, jobs=1)
    two = simulated_pool(b, 2, SEED, simulate=run_study, protocol=short, jobs=1)
    return three, two


def _values(path, participants=None):
    pool = load_pool([str(path)], participants=participants, workers=1)
    return pool.participants, pool.off, pool.on


def _same(a, b):
    assert a[0] == b[0]
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[2], b[2])


def _bytes(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_a_pool_is_recorded_with_its_parameters_and_hash(pools, short):
    three, _ = pools
    assert three.status == "simulated" and three.participants == ("P01", "P02", "P03")
    record = json.loads(three.path.with_name(three.path.name + ".json").read_text())
    assert record["complete"] is True and record["sha256"] == three.sha256 == power_pool.sha256_file(three.path)
    assert record["participants"] == 3 and record["seed"] == SEED
    assert record == {**power_pool.pool_parameters(3, SEED, short, MODEL_VERSION), "complete": True,
                      "sha256": three.sha256, "bytes": three.path.stat().st_size, "resumed_participants": []}
    assert record["participant_model"] == MODEL_VERSION
    assert is_pool_file(three.path.name) and is_pool_file(three.path.name + ".json")


def test_participant_k_is_the_same_whatever_the_study_size(pools):
    three, two = pools
    _same(_values(three.path, ("P01", "P02")), _values(two.path))


def test_a_complete_pool_is_reused_read_only(pools, short):
    three, _ = pools
    before = _bytes(three.path.parent)
    again = simulated_pool(three.path.parent, 3, SEED, simulate=run_study, protocol=short, jobs=1)
    assert again.status == "reused" and again.path == three.path and again.sha256 == three.sha256
    _values(again.path)
    assert _bytes(three.path.parent) == before  # reading it changed nothing, not even a WAL file


def test_a_larger_pool_serves_a_smaller_request_as_its_first_participants(pools, short, monkeypatch):
    three, two = pools
    served = simulated_pool(three.path.parent, 2, SEED, simulate=run_study, protocol=short, jobs=1)
    assert served.status == "reused-larger" and served.path == three.path and served.participants == ("P01", "P02")
    assert not (three.path.parent / "pool-2-seed5.db").exists()  # nothing simulated
    _same(_values(served.path, served.participants), _values(two.path))
    # another seed is another population: not served by it (it would be simulated; here the disk is "full")
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(power_pool.shutil, "disk_usage", lambda _: usage(0, 0, 0))
    with pytest.raises(PoolError, match="simulating 2 participants needs about"):
        simulated_pool(three.path.parent, 2, SEED + 1, simulate=run_study, protocol=short, jobs=1)


def test_a_changed_pool_is_refused_not_used(pools, short, tmp_path):
    three, _ = pools
    folder = tmp_path / "copy"
    folder.mkdir()
    for name, data in _bytes(three.path.parent).items():
        (folder / name).write_bytes(data)
    with (folder / three.path.name).open("ab") as f:
        f.write(b"\0")
    before = _bytes(folder)
    with pytest.raises(PoolError) as err:
        simulated_pool(folder, 3, SEED, simulate=run_study, protocol=short, jobs=1)
    assert str(err.value) == (f"{folder / three.path.name}: its SHA-256 is not the one recorded in "
                              f"{three.path.name}.json when it was simulated (the file changed since); it is not "
                              "used: move it away or choose another --out")
    assert _bytes(folder) == before


@pytest.mark.parametrize(("change", "message"), [
    (lambda r: r.update(seed=99), "recorded with seed 99, not 5"),
    (lambda r: r.update(protocol_sha256="0" * 64), "recorded with protocol_sha256 '000"),
    (lambda r: r.update(software_version="0.0.1"), "recorded with software_version '0.0.1'"),
    # a pool of another participant model, or from before the model had a version, is another model's prediction
    (lambda r: r.update(participant_model="1"), "recorded with participant_model '1'"),
    (lambda r: r.pop("participant_model"), "recorded with participant_model None"),
])
def test_a_pool_recorded_with_other_parameters_is_refused(pools, short, tmp_path, change, message):
    three, _ = pools
    folder = tmp_path / "copy"
    folder.mkdir()
    for name, data in _bytes(three.path.parent).items():
        (folder / name).write_bytes(data)
    record_path = folder / (three.path.name + ".json")
    record = json.loads(record_path.read_text())
    change(record)
    record_path.write_text(json.dumps(record))
    before = _bytes(folder)
    with pytest.raises(PoolError, match=message) as err:
        simulated_pool(folder, 3, SEED, simulate=run_study, protocol=short, jobs=1)
    assert "it is not used (nor deleted)" in str(err.value) and "\n" not in str(err.value)
    assert _bytes(folder) == before


def test_a_pool_without_record_is_refused(pools, short, tmp_path):
    three, _ = pools
    (tmp_path / three.path.name).write_bytes(three.path.read_bytes())
    with pytest.raises(PoolError, match=r"no readable record pool-3-seed5\.db\.json beside it"):
        simulated_pool(tmp_path, 3, SEED, simulate=run_study, protocol=short, jobs=1)


def test_too_little_disk_is_refused_before_anything_is_written(short, tmp_path, monkeypatch):
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(power_pool.shutil, "disk_usage", lambda _: usage(10**9, 10**9, 50 * 10**6))
    out = tmp_path / "plan"
    with pytest.raises(PoolError) as err:
        simulated_pool(out, 100, SEED, simulate=run_study, protocol=short, jobs=1)
    need = 100 * power_pool.POOL_MB_PER_PARTICIPANT * 1.25
    assert str(err.value) == (f"--pool: simulating 100 participants needs about {need:,.0f} MB in {tmp_path}, "
                              "50 MB are free there; free space or choose a smaller --pool")
    assert not out.exists()


def test_an_interrupted_simulation_is_completed_not_used_as_it_is(pools, short, tmp_path):
    three, _ = pools

    def interrupt(progress):
        if progress.participant >= 2:
            raise KeyboardInterrupt  # Ctrl-C while the second participant runs

    with pytest.raises(KeyboardInterrupt):
        simulated_pool(tmp_path, 3, SEED, simulate=run_study, protocol=short, jobs=1, on_progress=interrupt)
    record = json.loads((tmp_path / "pool-3-seed5.db.json").read_text())
    assert record["complete"] is False and "sha256" not in record
    # a request for fewer participants is not served by an unfinished pool
    with pytest.raises(KeyboardInterrupt):
        simulated_pool(tmp_path, 2, SEED, simulate=run_study, protocol=short, jobs=1, on_progress=interrupt)
    (tmp_path / "pool-2-seed5.db").unlink()
    (tmp_path / "pool-2-seed5.db.json").unlink()
    resumed = simulated_pool(tmp_path, 3, SEED, simulate=run_study, protocol=short, jobs=1)
    assert resumed.status == "resumed"
    record = json.loads((tmp_path / "pool-3-seed5.db.json").read_text())
    assert record["complete"] is True and record["resumed_participants"] == ["P02"]
    # what was simulated was kept: P01 as before; P03 not started, so as in an uninterrupted pool; P02's cut
    # session resumed (its cut trial kept as aborted and run again): complete, but another draw
    done = _values(resumed.path)
    ref = _values(three.path)
    for k in (0, 2):
        np.testing.assert_array_equal(done[1][..., k], ref[1][..., k])
        np.testing.assert_array_equal(done[2][..., k], ref[2][..., k])
    from analysis.reading.load import load_study

    trials = load_study([str(resumed.path)]).trials
    p02 = trials[trials["participant_code"] == "P02"]
    assert (p02["excluded"] == "").sum() == short.trials_per_participant
    assert (p02["excluded"] == "aborted trial").sum() == 1
    assert simulated_pool(tmp_path, 3, SEED, simulate=run_study, protocol=short, jobs=1).status == "reused"
    # the first 2 of this pool are not those of a pool of 2 (P02 was resumed): a pool of 2 is simulated instead
    wanted = [power_pool.pool_parameters(n, SEED, short, MODEL_VERSION) for n in (1, 2)]
    assert power_pool._larger_pool(tmp_path, 2, SEED, wanted[1]) is None
    assert power_pool._larger_pool(tmp_path, 1, SEED, wanted[0]) == resumed.path
