"""Session 21 (issue 12): cache the continuous streams a trigger-free classifier trains and is measured on.

    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s21/data.py cohort [OUT_DIR]
    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s21/data.py drives SEED [OUT_DIR]

* ``cohort``: the training cohort the shipped ConvLSTM trains on (``simulate_cohort(20, seed=0, 15 min)``, what
  ``models.dataset.build_cohort_datasets(20, 0, 15.0)`` windows), kept as whole recordings (not detector windows):
  OUT_DIR/cohort_seed0.npz (the 120 recordings end to end, one row per 100 Hz frame, with the recording index) and
  OUT_DIR/cohort_seed0.json (every recording's truth events, times relative to that recording).
* ``drives SEED``: drive-eval's drives of that seed, 20 h as drive-eval builds them (``held_out_drives(20, SEED)``:
  28 distraction drives and 12 baseline drives of 30 min) -> OUT_DIR/drives_seedSEED.npz / .json. Development seeds
  only (1 chooses, 5 checks once): the script refuses the spent ones.

Default OUT_DIR: /work/s9-runs/stream21 (not committed: about 100 MB per 20 h).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

DEFAULT_DIR = Path("/work/s9-runs/stream21")
DRIVE_HOURS = 20.0
ALLOWED_DRIVE_SEEDS = (1, 5)
"""Development drive seeds (preamble): seed 2, 62 and 72+ are held out or spent."""


def save_streams(out: Path, name: str, recs: list[tuple[str, np.ndarray, list[dict], str]]) -> None:
    """Recordings (name, acc (n, 3), events, kind) -> OUT/name.npz (acc end to end, and each recording's start row)
    and OUT/name.json (names, kinds, events)."""
    starts = np.cumsum([0] + [len(a) for _, a, _, _ in recs])
    np.savez(out / f"{name}.npz", acc_mps2=np.concatenate([a for _, a, _, _ in recs]).astype(np.float32),
             starts=starts)
    meta = [{"name": n, "kind": k, "events": ev} for n, _, ev, k in recs]
    (out / f"{name}.json").write_text(json.dumps(meta))


def load_streams(path_stem: Path) -> list[dict]:
    """The recordings saved by :func:`save_streams`: dicts with name, kind, events, acc_mps2."""
    z = np.load(f"{path_stem}.npz")
    meta = json.loads(Path(f"{path_stem}.json").read_text())
    acc, starts = z["acc_mps2"], z["starts"]
    for k, m in enumerate(meta):
        m["acc_mps2"] = acc[starts[k]:starts[k + 1]]
    return meta


def main(argv: list[str]) -> int:
    what = argv[0]
    if what == "cohort":
        from firmware_sim.devices.wrist import simulate_cohort

        out = Path(argv[1]) if len(argv) > 1 else DEFAULT_DIR
        recs = [(f"subject {r.subject_id} {r.trial}", r.acc_mps2, [e.to_json() for e in r.events], r.trial)
                for r in simulate_cohort(20, seed=0, minutes_per_trial=15.0)]
        name = "cohort_seed0"
    elif what == "drives":
        from firmware_sim.scenarios.drive_eval import held_out_drives

        seed = int(argv[1])
        if seed not in ALLOWED_DRIVE_SEEDS:
            raise SystemExit(f"drive seed {seed}: only development seeds {ALLOWED_DRIVE_SEEDS}")
        out = Path(argv[2]) if len(argv) > 2 else DEFAULT_DIR
        recs = [(d.name, d.acc_mps2, d.events, d.kind) for d in held_out_drives(DRIVE_HOURS, seed)]
        name = f"drives_seed{seed}"
    else:
        raise SystemExit(__doc__)
    out.mkdir(parents=True, exist_ok=True)
    save_streams(out, name, recs)
    hours = sum(len(a) for _, a, _, _ in recs) / 100 / 3600
    print(f"{name}: {len(recs)} recordings, {hours:.1f} h -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
