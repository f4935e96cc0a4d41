"""Where the early decisions' errors are, on the selection cohort only (issue 12, "What a retrain would need").

    PYTHONPATH=. python reports/wearable/selection/early_errors.py [OUT_MD]

Trains the chosen recipe (reports/wearable/selection/selection.json: captures, time shift, epochs,
schedule, step-loss weights, seed 0) on the selection cohort's training subjects, exactly as
``python -m models select`` does (same weights), and reads its decisions after S = 1..6 sub-windows
on the validation subjects' detector captures: per step the accuracy, how many distraction captures
go to the other phone class (Phone <-> Texting), the accuracy if the two were one class ("phone in
hand"), and, at a confidence threshold, how many distraction captures would alert and how many of
those alerts name the right class. Raw softmax (the shipped model's temperatures are fitted later,
per model). Then, from the validation drives' breakdown of the shipped settings
(reports/wearable/early_tuning/breakdown_early.json, ``firmware_sim early-tune --seed 1``): the
onset -> first alert time every distraction would get if its first alert came at S = 1 or S = 2 of
its first capture (its trigger delay plus the step's time after the trigger, measured there), the
bound a better classifier at that step could reach with this detector and these sub-windows. No
held-out subject and no held-out drive is read.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
THRESHOLDS = (0.5, 0.7, 0.9)


def main(out: Path) -> None:
    import torch

    from models.dataset import load_npz
    from models.evaluate import predict_steps
    from models.selection import training_arrays
    from models.train import fit

    torch.set_num_threads(1)
    sel = json.loads((HERE / "selection.json").read_text())
    r = sel["recipe"]
    gt, cap = load_npz(HERE / "data" / "train.npz"), load_npz(HERE / "data" / "test.npz")
    X, y = training_arrays(gt, cap if r["captures"] else None, sel["train_subjects"])
    model = fit("convlstm", X, y, len(gt.classes), epochs=r["epochs"], seed=sel["selection_seed"] - 1000,
                progress=False, shift_fwd=r["shift_fwd"], schedule_epochs=r["schedule_epochs"],
                step_loss_weights=r.get("step_loss_weights"))
    val = cap.subset(np.isin(cap.subject, sel["validation_subjects"]))
    probs = predict_steps(model, val.X)
    classes = list(gt.classes)
    other, phone, text = classes.index("Other"), classes.index("Phone"), classes.index("Texting")
    hand = np.array([phone if k == text else k for k in range(len(classes))])
    dist = val.y != other
    lines = ["# Early decisions' errors on the selection cohort (the chosen recipe)", "",
             f"`PYTHONPATH=. python reports/wearable/selection/early_errors.py`: recipe {r}; trained on selection "
             f"subjects {sel['train_subjects']}, read on the {len(val)} detector captures of subjects "
             f"{sel['validation_subjects']} ({int(dist.sum())} of a distraction). Raw softmax.", "",
             "| S | accuracy, every capture | distraction captures read as Other | Phone read as Texting | Texting read as Phone | accuracy, Phone+Texting one class | "
             + " | ".join(f"p >= {t}: distraction captures alerted / their class right" for t in THRESHOLDS) + " |",
             "|---:|---:|---:|---:|---:|---:|" + "---:|" * len(THRESHOLDS)]
    for s, p in enumerate(probs, start=1):
        pred, conf = p.argmax(1), p.max(1)
        cells = [f"{np.mean(pred == val.y):.3f}", f"{np.mean(pred[dist] == other):.3f}",
                 f"{np.sum((val.y == phone) & (pred == text))} of {np.sum(val.y == phone)}",
                 f"{np.sum((val.y == text) & (pred == phone))} of {np.sum(val.y == text)}",
                 f"{np.mean(hand[pred] == hand[val.y]):.3f}"]
        for t in THRESHOLDS:
            alert = dist & (pred != other) & (conf >= t)
            cells.append(f"{np.mean(alert[dist]):.3f} / {np.mean(pred[alert] == val.y[alert]):.3f}")
        lines.append(f"| {s} | " + " | ".join(cells) + " |")
    lines += _latency_bound()
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _latency_bound() -> list[str]:
    b = json.loads((HERE.parent / "early_tuning" / "breakdown_early.json").read_text())
    first = [e for e in b["events"] if "first_steps" in e]
    after = {s: float(np.median([e["onset_to_alert_s"] - e["first_trigger_delay_s"] for e in first
                                 if e["first_steps"] == s])) for s in (2, 3)}
    after[1] = after[2] - (after[3] - after[2])  # one sub-window before S = 2
    delay = np.array([e["trigger_delay_s"] for e in b["events"] if e.get("trigger_delay_s") is not None])
    lines = ["", "## The latency a perfect early step would give (validation drives, this detector)", "",
             f"From `{b['command']}` (breakdown_early.json): {len(delay)} of {len(b['events'])} distractions "
             f"triggered a capture, a median {np.median(delay):.2f} s (p95 {np.percentile(delay, 95):.2f} s) after "
             f"the onset. The first alert frame at S comes a fixed time after the trigger: S = 2 "
             f"{after[2]:.2f} s, S = 3 {after[3]:.2f} s measured; S = 1 ~{after[1]:.2f} s (one sub-window earlier).", "",
             "| every first alert at | onset -> first alert, median | p95 | share <= 2.0 s |", "|---|---:|---:|---:|"]
    for s in (1, 2):
        x = delay + after[s]
        lines.append(f"| S = {s} | {np.median(x):.2f} s | {np.percentile(x, 95):.2f} s | {np.mean(x <= 2.0):.2f} |")
    return lines


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "early_errors.md")
