"""firmware_sim/scenarios/drive_eval.py: the event figures of held-out driving, per decision mode,
from the runtime's own decisions (a scripted early classifier on a step signal: known answers)."""
import json

import numpy as np
import pytest
from support.early_model import NEUTRAL_WEIGHTS, SCRIPTED_EARLY_THRESHOLDS, Scripted, step_signal, write_assets

from edge_runtime import config
from edge_runtime.wearable import loop  # noqa: F401 - its [alerts] section
from firmware_sim.__main__ import main
from firmware_sim.scenarios.drive_eval import MODES, Drive, ModeScore, evaluate, held_out_drives, plot_example


def _drive():
    # triggers at 10 s (a Phone distraction 9.5..14 s), 40 s (nothing there: a false alert),
    # 52 s (a Drink 51.8..70 s whose capture the classifier calls Phone)
    acc = step_signal(9000, [1000, 4000, 5200])
    events = [{"start_s": 9.5, "end_s": 14.0, "label": "Phone"}, {"start_s": 51.8, "end_s": 70.0, "label": "Drink"},
              {"start_s": 80.0, "end_s": 81.0, "label": "Other"}]
    return Drive("steps", acc, events, "distraction")


def test_each_mode_is_scored_from_its_first_alerts():
    cfg = config.override(config.load(None), "alerts", event_hold_s=0.0, class_weights=NEUTRAL_WEIGHTS,
                          min_confidence_by_steps=SCRIPTED_EARLY_THRESHOLDS)
    res = evaluate([_drive()], Scripted({2: ("Phone", 0.95), 6: ("Phone", 0.9)}), cfg, progress=lambda _: None)
    early, full = res["scores"]["early"], res["scores"]["full_window"]
    for s in (early, full):
        assert (s["distractions"], s["event_recall"], s["first_alert_class_accuracy"]) == (2, 1.0, 0.5)
        assert s["false_alerts"] == 1 and s["false_alerts_per_hour"] == pytest.approx(1 / (90 / 3600), rel=1e-3)
    # early: the preliminary frame goes out when the capture (from frame 900) holds 263 frames
    assert early["onset_to_first_alert_s"]["median"] == pytest.approx(np.median([11.62 - 9.5, 53.62 - 51.8]), abs=1e-3)
    assert full["onset_to_first_alert_s"]["median"] == pytest.approx(np.median([15.99 - 9.5, 57.99 - 51.8]), abs=1e-3)
    assert (early["first_alerts_after_the_distraction_ended"], full["first_alerts_after_the_distraction_ended"]) == (0, 1)
    assert early["statuses"] == {"confirmed": 3, "preliminary": 3} and full["statuses"] == {"alert": 3}
    ex = res["example"]
    assert ex["mode"] == "early" and ex["decisions"][0]["status"] == "preliminary"


def test_a_withdrawn_false_alert_and_a_repeat_alert_are_counted(tmp_path):
    cfg = config.override(config.load(None), "alerts", event_hold_s=0.0, class_weights=NEUTRAL_WEIGHTS,
                          min_confidence_by_steps=SCRIPTED_EARLY_THRESHOLDS)
    acc = step_signal(9000, [1000, 1700, 4000])  # 17 s: the hand returns during the Phone event (9.5..20 s)
    drive = Drive("steps", acc, [{"start_s": 9.5, "end_s": 20.0, "label": "Phone"}], "distraction")
    res = evaluate([drive], Scripted({2: ("Phone", 0.95), 6: ("Other", 0.9)}), cfg, modes=("early",),
                   progress=lambda _: None)
    s = res["scores"]["early"]
    assert (s["repeat_alerts"], s["false_alerts"], s["false_alerts_withdrawn"]) == (1, 1, 1)
    plot_example(res["example"], tmp_path / "trace.png")
    assert (tmp_path / "trace.png").stat().st_size > 10_000
    # with the event tracker, the hand returning continues the event: no repeat alert
    held = config.override(config.load(None), "alerts", event_hold_s=10.0, class_weights=NEUTRAL_WEIGHTS,
                          min_confidence_by_steps=SCRIPTED_EARLY_THRESHOLDS)
    res = evaluate([drive], Scripted({2: ("Phone", 0.95), 6: ("Phone", 0.9)}), held, modes=("early",),
                   progress=lambda _: None)
    assert res["scores"]["early"]["repeat_alerts"] == 0 and res["scores"]["early"]["statuses"]["continued"] == 1


