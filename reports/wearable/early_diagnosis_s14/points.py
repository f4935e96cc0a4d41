"""Where the hybrid's time and errors come from: per decision point, the prefix model and the shipped ConvLSTM
(class weights applied) on the captures of development drives (``hybrid.seed_data``'s: the runtime's triggers).

    PYTHONPATH=. python reports/wearable/early_diagnosis_s14/points.py PREFIX.pt[,PREFIX.pt..] HOURS SEED THRESHOLD

Onset captures: the first capture whose trigger falls in a distraction (1 s before its start to its end, as
drive-eval's trigger rule); Other captures: triggers in no distraction. Per point: top-class accuracy on onsets,
and at THRESHOLD the share of onsets alerting right / alerting wrong and the share of Other captures alerting (a
distraction class at >= THRESHOLD: what would open a false alert if nothing else stopped it).
"""
import sys

import numpy as np

from edge_runtime import config
from edge_runtime.wearable.classifier import N_SUBSEQ, Engine, needed_frames
from edge_runtime.wearable.labels import CLASSES, DISTRACTIONS, OTHER
from firmware_sim.scenarios.drive_eval import MATCH_BEFORE_S
from reports.wearable.early_diagnosis_s14.hybrid import PREFIX_FRAMES, offset_s, seed_data
from reports.wearable.early_diagnosis_s14.prefix_net import load


def main(prefix: str, hours: float, seed: int, thr: float) -> None:
    import torch
    torch.set_num_threads(1)
    if seed not in (1, 5):
        raise SystemExit("development seeds 1 and 5 only")
    cfg = config.load(None)
    engine = Engine.from_params(cfg.model)
    drives, _, caps = seed_data(seed, hours, cfg, engine, [load(p) for p in prefix.split(",")], "/tmp/s14p/cache")
    other = CLASSES.index(OTHER)
    ys, conv, pre = [], [], []
    for drive, (t, cv, pr) in zip(drives, caps):
        truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
        seen = set()
        for i, tt in enumerate(t):
            e = next((k for k, e in enumerate(truth) if e["start_s"] - MATCH_BEFORE_S <= tt <= e["end_s"]), None)
            if e is not None and e in seen:
                continue  # a repeat capture of a distraction: not its onset
            if e is not None:
                seen.add(e)
            ys.append(other if e is None else CLASSES.index(truth[e]["label"]))
            conv.append(cv[i])
            pre.append(pr[i])
    y, conv, pre = np.asarray(ys), np.stack(conv), np.stack(pre)
    onset, oth = y != other, y == other
    rows = [(f"prefix {offset_s(n):.2f} s", pre[:, j]) for j, n in enumerate(PREFIX_FRAMES)]
    rows += [(f"ConvLSTM S={s} {offset_s(needed_frames(s)):.2f} s", conv[:, s - 1]) for s in range(1, N_SUBSEQ + 1)]
    rows.sort(key=lambda r: float(r[0].split()[-2]))
    print(f"seed {seed}, {hours:g} h: {int(onset.sum())} onset captures, {int(oth.sum())} Other captures; threshold {thr}")
    print("")
    print("| point | onset accuracy | onsets alerting right / wrong | Other captures alerting |")
    print("|---|---:|---:|---:|")
    for name, p in rows:
        top, conf = p.argmax(1), p.max(1)
        al = (top != other) & (conf >= thr)
        print(f"| {name} | {np.mean(top[onset] == y[onset]):.3f} | {np.mean(al[onset] & (top[onset] == y[onset])):.3f} / "
              f"{np.mean(al[onset] & (top[onset] != y[onset])):.3f} | {np.mean(al[oth]):.3f} |")


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]))
