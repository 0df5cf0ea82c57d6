"""A sweep on a Dask cluster: the same cells to the last digit, a worker killed mid-run included; bad addresses.

One local cluster of two worker processes (each with a nanny that restarts it) serves the module; a participant
of the short protocol below takes a fraction of a second, so the sweep is small and the kill lands while tasks run.
"""

from __future__ import annotations

import os
import signal
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest
from cli_subprocess import TWO_GROUPS, tiny_protocol

from analysis.planning.sweep import CACHE_FILE
from pipeline.force.pipeline_settings import paper_settings
from protocol.study.config import protocol_from_dict
from study_app.cli.main import main
from study_app.headless import fanout
from study_app.headless.cluster_study import SCRATCH_PREFIX
from study_app.headless.sweep_run import run_sweep

distributed = pytest.importorskip("distributed")

T = TypeVar("T")



@pytest.fixture(scope="module")
def short_protocol():
    import tomllib

    # one target, both modes, 2 trials per cell, no training: a participant takes a fraction of a second
    return protocol_from_dict(tomllib.loads(tiny_protocol("short", 2.0, pause_s=0.05)), "short.toml")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as c:
        yield c


def _grid() -> list[dict[str, float]]:
    return [{**paper_settings(), "filter_window": w} for w in (1, 10)]


def _kill_a_busy_worker(client, killed: list[str], stop: threading.Event) -> None:
    """Kill (SIGKILL) the process of the first worker seen running a task: as a machine lost mid-run."""
    while not stop.is_set() and not killed:
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(busy[0])
            return
        time.sleep(0.005)  # polling a real cluster's state (no virtual clock exists across processes)


def _with_a_worker_killed(cluster, run: Callable[[Any], T]) -> tuple[T, list[str]]:
    """``run(client)`` on the cluster while a thread kills the first worker seen running a task; its result and the
    workers killed."""
    with distributed.Client(cluster, set_as_default=False) as client:
        killed: list[str] = []
        stop = threading.Event()
        killer = threading.Thread(target=_kill_a_busy_worker, args=(client, killed, stop), daemon=True)
        killer.start()
        try:
            return run(client), killed
        finally:
            stop.set()
            killer.join(5.0)


def test_a_sweep_on_a_cluster_with_a_worker_killed_mid_run_equals_the_local_one(tmp_path: Path, short_protocol,
                                                                                cluster) -> None:
    (tmp_path / "a").mkdir()
    local = run_sweep(_grid(), studies=1, participants=3, seed=5, cache=tmp_path / "a" / CACHE_FILE,
                      protocol=short_protocol)
    (tmp_path / "b").mkdir()
    remote, killed = _with_a_worker_killed(cluster, lambda client: run_sweep(
        _grid(), studies=1, participants=3, seed=5, cache=tmp_path / "b" / CACHE_FILE, protocol=short_protocol,
        client=client))
    assert killed, "no worker was seen running a task"
    # every participant of every cell, each value to the last bit, in the same order
    assert [(c.settings, c.study, c.rows) for c in remote] == [(c.settings, c.study, c.rows) for c in local]
    assert len(remote) == 2 and all(len(c.rows) == 3 * 4 for c in remote)


