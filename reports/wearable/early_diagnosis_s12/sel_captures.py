"""Selection cohort (seed 1000, 12 subjects, 10 min per trial: models/selection.py) re-simulated, with the
simulator's per-event detail kept (Phone look_first, Texting position, Drink strategy, Other kind).

    PYTHONPATH=/work/main nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/sel_captures.py /tmp/s12w/sel.npz

Captures are labelled exactly as windows_from_stream in models/dataset.py does (the truth event the trigger falls
in, [start - 1 s, end], nearest start; else Other), so the counts must equal the selection cohort's test.npz.
Also saved: the trigger delay (trigger - event start) of every capture of a distraction, and the onset GT windows.
"""
import json
import sys
import time

import numpy as np

from edge_runtime.wearable.detector import DetectorConfig, detect_triggers, extract_captures
from edge_runtime.wearable.labels import CLASSES, OTHER
from firmware_sim.devices.wrist import TRIALS, make_subjects, simulate_trial

SEED, N_SUBJ, MINUTES = 1000, 12, 10.0


def main(out):
    cfg = DetectorConfig()
    X, y, subj, trial, rep, delay, detail = [], [], [], [], [], [], []
    t0 = time.time()
    for s in make_subjects(N_SUBJ, SEED):
        for tr in TRIALS:
            rec = simulate_trial(s, tr, SEED, MINUTES)
            ev = sorted(rec.events, key=lambda e: e.start_s)
            starts = np.array([e.start_s for e in ev]); ends = np.array([e.end_s for e in ev])
            caps = extract_captures(rec.acc_mps2, detect_triggers(rec.acc_mps2, cfg), cfg)
            caught = set()
            for c in caps:
                t = c.trigger_index / 100.0
                hit = np.flatnonzero((starts - 1.0 <= t) & (t <= ends))
                j = None if hit.size == 0 else int(hit[np.argmin(np.abs(starts[hit] - t))])
                X.append(c.data); subj.append(s.subject_id); trial.append(tr)
                if j is None:
                    y.append(CLASSES.index(OTHER)); rep.append(0); delay.append(np.nan); detail.append("{}")
                else:
                    e = ev[j]
                    y.append(CLASSES.index(e.label)); rep.append(int(j in caught)); caught.add(j)
                    delay.append(t - e.start_s)
                    d = dict(e.detail or {}); d["subject_phone_look_prob"] = s.phone_look_prob
                    d["subject_phone_hold"] = s.phone_hold; d["subject_texting_pos"] = s.texting_pos
                    d["duration_s"] = e.end_s - e.start_s
                    detail.append(json.dumps(d))
        print(f"subject {s.subject_id} done, {len(y)} captures, {time.time() - t0:.0f} s", flush=True)
    np.savez_compressed(out, X=np.stack(X).astype(np.float32), y=np.array(y), subject=np.array(subj),
                        trial=np.array(trial), repeat=np.array(rep), delay_s=np.array(delay),
                        detail=np.array(detail), classes=np.array(CLASSES))
    print("counts", dict(zip(CLASSES, np.bincount(y, minlength=6).tolist())), "repeats", int(np.sum(rep)))


if __name__ == "__main__":
    main(sys.argv[1])
