"""firmware_sim/scenarios/early_tuning.py: the breakdown of where the time and errors go, the cached
model outputs, the sweep and the rule that picks the operating point (a scripted classifier on step
signals: known answers)."""
import pytest
from support.early_model import NEUTRAL_WEIGHTS, SCRIPTED_EARLY_THRESHOLDS, Scripted, step_signal

from edge_runtime import config
from edge_runtime.wearable import loop  # noqa: F401 - its [alerts] section
from firmware_sim.__main__ import main
from firmware_sim.scenarios.drive_eval import Drive, evaluate
from firmware_sim.scenarios.early_tuning import (
    CachedClassifier,
    breakdown,
    choose,
    decide,
    false_alert_cause,
    score,
    sweep,
)


class Counting(Scripted):
    """Scripted, counting how often the model is asked (as an Engine would be)."""

    def __init__(self, answers):
        super().__init__(answers)
        self.early.min_confidence_by_steps = {}
        self.calls = 0

    def classify_prefix(self, x, steps):
        self.calls += 1
        return super().classify_prefix(x, steps)


def _drive():
    # triggers at 10 s (a Phone 9.5..14 s), 40 s (an Other motion 39.8..41 s: a false alert),
    # 52 s (2 s after a Drink ended: the hand returning), 75 s (nothing there)
    acc = step_signal(9000, [1000, 4000, 5200, 7500])
    events = [{"start_s": 9.5, "end_s": 14.0, "label": "Phone"},
              {"start_s": 39.8, "end_s": 41.0, "label": "Other", "kind": "scratch_head"},
              {"start_s": 45.0, "end_s": 50.0, "label": "Drink"}]
    return Drive("steps", acc, events, "distraction")


def _cfg(**alerts):
    """The capture path's early decisions (what early-tune sweeps), with no event hold and neutral weights."""
    return config.override(config.load(None), "alerts", **{"decision": "early", "event_hold_s": 0.0,
                                                           "class_weights": NEUTRAL_WEIGHTS, **alerts})


def test_decide_is_the_runtime_replay_and_the_cache_asks_the_model_once():
    answers = {2: ("Phone", 0.95), 6: ("Phone", 0.9)}
    model = Counting(answers)
    clf = CachedClassifier(model)
    drives = [_drive()]
    first = decide(drives, clf, _cfg())
    asked = model.calls
    # four captures of two shapes (a step up, a step down), five steps each: S = 1 comes before the
    # shipped earliest_alert_step (2) and counts for no agreement, so the loop does not compute it
    assert asked == 2 * 5
    assert decide(drives, clf, _cfg(earliest_alert_step=3)) != first and model.calls == asked
    # the same figures as drive-eval's replay through the publisher (scored by trigger, as early-tune selects)
    replayed = evaluate(drives, Scripted(answers), _cfg(), modes=("early",), progress=lambda _: None)
    assert score(drives, first) == replayed["scores_by_trigger"]["early"]


def test_breakdown_says_when_the_trigger_came_which_step_alerted_and_what_set_off_false_alerts():
    drive = _drive()
    ds = decide([drive], Scripted({2: ("Phone", 0.95), 6: ("Phone", 0.9)}),
                _cfg(min_confidence_by_steps=SCRIPTED_EARLY_THRESHOLDS))
    b = breakdown([drive], ds, pre_frames=100, rate_hz=100)
    phone, drink = b["events"]
    assert (phone["trigger_delay_s"], phone["first_steps"], phone["first_correct"]) == (0.5, 2, True)
    assert phone["onset_to_alert_s"] == pytest.approx(11.62 - 9.5)
    assert drink["missed"] == "no trigger" and drink["trigger_delay_s"] is None
    assert [f["cause"] for f in b["false_alerts"]] == ["Other motion (scratch_head)",
                                                       "hand returning after a distraction", "driving (no hand event)"]
    s = b["summary"]
    assert s["first_alert_by_steps"]["2"]["first_alerts"] == 1 and s["false_alerts_by_steps"] == {2: 3}
    # the full window says Other: a missed distraction, for that reason
    ds = decide([drive], Scripted({6: ("Other", 0.9)}), _cfg())
    assert breakdown([drive], ds, 100, 100)["events"][0]["missed"] == "full window said Other"
    assert false_alert_cause(drive, 30.0) == "driving (no hand event)"