@pytest.mark.parametrize("address", ["localhost:8786", "tcp://", "tcp://a b:1", "http://x:8786"])
def test_a_malformed_scheduler_address_is_refused_in_one_line_before_any_work(tmp_path: Path, address, capsys
                                                                              ) -> None:
    out = tmp_path / "sweep"
    rc = main(["sweep", "--set", "filter_window=1,10", "--scheduler", address, "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert err[0].startswith("haptic-study: error: --scheduler: ") and "tcp://HOST:PORT" in err[0]
    assert not out.exists()


def test_the_environment_variable_names_the_scheduler_and_is_checked_too(monkeypatch) -> None:
    monkeypatch.setenv(fanout.SCHEDULER_ENV, "tcp://10.0.0.5:8786")
    assert fanout.scheduler_address(None) == "tcp://10.0.0.5:8786"
    assert fanout.scheduler_address("tcp://h:1") == "tcp://h:1"  # the option wins
    monkeypatch.setenv(fanout.SCHEDULER_ENV, "nonsense")
    with pytest.raises(fanout.InputRefused, match=f"^{fanout.SCHEDULER_ENV}: 'nonsense'"):
        fanout.scheduler_address(None)
    monkeypatch.delenv(fanout.SCHEDULER_ENV)
    assert fanout.scheduler_address(None) is None


def test_a_scheduler_nobody_answers_at_is_refused_before_the_folder_is_made(tmp_path: Path, monkeypatch, capsys
                                                                            ) -> None:
    monkeypatch.setattr(fanout, "CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "sweep"
    rc = main(["sweep", "--set", "filter_window=1,10", "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no Dask scheduler answered at tcp://127.0.0.1:9" in err[0]
    assert not out.exists()


def _rig_kernels_cached_where(dask_worker) -> tuple[str, list[str]]:
    """On a worker: build a simulated rig; where numba caches, and the cache files there."""
    import numba

    from pipeline.sim.rig import SimRig

    SimRig()
    folder = numba.config.CACHE_DIR
    return dask_worker.local_directory, sorted(p.name for p in Path(folder).rglob("*.nbi"))


def test_the_workers_run_this_software(cluster) -> None:
    client = fanout.connect(cluster.scheduler_address)
    try:
        assert set(client.run(fanout.software_identity).values()) == {fanout.software_identity()}
    finally:
        client.close()


def test_the_workers_cache_the_compiled_rig_in_their_own_folders(cluster) -> None:
    """Once tasks have run on them (after a worker killed mid-run, in this module), the workers cache the simulated
    rig's compiled code in Dask's scratch folder, not in the installation."""
    client = fanout.connect(cluster.scheduler_address)
    try:
        fanout.run_tasks(abs, [-1, -2], lambda _: None, client=client)
        where = client.run(fanout.kernels_in_scratch)
        seen = client.run(_rig_kernels_cached_where)
        assert len(seen) == 2
        for worker, (local, files) in seen.items():
            assert where[worker] == os.path.join(os.path.dirname(os.path.abspath(local)), "haptic-study-kernels")
            assert any(f.startswith("rig.") for f in files) and any(f.startswith("sensor.") for f in files), files
    finally:
        client.close()


def _same_study():
    """scripts/same_study.py: a study's tables compared row for row, its sessions matched by participant and kind."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("same_study", Path(__file__).resolve().parents[1] / "scripts"
                                                  / "same_study.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_study_run_on_a_cluster_with_a_worker_killed_is_the_local_one_row_for_row(tmp_path: Path, short_protocol,
                                                                                     cluster, capsys) -> None:
    """Issue 47: `run --scheduler`: each participant into a worker's scratch database, merged here as it comes back;
    a worker lost mid-run is retried.  The merged study equals the one run here (session ids aside) and `check`
    verifies every block's checksum, bound anew to its merged session."""
    from study_app.headless import run_study

    here, there = tmp_path / "here.db", tmp_path / "there.db"
    scratch_before = set(Path(tempfile.gettempdir()).glob(f"{SCRATCH_PREFIX}*"))
    run_study(str(here), participants=3, seed=5, protocol=short_protocol, jobs=1)
    progress, _ = _with_a_worker_killed(cluster, lambda client: run_study(
        str(there), participants=3, seed=5, protocol=short_protocol, client=client))
    assert sorted(progress.sessions) == [1, 2, 3] and progress.study_trials_done == 3 * 4
    assert _same_study().compare(str(here), str(there))
    assert main(["check", "--db", str(there)]) == 0
    assert "No problem found." in capsys.readouterr().out
    # the workers wrote in their own Dask directories only, and removed what they wrote (a killed one: Dask will)
    assert set(Path(tempfile.gettempdir()).glob(f"{SCRATCH_PREFIX}*")) <= scratch_before
    with distributed.Client(cluster, set_as_default=False) as client:
        dirs = client.run(lambda dask_worker: dask_worker.local_directory)
    assert not [p for d in dirs.values() for p in Path(d).glob(f"{SCRATCH_PREFIX}*")]


@pytest.mark.parametrize("given,why", [(["--clock", "real"], "--clock real"), (["--jobs", "2"], "--jobs"),
                                       (["--inject-fault", "kill@P01:1"], "--inject-fault")])
def test_a_run_on_a_cluster_refuses_what_it_cannot_do_before_any_work(tmp_path: Path, capsys, given, why) -> None:
    db = tmp_path / "s.db"
    rc = main(["run", "--participants", "2", "--db", str(db), "--scheduler", "tcp://127.0.0.1:9", *given])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and f"--scheduler = tcp://127.0.0.1:9: {why} does not apply" in err[0], err
    assert not db.exists()


def test_a_simulated_power_pool_on_a_cluster_is_the_local_one(tmp_path: Path, short_protocol, cluster) -> None:
    """Issue 47: `power --simulated --scheduler`: the pool's participants run on the cluster, the pool is the same."""
    import functools

    from analysis.planning.power_pool import simulated_pool
    from study_app.headless import run_study
    from study_app.headless.sim_trials import MODEL_VERSION

    here = simulated_pool(tmp_path / "here", 4, 7, simulate=run_study, participant_model=MODEL_VERSION,
                          protocol=short_protocol, jobs=1)
    with distributed.Client(cluster, set_as_default=False) as client:
        there = simulated_pool(tmp_path / "there", 4, 7, simulate=functools.partial(run_study, client=client),
                               participant_model=MODEL_VERSION, protocol=short_protocol)
    assert (here.status, there.status) == ("simulated", "simulated") and here.participants == there.participants
    assert _same_study().compare(str(here.path), str(there.path))


def test_power_runs_on_a_cluster_only_what_it_simulates(tmp_path: Path, capsys) -> None:
    rc = main(["power", "--db", str(tmp_path / "pilot.db"), "--scheduler", "tcp://127.0.0.1:9", "--out",
               str(tmp_path / "p")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err == ["haptic-study: error: --scheduler = tcp://127.0.0.1:9: only with --simulated (a pilot "
                               "study is read here)"]


def test_a_two_group_power_on_a_cluster_is_the_local_one(tmp_path: Path, cluster, capsys) -> None:
    """Issue 44: `power --groups --simulated --scheduler`: the two-group pool's participants (novices and experienced
    surgeons, placed in turn) run on the cluster; the pool, its groups and the planned power equal the local run's."""
    proto = tmp_path / "groups.toml"
    proto.write_text(tiny_protocol("two groups", 2.0, pause_s=0.05) + TWO_GROUPS, encoding="utf-8")
    common = ["power", "--groups", "--simulated", "--protocol", str(proto), "--pool", "6", "--seed", "3",
              "--n", "3,4", "--resamples", "40"]
    assert main([*common, "--out", str(tmp_path / "here")]) == 0
    here = capsys.readouterr().out
    assert main([*common, "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "there")]) == 0
    there, err = capsys.readouterr()
    assert "merged" in err  # the progress bar's label: each participant came back from the cluster
    assert "surgeon against novice (group)" in here
    assert (tmp_path / "here" / "group_power.csv").read_bytes() == (tmp_path / "there" / "group_power.csv").read_bytes()
    assert (tmp_path / "here" / "group_power.txt").read_text() == (tmp_path / "there" / "group_power.txt").read_text()
    [pool_here] = (tmp_path / "here").glob("pool-*.db")
    [pool_there] = (tmp_path / "there").glob("pool-*.db")
    assert _same_study().compare(str(pool_here), str(pool_there))  # the covariates table included
    assert there.splitlines()[-1] == f"Written in {tmp_path / 'there'}/: group_power.csv, group_power.txt"