def _one_trigger(events, answers, modes=MODES):
    """A single trigger at 40 s (an Other motion's, unless a distraction starts within 1 s after it): the
    early preliminary at S = 2 goes out at 41.62 s, at S = 3 at 42.78 s, the full window at 45.99 s."""
    cfg = config.override(config.load(None), "alerts", event_hold_s=0.0, class_weights=NEUTRAL_WEIGHTS,
                          min_confidence_by_steps=SCRIPTED_EARLY_THRESHOLDS)
    drive = Drive("steps", step_signal(9000, [4000]), events, "distraction")
    return evaluate([drive], Scripted(answers), cfg, modes=modes, progress=lambda _: None)


PHONE = {2: ("Phone", 0.95), 6: ("Phone", 0.9)}


def _figures(s):
    return (s["event_recall"], s["detected_by_frame"], s["false_alerts"], s["onset_to_first_alert_s"]["median"])


def test_an_alert_that_reaches_the_driver_during_a_distraction_is_that_distractions():
    """The capture of an Other motion at 40 s holds a Drink from 43 s: its full-window alert (45.99 s) goes
    out 2.99 s into the Drink. By trigger alone a false alert and a missed Drink; by frame the Drink's, 2.99 s
    after its onset, though its class (Phone) is wrong. Early: the preliminary (41.62 s) went out before the
    onset, its confirmation at 45.99 s during the Drink: the event is the Drink's, from the confirmation, as
    the full window's is (no mode is scored differently for the same capture)."""
    res = _one_trigger([{"start_s": 43.0, "end_s": 48.0, "label": "Drink"}], PHONE)
    for mode in MODES:
        s = res["scores"][mode]
        assert _figures(s) == (1.0, 1, 0, pytest.approx(2.99, abs=1e-3))
        assert (s["first_alerts_by_frame"], s["first_alert_class_accuracy"]) == (1, 0.0)
        assert _figures(res["scores_by_trigger"][mode]) == (0.0, 0, 1, None)


@pytest.mark.parametrize("full_window, credited", [(("Other", 0.9), False), (("Phone", 0.9), True)])
def test_a_withdrawn_alert_during_a_distraction_is_a_false_alert_and_its_miss_reason_stays_by_trigger(
        full_window, credited):
    """A preliminary at S = 3 (42.78 s) goes out 1.58 s into a Drink from 41.2 s (the trigger, 40 s, is more
    than 1 s before it). Withdrawn by its full window, the event is not the Drink's: a false alert (withdrawn)
    and a missed Drink, as by trigger, whose reason is its own captures' (none: the detector was paused), not
    the withdrawn capture's. Confirmed instead, the same frame is the Drink's alert, 1.58 s after its onset."""
    res = _one_trigger([{"start_s": 41.2, "end_s": 48.0, "label": "Drink"}], {3: ("Phone", 0.95), 6: full_window},
                       modes=("early",))
    s = res["scores"]["early"]
    if credited:
        assert _figures(s) == (1.0, 1, 0, pytest.approx(1.58, abs=1e-3))
    else:
        assert _figures(s) == (0.0, 0, 1, None) and s["false_alerts_withdrawn"] == 1
        assert s["by_class"]["Drink"] == {"distractions": 1, "alerted": 0,
                                          "no trigger: detector paused by an earlier capture": 1}
        assert s["by_class"] == res["scores_by_trigger"]["early"]["by_class"]


@pytest.mark.parametrize("onset_s, credited", [(45.0, False), (44.8, True)])
def test_a_frame_is_credited_only_after_one_sub_window_of_the_distraction(onset_s, credited):
    """The full window's frame at 45.99 s: 0.99 s after a Drink's onset its decision held less than one
    sub-window (1.155 s) of it, decided on the Other motion before it: a false alert and a miss; 1.19 s after
    it, the Drink's alert. Early: the preliminary went out before the onset, its confirmation at the same
    frame, scored alike."""
    from firmware_sim.scenarios.drive_eval import SUBWINDOW_S

    assert SUBWINDOW_S == pytest.approx(33 / (200 / 7))
    res = _one_trigger([{"start_s": onset_s, "end_s": 48.0, "label": "Drink"}], PHONE)
    for mode in MODES:
        assert _figures(res["scores"][mode]) == ((1.0, 1, 0, pytest.approx(45.99 - onset_s, abs=1e-3)) if credited
                                                 else (0.0, 0, 1, None))


