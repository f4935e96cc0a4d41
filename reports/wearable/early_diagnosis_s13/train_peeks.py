"""Stage 1 (b): the shipped model's recipe (seed, epochs, schedule, augmentation, data: the training cohort, seed 0)
retrained with deep supervision over partial sub-windows too (``models.train.fit(peek_frames=...)``).

    PYTHONPATH=. python reports/wearable/early_diagnosis_s13/train_peeks.py TRAIN_NPZ TEST_NPZ OUT_DIR [K,K,...]

TRAIN_NPZ / TEST_NPZ: the training cohort's ground-truth windows and detector captures (what
``python -m export assets --seed 0`` writes to its work directory's data/); K: the peek lengths in resampled
frames (default 11,22). Writes OUT_DIR/model.pt.
"""
import sys
import time

import numpy as np

from models.dataset import load_npz
from models.selection import load_recipe, training_arrays
from models.train import fit, recipe_fit_kwargs, save_checkpoint


def main(train_npz, test_npz, out, frames=(11, 22)):
    recipe = load_recipe(None)
    train, test = load_npz(train_npz), load_npz(test_npz)
    X, y = training_arrays(train, test if recipe["captures"] else None, np.unique(train.subject))
    t = time.time()
    model = fit("convlstm", X, y, len(train.classes), epochs=recipe["epochs"], seed=0, progress=False,
                peek_frames=frames, **recipe_fit_kwargs(recipe))
    print(f"trained on {len(y)} windows, {recipe['epochs']} epochs, peeks {frames}: {time.time() - t:.0f} s", flush=True)
    save_checkpoint(out, model, arch="convlstm", classes=list(train.classes), seed=0, epochs=recipe["epochs"],
                    metrics={}, data={"train": train_npz, "test": test_npz, "peek_frames": list(frames)})


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3],
         tuple(int(k) for k in sys.argv[4].split(",")) if len(sys.argv) > 4 else (11, 22))
