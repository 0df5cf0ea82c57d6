"""Limits that fit the machine (issue 22): a command whose memory grows with its arguments refuses, in one line and
before any work, a request the machine's available memory cannot hold (the machine's memory is stood in for)."""

from __future__ import annotations

import pytest

import foundation.resources
from foundation.resources import available_memory_bytes, memory_problem
from study_app.cli.main import main


def test_the_available_memory_is_read_from_the_machine():
    have = available_memory_bytes()
    assert have is None or 0 < have < 1 << 50
    assert memory_problem(1, "a byte", "") is None


@pytest.fixture
def small_machine(monkeypatch):
    monkeypatch.setattr(foundation.resources, "available_memory_bytes", lambda: 512 << 20)  # 512 MiB available


def test_sim_refuses_a_run_longer_than_the_memory_holds(small_machine, capsys):
    assert main(["sim", "--seconds", "86400"]) == 2
    err = capsys.readouterr().err
    assert err == ("haptic-study: error: sim --seconds 86400 needs about 12.9 GiB of memory; this machine has 512.0 "
                   "MiB available; simulate fewer seconds (the summary keeps every tick)\n")


def test_power_refuses_studies_larger_than_the_memory_holds(tmp_path, capsys, monkeypatch):
    import numpy as np

    from analysis.planning.paired_pool import PairedPool

    monkeypatch.setattr(foundation.resources, "available_memory_bytes", lambda: 8 << 20)  # 8 MiB available
    pool = PairedPool(tuple(f"P{i}" for i in range(6)), ("overall",), ("success_rate", "tct_s", "rmse_n", "max_ae_n"),
                      np.zeros((1, 4, 6)), np.ones((1, 4, 6)), "a pilot")
    # (the pilot is stood in for too, and checked)
    monkeypatch.setattr("analysis.planning.paired_pool.load_pool", lambda *a, **k: pool)
    monkeypatch.setattr("analysis.reading.inputs.check_databases", lambda paths, **k: list(map(str, paths)))
    (tmp_path / "pilot.db").write_bytes(b"")
    code = main(["power", "--db", str(tmp_path / "pilot.db"), "--out", str(tmp_path / "p"), "--n", "10000",
                 "--resamples", "1000000"])
    assert code == 2
    assert capsys.readouterr().err == (
        "haptic-study: error: power: resampling studies of up to 10000 participants needs about 17.8 MiB of memory; "
        "this machine has 8.0 MiB available; ask for smaller --n values (memory grows with n; --resamples costs "
        "time only)\n")
    assert not (tmp_path / "p").exists()