def test_a_frame_just_after_a_distractions_end_is_a_false_alert():
    res = _one_trigger([{"start_s": 43.0, "end_s": 45.98, "label": "Drink"}], PHONE)
    for mode in MODES:
        assert _figures(res["scores"][mode]) == (0.0, 0, 1, None)


def test_an_alert_triggered_in_one_distraction_stays_its_own_when_its_frame_goes_out_in_the_next():
    """The trigger at 40 s falls in a Phone (39.5..41 s), the full-window frame in a Drink (43..48 s): the
    alert is the Phone's (late, 6.49 s after its onset), not the Drink's, which is missed; early's
    confirmation in the Drink is an update of the Phone's alert, not a second alert."""
    res = _one_trigger([{"start_s": 39.5, "end_s": 41.0, "label": "Phone"},
                        {"start_s": 43.0, "end_s": 48.0, "label": "Drink"}], PHONE)
    for mode, latency_s in (("full_window", 6.49), ("early", 2.12)):
        s = res["scores"][mode]
        assert _figures(s) == (0.5, 0, 0, pytest.approx(latency_s, abs=1e-3))
        assert (s["first_alert_class_accuracy"], s["first_alerts_after_the_distraction_ended"], s["repeat_alerts"]) == (
            1.0, 1, 0)
        assert s["by_class"]["Drink"]["alerted"] == 0


def test_mode_score_takes_its_attribution_explicitly():
    from firmware_sim.scenarios.drive_eval import ModeScore

    with pytest.raises(TypeError):
        ModeScore()
    with pytest.raises(ValueError, match="attribution 'time'"):
        ModeScore(attribution="time")


def test_held_out_drives_mix_baseline_drives_without_distractions():
    drives = list(held_out_drives(hours=0.2, seed=3, baseline_share=0.5, drive_minutes=3))
    assert [d.kind for d in drives] == ["distraction"] * 2 + ["baseline"] * 2
    assert all(e["label"] == "Other" for d in drives if d.kind == "baseline" for e in d.events)
    assert sum(d.hours for d in drives) == pytest.approx(0.2)


def test_the_command_writes_json_markdown_and_the_trace(tmp_path, capsys):
    assert main(["drive-eval", "--hours", "0.1", "--drive-minutes", "3", "--seed", "5", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "drive_eval.json").read_text())
    # the shipped decider (stream) beside the capture path's two modes (the shipped ConvLSTM takes partial captures)
    assert set(report["scores"]) == {"full_window", "early", "stream"}
    assert all(report["scores"][m]["driving_hours"] == pytest.approx(0.1) for m in report["scores"])
    assert "| event recall |" in (tmp_path / "drive_eval.md").read_text()
    # provenance: what decided (the shipped int8 model by its int8 step model, each by its sha256) and the code
    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest
    from firmware_sim.scenarios.drive_eval import git_head

    sha = {e["name"]: e["sha256"] for e in load_manifest(ASSETS_DIR)["models"]}
    assert report["decision_path"] == {"model": "convlstm-int8", "sha256": sha["convlstm-int8"],
                                       "step_model": "convlstm-step-int8", "step_model_sha256": sha["convlstm-step-int8"]}
    assert (report["stream_path"]["model"], report["stream_path"]["sha256"]) == ("stream-int8", sha["stream-int8"])
    head = git_head()
    assert report["git_commit"] == head and (head is None or len(head) == 40)
    assert f"Decisions by the step model convlstm-step-int8 (sha256 {sha['convlstm-step-int8']})" in (
        tmp_path / "drive_eval.md").read_text()
    assert main(["drive-eval", "--hours", "0.05", "--drive-minutes", "3", "--seed", "5", "--out", str(tmp_path),
                 "--decision", "early", "--step-accuracy"]) == 0
    assert "| S | decision frame" in (tmp_path / "drive_eval.md").read_text()
    assert main(["drive-eval", "--hours", "1", "--decision", "late", "--out", str(tmp_path)]) == 2
    assert "--decision late" in capsys.readouterr().err


