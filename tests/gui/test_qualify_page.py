"""Qualify from the window: the commissioning view's Qualify tab runs ``haptic-study qualify`` as a child process on
the hardware file's rig (here the loopback fakes: Net F/T, UR controller, the fake OpenHaptics under the real Touch
backend), shows each check's verdict as it comes, and the record is the one the command writes; the window's engine
lets the devices go before and is restarted after.  The model's reading of the command's lines is tested alone."""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backends"))

from fake_netft import FakeNetFT
from fake_rtde import FakeRtde

from pipeline.commissioning.qualification import CHECKS, record_path
from study_app.gui.qualify_page import QualifyPage
from study_app.models.qualify import QualifyModel

ROOT = Path(__file__).resolve().parents[2]
FAKE_OPENHAPTICS = ROOT / "tests" / "backends" / "fake_openhaptics"
FRAMES = "rot_tip_sensor = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nrot_haptic_base = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]\n"


def test_the_tab_runs_the_command_shows_each_verdict_and_the_record_is_the_commands(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PYTHONPATH", f"{FAKE_OPENHAPTICS}:{ROOT}")
    monkeypatch.setenv("FAKE_TOUCH_STATE", str(tmp_path / "touch.state"))
    monkeypatch.delenv("FAKE_TOUCH_KEEPS_FORCE", raising=False)
    calls: list[str] = []
    with FakeNetFT(rate_hz=1000.0, counts=(0, 0, 1_000_000, 0, 0, 0)) as netft, FakeRtde() as rtde:
        hw = tmp_path / "hardware.toml"
        hw.write_text(f'[sensor]\nhost = "127.0.0.1"\nport = {netft.udp_port}\nhttp_port = {netft.http_port}\n'
                      f'[robot]\nhost = "{rtde.host}"\nconnect_timeout_s = 2.0\n[haptic]\n[frames]\n{FRAMES}'
                      "[framework]\nf_max_n = 3.0\nf_scale_n = 7.0\n", encoding="utf-8")
        model = QualifyModel(str(hw))
        page = QualifyPage(model, lambda: calls.append("release"), lambda: calls.append("restore"), lambda: "",
                           lambda: "")
        qtbot.addWidget(page)
        page.seconds.setValue(1)
        page.run()
        assert calls == ["release"] and not page.run_button.isEnabled()
        qtbot.waitUntil(lambda: model.state != "running", timeout=150_000)
    assert calls == ["release", "restore"], model.lines
    assert model.state == "done", (model.error, model.lines)
    shown = {page.table.item(i, 0).text(): page.table.item(i, 1).text() for i in range(len(CHECKS))}
    record = json.loads(record_path(str(tmp_path / "calibration.json")).read_text(encoding="utf-8"))
    assert shown == {c["name"]: c["verdict"] for c in record["checks"]}
    assert shown["process-death"] == "PASS" and shown["thermal-budget"] == "PASS" and shown["latency"] == "PASS"
    assert model.record == record and str(record_path(str(tmp_path / "calibration.json"))) in page.summary.text()
    assert page.progress.value() == len(CHECKS) and page.run_button.isEnabled()


def test_the_model_reads_the_progress_and_a_refusal() -> None:
    model = QualifyModel("/lab/hardware.toml", python="py")
    assert model.command()[:6] == ["py", "-m", "study_app.cli", "qualify", "--hardware", "/lab/hardware.toml"]
    model.start("left", 5)
    assert model.command()[-4:] == ["--seconds", "5", "--arm", "left"]
    model.progress("qualify: process-death: running")
    assert model.rows()[0][1] == "running…" and model.rows()[1][1] == "waiting"
    model.progress("qualify: latency: timing the F/T sensor's answers")  # what it does, not a verdict
    assert model.done_checks == 0 and "timing the F/T sensor's answers" in model.summary()
    model.progress("qualify: process-death: PASS")
    assert model.done_checks == 1 and model.rows()[0][1] == "PASS"
    model.progress("/lab/hardware.toml has no such arm; its arms: right")
    model.finish(2, "")
    assert model.state == "failed" and "no such arm" in model.summary()
    assert "real rig" in QualifyModel(None).refusal("")
    assert QualifyModel("/x").refusal("not during a session") == "not during a session"


def test_the_window_has_the_tab_and_on_the_simulated_rig_says_why_it_cannot_run(qtbot, tmp_path):
    from conftest import SHORT_PROTOCOL, open_ready_window

    w = open_ready_window(qtbot, tmp_path, SHORT_PROTOCOL, speed=0.0)
    tabs = w.calibration_wizard.steps
    assert tabs.tabText(tabs.count() - 1) == "4 · Qualify" and tabs.widget(tabs.count() - 1) is w.qualify_page
    assert not w.qualify_page.run_button.isEnabled()
    assert "--rig real --hardware FILE" in w.qualify_page.run_button.toolTip()
