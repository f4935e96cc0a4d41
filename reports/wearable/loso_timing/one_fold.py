"""Time (and profile) one ConvLSTM LOSO fold as `python -m models report` trains it: held-out subject 1,
the selection's recipe (12 of a 24-epoch schedule, captures, shift 10), per-step temperatures on the
selection cohort. Writes OUT/model.pt and OUT/res.npz (probabilities) for compare_reference.py.

    PYTHONPATH=. nice -n 15 python reports/wearable/loso_timing/one_fold.py 12 OUT [convlstm|cnn|lstm]
    PYTHONPATH=. python -m cProfile -o OUT.prof reports/wearable/loso_timing/one_fold.py 1 OUT
"""
import sys
import time

import numpy as np

from models.dataset import load_npz
from models.experiments import _fold
from models.selection import load_recipe, selection_captures

epochs, out = int(sys.argv[1]), sys.argv[2]
arch = sys.argv[3] if len(sys.argv) > 3 else "convlstm"
train, test = load_npz("reports/wearable/data/train.npz"), load_npz("reports/wearable/data/test.npz")
job = dict(name="s1", arch=arch, epochs=epochs, seed=0, threads=1, train=train, test=test,
           train_idx=np.flatnonzero(train.subject != 1), eval_idx=np.flatnonzero(test.subject == 1),
           eval_from="test", ckpt_dir=out, desc="fold s1", progress=False, progress_folds=False,
           recipe=load_recipe(None), calib=selection_captures(None) if arch == "convlstm" else None)
t0 = time.time()
r = _fold(job)
print(f"fold s1: {time.time() - t0:.1f} s")
np.savez(f"{out}/res.npz", probs=r["probs"], y_pred=r["y_pred"],
         **({"raw": r["steps"]["raw"], "cal": r["steps"]["calibrated"]} if "steps" in r else {}))