def test_with_a_model_that_takes_partial_captures_both_modes_are_measured_side_by_side(tmp_path):
    assets = write_assets(tmp_path / "assets", early={"steps": [1, 2, 3, 4, 5, 6]}, favour="Phone")
    out = tmp_path / "out"
    assert main(["drive-eval", "--hours", "0.1", "--drive-minutes", "3", "--seed", "5", "--assets", str(assets),
                 "--decision", "full_window,early", "--out", str(out)]) == 0  # these assets have no stream model
    report = json.loads((out / "drive_eval.json").read_text())
    early, full = report["scores"]["early"], report["scores"]["full_window"]
    assert report["early_steps"] == [1, 2, 3, 4, 5, 6] and early["statuses"].get("preliminary", 0) > 0
    assert early["onset_to_first_alert_s"]["median"] < full["onset_to_first_alert_s"]["median"] - 4.0
    assert "| figure | full_window | early |" in (out / "drive_eval.md").read_text()


def test_class_agreement_compares_two_models_at_every_step_on_every_capture():
    from support.early_model import engine

    from edge_runtime.wearable.detector import DetectorConfig
    from firmware_sim.scenarios.drive_eval import class_agreement

    drive = _drive()  # three captures
    phone, phone2, drink = engine(favour="Phone"), engine(favour="Phone", seed=1), engine(favour="Drink")
    same = class_agreement([drive], phone, phone2, DetectorConfig())
    assert (same["agreement"], same["decisions"]) == (1.0, 3 * 6) and set(same["by_steps"]) == {"1", "2", "3", "4", "5", "6"}
    assert class_agreement([drive], phone, drink, DetectorConfig())["agreement"] == 0.0


def test_missed_distractions_are_told_by_class_and_where_they_were_lost():
    # a trigger at 10 s (Phone 9.5..10.2 s, alerted); a Drink 10.5..12 s whose motion came while the
    # detector was paused by the Phone's capture; a Marker 30..32 s with no motion the detector sees
    acc = step_signal(6000, [1000])
    events = [{"start_s": 9.5, "end_s": 10.2, "label": "Phone"}, {"start_s": 10.5, "end_s": 12.0, "label": "Drink"},
              {"start_s": 30.0, "end_s": 32.0, "label": "Marker"}]
    cfg = config.override(config.load(None), "alerts", event_hold_s=0.0, class_weights=NEUTRAL_WEIGHTS)
    res = evaluate([Drive("steps", acc, events, "distraction")], Scripted({2: ("Phone", 0.95), 6: ("Phone", 0.9)}),
                   cfg, modes=("early",), progress=lambda _: None)
    assert res["scores"]["early"]["by_class"] == {
        "Drink": {"distractions": 1, "alerted": 0, "no trigger: detector paused by an earlier capture": 1},
        "Marker": {"distractions": 1, "alerted": 0, "no trigger: below the threshold": 1},
        "Phone": {"distractions": 1, "alerted": 1}}


def test_step_accuracy_scores_every_capture_at_every_sub_window_count():
    from firmware_sim.scenarios.drive_eval import step_accuracy

    # triggers at 10 s (a Phone) and 40 s (nothing there: truth Other); the model says Phone throughout
    drive = Drive("steps", step_signal(6000, [1000, 4000]), [{"start_s": 9.5, "end_s": 14.0, "label": "Phone"}],
                  "distraction")
    clf = Scripted({})
    acc = step_accuracy([drive], clf, config.load(None).detector)
    assert acc["2"] == {"accuracy_every_capture": 0.5, "captures": 2, "accuracy_distraction_captures": 1.0,
                        "decision_frame_after_trigger_s": 1.62}
    # weighting Other up makes the 40 s capture right and the Phone wrong
    weights = (1.0, 1.0, 1.0, 1.0, 1.0, 10.0)
    assert step_accuracy([drive], clf, config.load(None).detector, weights)["6"]["accuracy_distraction_captures"] == 0.0


def test_git_head_reads_a_checkout_a_worktree_and_packed_refs_without_git(tmp_path):
    from firmware_sim.scenarios.drive_eval import git_head

    a, b = "a" * 40, "b" * 40
    common = tmp_path / "repo" / ".git"
    (common / "refs" / "heads").mkdir(parents=True)
    (common / "HEAD").write_text("ref: refs/heads/main\n")
    (common / "refs" / "heads" / "main").write_text(a + "\n")
    assert git_head(tmp_path / "repo") == a
    wt_git = common / "worktrees" / "wt"  # a worktree whose branch is only in packed-refs
    wt_git.mkdir(parents=True)
    (wt_git / "HEAD").write_text("ref: refs/heads/topic\n")
    (wt_git / "commondir").write_text("../..\n")
    (common / "packed-refs").write_text(f"# pack-refs with: peeled\n{b} refs/heads/topic\n")
    (tmp_path / "wt").mkdir()
    (tmp_path / "wt" / ".git").write_text(f"gitdir: {wt_git}\n")
    assert git_head(tmp_path / "wt") == b
    (wt_git / "HEAD").write_text(a + "\n")  # detached
    assert git_head(tmp_path / "wt") == a
    assert git_head(tmp_path / "nowhere") is None


