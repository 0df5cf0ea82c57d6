"""A sweep on a Dask cluster: the same cells to the last digit, a worker killed mid-run included; bad addresses.

One local cluster of two worker processes (each with a nanny that restarts it) serves the module; a participant
of the short protocol below takes a fraction of a second, so the sweep is small and the kill lands while tasks run.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from analysis.planning.sweep import CACHE_FILE
from pipeline.force.pipeline_settings import paper_settings
from protocol.study.config import protocol_from_dict
from study_app.cli.main import main
from study_app.headless import fanout
from study_app.headless.sweep_run import run_sweep

distributed = pytest.importorskip("distributed")

SHORT = """name = "short"
[[targets]]
label = "GENTLE"
force_n = 0.6
[design]
modes = ["on", "off"]
trials_per_cell = 2
[trial]
max_trial_s = 2.0
pause_s = 0.05
[training]
enabled = false
"""


@pytest.fixture(scope="module")
def short_protocol():
    import tomllib

    return protocol_from_dict(tomllib.loads(SHORT), "short.toml")


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


def test_a_sweep_on_a_cluster_with_a_worker_killed_mid_run_equals_the_local_one(tmp_path: Path, short_protocol,
                                                                                cluster) -> None:
    (tmp_path / "a").mkdir()
    local = run_sweep(_grid(), studies=1, participants=3, seed=5, cache=tmp_path / "a" / CACHE_FILE,
                      protocol=short_protocol)
    (tmp_path / "b").mkdir()
    with distributed.Client(cluster, set_as_default=False) as client:
        killed: list[str] = []
        stop = threading.Event()
        killer = threading.Thread(target=_kill_a_busy_worker, args=(client, killed, stop), daemon=True)
        killer.start()
        try:
            remote = run_sweep(_grid(), studies=1, participants=3, seed=5, cache=tmp_path / "b" / CACHE_FILE,
                               protocol=short_protocol, client=client)
        finally:
            stop.set()
            killer.join(5.0)
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


def test_the_workers_run_this_software(cluster) -> None:
    client = fanout.connect(cluster.scheduler_address)
    try:
        assert set(client.run(fanout.software_identity).values()) == {fanout.software_identity()}
    finally:
        client.close()