def test_sweep_scores_each_policy_and_the_rule_takes_the_fastest_that_keeps_class_and_recall():
    drives = [_drive()]
    clf = CachedClassifier(Counting({2: ("Phone", 0.95), 4: ("Texting", 0.95), 6: ("Phone", 0.9)}))
    grid = {"early_threshold": ("manifest", 0.9), "earliest_alert_step": (1, 3), "early_agreement_steps": (1,),
            "early_min_margin": (0.0,), "full_window_threshold": ("manifest",), "event_hold_s": (0.0,)}
    rows = sweep(drives, clf, _cfg(), grid, progress=lambda _: None)
    assert len(rows) == 4
    by = {(r["point"]["early_threshold"], r["point"]["earliest_alert_step"]): r for r in rows}
    # no manifest thresholds: 0.9 before the full window; from S = 3 on the first alert is S = 4's Texting
    assert by[("manifest", 1)]["class_accuracy"] == 1.0 and by[("manifest", 3)]["class_accuracy"] == 0.0
    assert by[(0.9, 1)]["median_s"] < by[(0.9, 3)]["median_s"]
    assert all(r["event_recall"] == 0.5 for r in rows)  # the Drink has no trigger
    full = {"event_recall": 0.5, "repeat_alerts": 0, "false_alerts": max(r["false_alerts"] for r in rows)}
    assert choose(rows, full)["point"]["earliest_alert_step"] == 1
    assert choose(rows, {**full, "event_recall": 0.6}) is None  # no policy keeps that recall
    for r in rows:
        if r["point"]["earliest_alert_step"] == 1:
            r["repeat_alerts"] = 1  # now the faster policies warn twice for one distraction
    assert choose(rows, full) is None  # the slower ones have the wrong class


def test_the_rule_tolerates_one_poisson_sd_of_the_full_windows_repeat_and_false_alerts_not_more():
    # the full window: 36 repeat alerts (sd 6) and 49 false alerts (sd 7) on the validation drives
    full = {"event_recall": 0.9, "repeat_alerts": 36, "false_alerts": 49}

    def row(median, repeat=36, false=49, recall=0.9, cls=0.91):
        return {"point": {"median": median}, "settings": {"earliest_alert_step": 2}, "median_s": median,
                "class_accuracy": cls, "event_recall": recall, "repeat_alerts": repeat, "false_alerts": false,
                "false_alerts_per_hour": false / 20}

    # one repeat alert more than the full window no longer decides: the faster policy is taken
    assert choose([row(5.8), row(3.8, repeat=37)], full)["median_s"] == 3.8
    assert choose([row(5.8), row(3.8, repeat=42)], full)["median_s"] == 3.8  # 36 + 6: at the limit
    assert choose([row(5.8), row(3.8, repeat=43)], full)["median_s"] == 5.8  # beyond one sd
    assert choose([row(5.8), row(3.8, false=56)], full)["median_s"] == 3.8  # 49 + 7
    assert choose([row(5.8), row(3.8, false=57)], full)["median_s"] == 5.8  # false alerts are a constraint now
    # recall and class accuracy keep no tolerance
    assert choose([row(5.8), row(3.8, recall=0.899)], full)["median_s"] == 5.8
    assert choose([row(5.8), row(3.8, cls=0.899)], full)["median_s"] == 5.8


class ByShape(Scripted):
    """Phone at every step, 0.9 sure of a capture whose step goes up, 0.6 of one whose step goes down."""

    def classify_prefix(self, x, steps):
        return self._probs("Phone", 0.9 if x[-1, 0] > x[0, 0] else 0.6)


def test_per_step_thresholds_are_the_lowest_confidence_whose_captures_are_right_often_enough(monkeypatch):
    from firmware_sim.scenarios import early_tuning

    monkeypatch.setattr(early_tuning, "MIN_SUPPORT", 1)
    # steps up at 10 s and 52 s (Phone distractions), down at 40 s and 75 s (nothing there)
    acc = step_signal(9000, [1000, 4000, 5200, 7500])
    events = [{"start_s": 9.5, "end_s": 14.0, "label": "Phone"}, {"start_s": 51.5, "end_s": 60.0, "label": "Phone"}]
    got = early_tuning.precision_thresholds([Drive("steps", acc, events, "distraction")], ByShape({}),
                                            config.load(None).detector, [0.5, 0.9])
    assert got == {"precision 0.5": [0.3] * 5, "precision 0.9": [0.61] * 5}


def test_the_held_out_seed_is_refused(tmp_path, capsys):
    assert main(["early-tune", "--seed", "2", "--out", str(tmp_path)]) != 0
    assert "held-out" in capsys.readouterr().err