# ---------------------------------------------------------------------------- the streaming decider (issue 12)


class MovesOnX:
    """A stand-in streaming classifier: Phone while the window's last second moves on x, else Other."""

    classes = ("Phone", "Texting", "TouchScreen", "Drink", "Marker", "Other")
    name, precision, entry, step_model = "stand-in", "fp32", {}, None

    def classify_window(self, window):
        p = np.full(6, 0.01, np.float32)
        p[0 if window[-25:, 0].mean() > 3.0 else 5] = 0.95
        return p


def test_the_stream_mode_replays_through_the_streaming_decider_and_scores_as_session_21():
    from edge_runtime.wearable import stream_decider  # noqa: F401 - its [stream] section
    from firmware_sim.scenarios.drive_eval import STREAM, stream_scored

    acc = np.tile(np.float32([0, 0, 9.81]), (12000, 1))
    acc[3000:5000, 0] += 6.0  # the distraction, 30-50 s
    acc[8000:8300, 0] += 6.0  # an Other motion the stand-in takes for a phone, 80-83 s
    events = [{"label": "Phone", "start_s": 30.0, "end_s": 50.0}, {"label": "Other", "start_s": 80.0, "end_s": 83.0}]
    cfg = config.box_config_type()()
    res = evaluate([Drive("d", acc, events, "distraction")], None, cfg, modes=(STREAM,), progress=lambda _: None,
                   stream_model=MovesOnX())
    s = res["scores"][STREAM]
    assert (s["event_recall"], s["first_alert_class_accuracy"], s["false_alerts"]) == (1.0, 1.0, 1)
    assert 0.5 < s["onset_to_first_alert_s"]["median"] < 2.5 and s["statuses"] == {"alert": 2}
    # session 21's convention: the scorer reads a stream alert's trigger 1 s after its frame, so a frame from 2 s
    # before a distraction's start is credited to it (and counted apart), one 2.1 s before is not
    d = {"t_trigger_s": 0.0, "t_alert_s": 28.1, "label": "Phone", "alerted": True, "status": "alert", "alert_seq": 0,
         "event_start_s": 0.0}
    for t_alert_s, credited in ((28.0, True), (27.9, False)):
        score = ModeScore(attribution="frame", detector=None)
        score.add(Drive("d", acc, events, "distraction"), [stream_scored({**d, "t_alert_s": t_alert_s})])
        got = score.as_dict()
        assert (got["event_recall"] == 1.0, got["first_alerts_before_the_onset"]) == (credited, int(credited))


def test_hop_f1_counts_every_hop_of_the_streaming_decider_against_the_truth():
    from edge_runtime.wearable.labels import CLASSES
    from edge_runtime.wearable.stream_decider import StreamParams
    from firmware_sim.scenarios.drive_eval import hop_f1

    acc = np.tile(np.float32([0, 0, 9.81]), (12000, 1))
    acc[3000:5000, 0] += 6.0  # the distraction the stand-in sees, 30-50 s
    acc[8000:8300, 0] += 6.0  # an Other motion it takes for a phone, 80-83 s
    events = [{"label": "Phone", "start_s": 30.0, "end_s": 50.0}, {"label": "Other", "start_s": 80.0, "end_s": 83.0}]
    params = StreamParams()
    got = hop_f1([Drive("d", acc, events, "distraction")], MovesOnX(), params)
    c = np.array(got["confusion"])
    other, phone = CLASSES.index("Other"), CLASSES.index("Phone")
    # every decided hop is scored once but the unscored ones (from the onset for 0.3 s, the second after the end)
    scored = round((120.0 - params.window_s) / params.hop_s) - round(1.3 / params.hop_s)
    assert abs(got["hops"] - scored) <= 2 and c.sum() == got["hops"]
    assert c[phone, phone] > 0 and c[other, phone] > 0  # the Other motion: Other taken for Phone
    assert c.sum(1)[[i for i in range(len(CLASSES)) if i not in (other, phone)]].sum() == 0
    assert 0.0 < got["macro_f1"] < 1.0 and set(got["per_class_f1"]) == {"Other", "Phone"}
