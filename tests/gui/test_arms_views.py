"""The window with a rig of several arms: the calibration window commissions the chosen arm, each arm's live force is
plotted (the task arm marked), and a task arm given second is put first as ``run --sim-arms`` does (models without a
window; the wiring offscreen)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.tick_record import TICK_DTYPE
from pipeline.runtime.ring import RingBuffer
from study_app.engine import messages as m
from study_app.models.app import AppModel
from study_app.models.arms import task_arm_first
from tests.gui.conftest import SHORT_PROTOCOL

TWO = m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                    arm_rings=(("left", "ring-left"), ("right", "ring-right")))
STEPS = [("TCP", False, "not on record"), ("payload", True, "0.650 kg"), ("frames", False, "not on record")]


def _protocol(tmp_path, task_arm: str) -> str:
    p = tmp_path / f"task_{task_arm}.toml"
    p.write_text(SHORT_PROTOCOL.replace("[design]\n", f"[design]\ntask_arm = \"{task_arm}\"\n"), encoding="utf-8")
    return str(p)


def test_the_calibration_steps_go_to_the_chosen_arm_and_each_arm_keeps_its_status() -> None:
    sent: list[object] = []
    a = AppModel(lambda c: sent.append(c) or True)
    a.apply(TWO)
    chain = a.commissioning
    assert chain.arms == ("left", "right") and chain.arm == "left" and chain.arm_title() == "arm left"
    a.apply(m.CalibrationStatus("sim", "simulated instrument", "", STEPS, "", "left"))
    a.apply(m.CalibrationStatus("sim", "simulated instrument", "", [("TCP", True, "tip …"), *STEPS[1:]], "", "right"))
    assert chain.status.arm == "left"
    a.steps.run_tcp()
    assert sent[-1] == m.CalibrateTcp("recommended", arm="left")
    a.apply(m.TcpCalibrationDone(True, "", "recommended", 8, {"tip_in_flange_m": [0, 0, 0.25]}))
    a.steps.select_arm("right")
    assert chain.arm == "right" and chain.status.arm == "right" and chain.status.steps[0][1]
    assert chain.tcp_result is None and chain.tcp_state == "idle"  # the left arm's result is not the right's
    a.steps.run_tcp()
    a.steps.calibrate()
    a.steps.check_frames()
    assert sent[-3:] == [m.CalibrateTcp("recommended", arm="right"), m.Calibrate("recommended", arm="right"),
                         m.CheckFrames(arm="right")]
    # while a step runs the arm stays: the results that come belong to it
    a.steps.select_arm("left")
    assert chain.arm == "right" and a.notices.notice.text.startswith("Calibration: finish the step under way first")
    with pytest.raises(ValueError, match="arm = 'centre': allowed values are left, right"):
        chain.select_arm("centre")


def test_the_real_gate_line_names_the_arm_whose_chain_is_missing() -> None:
    a = AppModel(lambda c: True)
    turned = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # the left sensor mounted 90° about z
    a.apply(m.EngineReady("", "real", "real", {}, float("nan"), (float("nan"),) * 3, "participant",
                          arm_rings=(("right", "r"), ("left", "l")),
                          arm_mounts=(("right", (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)), ("left", turned))))
    done = [(n, True, "on record") for n, _, _ in STEPS]
    a.apply(m.CalibrationStatus("real", "grasper", "/lab/right.json", done, "", "right"))
    a.apply(m.CalibrationStatus("real", "grasper", "/lab/left.json", STEPS, "no TCP calibration on record", "left"))
    assert a.actions.calibration_missing() == "arm left: no TCP calibration on record"
    assert a.commissioning.gate_text() == ("Arm right's chain is on record (/lab/right.json); a session cannot start "
                                           "yet: arm left: no TCP calibration on record.")
    a.real_calibration.begin("quick")
    right_target = a.real_calibration.target_tcp(a.real_calibration.current)
    a.steps.select_arm("left")
    assert a.commissioning.gate_text() == ("A session cannot start yet: arm left: no TCP calibration on record.")
    # the pose targets as the left arm's pendant shows them: its own sensor mount
    assert a.real_calibration.rot_tip_sensor == turned and a.real_calibration.index == 0
    assert a.real_calibration.target_tcp(a.real_calibration.current) != right_target
    assert a.commissioning.arms_overview() == [("right", "✔ TCP ✔ payload ✔ frames"),
                                               ("left", "✘ TCP ✔ payload ✘ frames")]


def test_the_task_arm_goes_first_as_run_puts_it(tmp_path) -> None:
    left = _protocol(tmp_path, "left")
    assert task_arm_first(("right", "left"), "sim", left) == ("left", "right")
    assert task_arm_first(("left", "right"), "sim", left) == ()  # already first
    assert task_arm_first(("right", "left"), "real", left) == ()  # the real rig's order is its hardware file's
    assert task_arm_first(("right",), "sim", left) == ()
    assert task_arm_first(("right", "left"), "sim", _protocol(tmp_path, "centre")) == ()  # the engine refuses it
    assert task_arm_first(("left", "right"), "sim", "") == ("right", "left")  # the paper's protocol: right


def test_a_start_whose_task_arm_is_not_first_restarts_the_rig_with_it_first_then_starts(tmp_path) -> None:
    sent: list[object] = []
    restarts: list[tuple[str, ...]] = []
    a = AppModel(lambda c: sent.append(c) or True)
    a.engine.restarter = lambda arms=(): restarts.append(arms)
    ready = m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                          arm_rings=(("right", "r"), ("left", "l")))
    a.apply(ready)
    a.setup.update(db_path=str(tmp_path / "s.db"), code="P01", protocol_path=_protocol(tmp_path, "left"))
    assert a.control.start()
    assert restarts == [("left", "right")] and not any(isinstance(c, m.StartSession) for c in sent)
    assert "restarting the simulated rig with arm left first" in a.notices.notice.text
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                          arm_rings=(("left", "l"), ("right", "r"))))
    assert isinstance(sent[-1], m.StartSession) and sent[-1].code == "P01"
    n = len(sent)
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot"))
    assert len(sent) == n  # sent once


def test_an_interrupted_session_resumes_on_its_arms_in_their_order(tmp_path) -> None:
    """Launched as --sim-arms left,right, a session that ran with right first is resumed after a restart of the
    simulated rig with right first; a session of other arms goes to the engine, which refuses it in one line."""
    sent: list[object] = []
    restarts: list[tuple[str, ...]] = []
    a = AppModel(lambda c: sent.append(c) or True)
    a.engine.restarter = lambda arms=(): restarts.append(arms)
    a.apply(TWO)
    a.setup.update(db_path=str(tmp_path / "s.db"))
    entry = {"session_id": 4, "code": "P01", "kind": "experiment", "started_at": "2026-01-01T10:00:00Z",
             "trials_planned": 20, "trials_done": 3, "trials_aborted": 0, "trials_total": 20, "reruns_run": 0}
    a.apply(m.SessionsListed(str(tmp_path / "s.db"), [{**entry, "arms": ["right", "left"]},
                                                      {**entry, "session_id": 5, "arms": ["right", "centre"]}]))
    a.control.resume_session(4)
    assert restarts == [("right", "left")] and sent == []
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                          arm_rings=(("right", "r"), ("left", "l"))))
    assert sent == [m.ResumeSession(str(tmp_path / "s.db"), 4)]
    a.control.resume_session(5)
    assert restarts == [("right", "left")] and sent[-1] == m.ResumeSession(str(tmp_path / "s.db"), 5)


def test_each_arms_force_is_pulled_from_its_own_ring() -> None:
    task, other = RingBuffer.create(TICK_DTYPE, 5000), RingBuffer.create(TICK_DTYPE, 5000)
    a = AppModel(lambda c: True)
    a.attach_ring(task, "left", {"right": other})
    for k in range(100):
        for ring, f in ((task, 0.5), (other, 2.0)):
            rec = np.zeros(1, dtype=TICK_DTYPE)[0]
            rec["t_s"], rec["force_n"] = k * 1e-3, f
            ring.write(rec)
    assert a.tick() == 100
    assert a.plots.peak(("force_n",)) == 0.5 and a.plots.arms["right"].peak(("force_n",)) == 2.0
    a.plots.reset()
    assert a.plots.arms == {} and a.plots.task_arm == ""


def test_the_force_plot_has_a_curve_per_arm_and_marks_the_task_arm(qtbot) -> None:
    from study_app.gui.force_plots import QtForcePlots
    from study_app.models.plots import PlotModel
    from study_app.models.session import SessionModel

    task, other = RingBuffer.create(TICK_DTYPE, 5000), RingBuffer.create(TICK_DTYPE, 5000)
    plots = PlotModel()
    view = QtForcePlots(plots, SessionModel())
    qtbot.addWidget(view)
    assert list(view.arm_curves) == [] and "arm" not in view.legend.text()  # one arm: as before
    assert view.legend_entries() == ["task force |F| (compensated, filtered)", "rendered on the haptic device",
                                     "target band", "cue"]
    plots.attach(task)
    plots.attach_arms("left", {"right": other})
    for k in range(50):
        for ring, f in ((task, 0.5), (other, 9.0)):
            rec = np.zeros(1, dtype=TICK_DTYPE)[0]
            rec["t_s"], rec["force_n"] = k * 1e-3, f
            ring.write(rec)
    plots.pull()
    view.refresh()
    assert list(view.arm_curves) == ["right"]
    assert view.legend_entries()[4:] == ["left (task force)", "right"]
    assert "each arm's |F|:" in view.legend.text() and "left (task force)" in view.legend.text()
    assert len(view.arm_curves["right"].getData()[1]) > 0
    assert "arm right peak 9.0 N: above the axis" in view.title_text


def test_the_wizards_arm_picker_asks_for_the_arm_chosen(qtbot) -> None:
    from study_app.gui.calibration_wizard import CalibrationWizard
    from study_app.models.calibration import CalibrationModel
    from study_app.models.commissioning import CommissioningModel

    chain, asked = CommissioningModel(), []
    wiz = CalibrationWizard(CalibrationModel(), lambda: None, chain=chain, on_arm=asked.append)
    qtbot.addWidget(wiz)
    wiz.show()
    assert not wiz.arm_picker.isVisible()  # one arm: no picker
    chain.apply(TWO)
    chain.apply(m.CalibrationStatus("sim", "simulated instrument", "", STEPS, "", "right"))
    assert wiz.arm_picker.isVisible()
    assert [wiz.arm_picker.choice.itemText(i) for i in range(2)] == ["left", "right"]
    wiz.arm_picker.choice.activated.emit(1)
    assert asked == ["right"]
    chain.select_arm("right")
    assert wiz.arm_picker.choice.currentIndex() == 1
    assert wiz.chain_status.steps.text().startswith("<b>On record for 'simulated instrument' on arm right</b>")
    chain.tcp_command()
    assert not wiz.arm_picker.choice.isEnabled()  # a step under way keeps its arm


def test_the_window_on_two_arms_commissions_the_second_and_starts_with_the_task_arm_first(qtbot, tmp_path) -> None:
    """gui --sim-arms right,left with task_arm = "left": the right arm's TCP from the calibration window, then Start
    restarts the simulated rig with the left arm first and the session runs, every arm's force plotted."""
    from PySide6.QtCore import QSettings

    from study_app.engine.setup import HostConfig
    from study_app.gui.main_window import ExperimenterWindow

    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    settings.setValue("setup/protocol_path", _protocol(tmp_path, "left"))
    w = ExperimenterWindow(HostConfig(clock="virtual", speed=4.0, sim_arms=("right", "left")), settings,
                           str(tmp_path / "study.db"))
    qtbot.addWidget(w, before_close_func=lambda win: setattr(win.session_actions, "confirm", lambda title, text: True))
    w.show()
    qtbot.waitUntil(lambda: w.model.session.state == "ready", timeout=30_000)
    chain = w.model.commissioning
    assert chain.arms == ("right", "left") and set(w.model.plots.arms) == {"left"}
    w.model.steps.select_arm("left")
    w.model.steps.run_tcp()
    qtbot.waitUntil(lambda: chain.tcp_state == "accepted", timeout=30_000)
    qtbot.waitUntil(lambda: chain.statuses["left"].steps[0][1], timeout=10_000)
    assert not chain.statuses["right"].steps[0][1]  # the other arm's record is untouched
    w.model.setup.update(code="P01")
    assert w.model.control.start()
    qtbot.waitUntil(lambda: w.model.session.running, timeout=60_000)
    assert chain.arms == ("left", "right") and w.bridge.client.config.sim_arms == ("left", "right")
    assert w.model.plots.task_arm == "left" and set(w.model.plots.arms) == {"right"}
    def drawn() -> bool:
        y = w.plots.arm_curves["right"].getData()[1]
        return y is not None and len(y) > 0

    qtbot.waitUntil(drawn, timeout=10_000)


def test_a_start_waiting_for_a_restart_is_dropped_when_the_engine_is_restarted_again(tmp_path) -> None:
    """The rearranged engine never came up; a later Restart engine must not start that session by itself."""
    sent: list[object] = []
    a = AppModel(lambda c: sent.append(c) or True)
    a.engine.restarter = lambda arms=(): None
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                          arm_rings=(("right", "r"), ("left", "l"))))
    a.setup.update(db_path=str(tmp_path / "s.db"), code="P01", protocol_path=_protocol(tmp_path, "left"))
    assert a.control.start()
    a.apply(m.EngineStopped("the engine exited unexpectedly", {}))
    assert a.engine.restart()
    a.apply(m.EngineReady("", "sim", "virtual", {}, 0.1, (0.3, 0.0, 0.115), "autopilot",
                          arm_rings=(("left", "l"), ("right", "r"))))
    assert not any(isinstance(c, m.StartSession) for c in sent)