def test_the_detector_threshold_moves_only_for_a_clear_gain_in_time():
    from firmware_sim.scenarios.early_tuning import choose_detector

    full = {"event_recall": 0.8, "repeat_alerts": 10, "false_alerts": 40}

    def run(thr, median, recall=0.85):
        return {"threshold_mps2": thr, "median_s": median, "event_recall": recall, "class_accuracy": 0.91,
                "false_alerts_per_hour": 2.0, "false_alerts": 40, "repeat_alerts": 5,
                "settings": {"earliest_alert_step": 2}}

    # a tie in time that another threshold wins on recall: the current one stays
    assert choose_detector([run(4.5, 4.70, 0.86), run(5.0, 4.68)], full, 5.0) == 5.0
    assert choose_detector([run(4.5, 4.50), run(5.0, 4.68)], full, 5.0) == 4.5  # clearly faster
    assert choose_detector([run(4.5, 4.70), run(5.0, 4.60, recall=0.7)], full, 5.0) == 4.5  # 5.0 loses recall


def test_the_shipped_alert_policy_is_the_one_validation_chose():
    """Fails when a shipped capture-path [alerts] or [detector] default (what ``decision = "early"`` runs) differs
    from what reports/wearable/early_tuning chose on validation: re-run the command it names, or ship its choice.
    The box itself decides by the streaming classifier (chosen on development drives, reports/wearable/stream_s22)."""
    import json
    from pathlib import Path

    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.loop import AlertPolicy

    report = json.loads((Path(__file__).resolve().parents[2] / "reports/wearable/early_tuning/tradeoff.json").read_text())
    chosen, shipped = report["chosen"]["settings"], AlertPolicy()
    manifest = Engine.from_manifest(ASSETS_DIR, "int8").early.min_confidence_by_steps
    assert [shipped.threshold(s, manifest) for s in range(1, 7)] == chosen["min_confidence_by_steps"]
    assert {k: getattr(shipped, k) for k in chosen if k != "min_confidence_by_steps"} == \
        {k: v for k, v in chosen.items() if k != "min_confidence_by_steps"}
    assert shipped.decision == "stream"
    assert config.load(None).detector.threshold_mps2 == report["chosen_detector_threshold_mps2"]


def test_knob_effects_compare_policies_that_differ_in_one_knob_only():
    from firmware_sim.scenarios.early_tuning import knob_effects

    def row(margin, hold, median, cls):
        return {"point": {"early_min_margin": margin, "event_hold_s": hold}, "median_s": median,
                "class_accuracy": cls, "false_alerts_per_hour": 1.0, "event_recall": 0.9}

    rows = [row(0.0, 3.0, 4.0, 0.90), row(0.3, 3.0, 4.5, 0.92), row(0.0, 5.0, 3.0, 0.80), row(0.3, 5.0, 3.1, 0.80)]
    got = knob_effects(rows, {"early_min_margin": (0.0, 0.3), "event_hold_s": (3.0, 5.0)})
    margin = got["early_min_margin"]["0.0 -> 0.3"]
    assert margin["pairs"] == 2 and margin["median_s"] == {"mean": 0.3, "min": 0.1, "max": 0.5}
    assert margin["class_accuracy"]["max"] == pytest.approx(0.02)
    assert got["event_hold_s"]["3.0 -> 5.0"]["class_accuracy"]["mean"] == pytest.approx(-0.11)


def test_the_command_writes_the_breakdowns_the_tradeoff_and_its_choice(tmp_path, monkeypatch, capsys):
    import json

    from firmware_sim.scenarios import early_tuning

    monkeypatch.setattr(early_tuning, "GRID", {
        "early_threshold": ("manifest", 0.9), "earliest_alert_step": (2,), "early_agreement_steps": (1,),
        "early_min_margin": (0.0,), "full_window_threshold": ("manifest",), "event_hold_s": (5.0,)})
    # a short run on seed 7 (neither validation nor held-out): the shipped model on two 3-minute drives
    assert main(["early-tune", "--seed", "7", "--hours", "0.1", "--drive-minutes", "3", "--out", str(tmp_path),
                 "--cache", str(tmp_path / "cache.npz"), "--detector-thresholds", "5.0"]) == 0
    for name in ("early_manifest", "early", "full_window"):
        b = json.loads((tmp_path / f"breakdown_{name}.json").read_text())
        assert b["summary"]["distractions"] == len(b["events"]) > 0
    report = json.loads((tmp_path / "tradeoff.json").read_text())
    assert len(report["rows"]) == 2 and (tmp_path / "tradeoff.png").stat().st_size > 10_000
    assert {"full window", "early, as configured"} <= set(report["marks"])
    assert report["chosen"] is None or report["chosen"] in report["rows"]
    assert (tmp_path / "cache.npz").is_file()
    capsys.readouterr()
