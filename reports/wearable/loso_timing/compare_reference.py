"""Saved LOSO folds against an earlier run's: bit-identical predictions (pooled predictions.npz of the
earlier run, split by subject) and weights (its folds/s<K>/model.pt)?

    PYTHONPATH=. python reports/wearable/loso_timing/compare_reference.py REF_DIR [NEW_DIR]

REF_DIR and NEW_DIR hold <arch>/loso/ (NEW_DIR defaults to reports/wearable)."""
import sys
from pathlib import Path

import numpy as np
import torch

ref_dir = Path(sys.argv[1])
new_dir = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("reports/wearable")
for arch in ("convlstm", "cnn", "lstm"):
    ref_file = ref_dir / arch / "loso" / "predictions.npz"
    if not ref_file.exists():
        continue
    ref = np.load(ref_file)
    folds = sorted((new_dir / arch / "loso" / "folds").glob("s*"), key=lambda p: int(p.name[1:]))
    for d in folds:
        mine = ref["subject"] == int(d.name[1:])
        if not (d / "result.json").exists() or not mine.any():
            continue
        r = np.load(d / "result.npz")
        same = (np.array_equal(ref["probs"][mine], r["probs"].astype(np.float32))
                and np.array_equal(ref["y_pred"][mine], r["y_pred"]))
        if "step_raw" in r.files:  # the ConvLSTM's early decisions, raw and temperature-scaled
            same = (same and np.array_equal(ref["step_probs_raw"][:, mine], r["step_raw"].astype(np.float32))
                    and np.array_equal(ref["step_probs"][:, mine], r["step_calibrated"].astype(np.float32)))
        a = torch.load(ref_dir / arch / "loso" / "folds" / d.name / "model.pt", weights_only=False)["state_dict"]
        b = torch.load(d / "model.pt", weights_only=False)["state_dict"]
        print(f"{arch} {d.name}: predictions identical {bool(same)}, weights identical "
              f"{all(torch.equal(a[k], b[k]) for k in a)}")
