"""Where the shipped anchoring's p95 head error comes from (s17 headtail, step 1).

    PYTHONPATH=. python reports/robot/s17_headtail/diagnose.py --cache /tmp/headtail --seeds 4 13 17 19 --method truth

Replays each cached placement through the shipped ``Calibration.to_robot`` and splits the ground-projected
head error and the applied factor's log error (against the factor that puts the pelvis at its true range)
by distance, camera height, motion, time structure (per-placement bias, slow drift, frame-to-frame) and by
which ankle anchored the frame (and whether it was the foot truly lower).
"""
from __future__ import annotations

import numpy as np
from common import ankle_choice, cache_arguments, load, replay

from edge_runtime.core.skeleton import HIP, L_ANKLE, R_ANKLE
from edge_runtime.robot.calibration import anchor_factor

SMOOTH_FRAMES = 31   # "slow" part of the error: a centred 1-s moving average


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    pad = np.pad(x, n // 2, mode="edge")
    return np.convolve(pad, np.ones(n) / n, mode="valid")


def per_frame(p: dict) -> dict:
    r = replay(p)
    cal, J, obs, truth = p["cal"], p["joints"], p["observed"], p["truth_m"]
    choice, lower_ok, ks = [], [], []
    for i in r["idx"]:
        c = ankle_choice(J[i], cal.A, obs[i])
        k, reason = anchor_factor(J[i], cal.A, cal.b, cal.params, obs[i])
        choice.append(c if reason is None else reason)
        ks.append(k)
        dy = truth[i, L_ANKLE, 1] - truth[i, R_ANKLE, 1]
        truly = "level" if abs(dy) < 0.03 else ("L" if dy < 0 else "R")
        lower_ok.append("level" if truly == "level" else ("both" if c == "both" else ("right" if c == truly else "wrong")))
    r["choice"], r["truly_lower"] = np.array(choice), np.array(lower_ok)
    # the per-frame (unfiltered) factor's log error: log k_frame - log k_true
    log_k_true = np.log(np.linalg.norm(truth[r["idx"], HIP] - cal.b, axis=1)
                        / np.linalg.norm(J[r["idx"], HIP] @ cal.A.T, axis=1))
    r["frame_log_err"] = np.log(np.array(ks)) - log_k_true
    return r


def pct(x, q=95):
    return float(np.percentile(x, q)) if len(x) else float("nan")


def main() -> None:
    ap = cache_arguments(__doc__)
    a = ap.parse_args()
    rows = []
    for s in a.seeds:
        for n, p in enumerate(load(a.cache, s, a.method)):
            r = per_frame(p)
            r["placement"] = np.full(len(r["err"]), s * 1000 + n)
            rows.append(r)
    cat = {k: np.concatenate([r[k] for r in rows]) for k in rows[0] if k != "idx"}
    err, far, le = cat["err"], cat["farther"], cat["log_k_err"]
    p95 = pct(err)
    tail = err > p95
    print(f"# seeds {a.seeds}, calibration {a.method}: {len(err)} frames, ground error median {np.median(err):.3f} "
          f"p95 {p95:.3f} m; farther > 0 / 0.1 / 0.3: {np.mean(far > 0):.3f} / {np.mean(far > 0.1):.3f} / "
          f"{np.mean(far > 0.3):.3f}")

    def split(name, groups):
        print(f"\n## by {name}: group | share of frames | share of p95 tail | median / p95 error (m) | "
              f"factor log error mean / sd")
        for g, m in groups:
            if m.sum():
                print(f"{g:>14} | {m.mean():.3f} | {tail[m].sum() / tail.sum():.3f} | {np.median(err[m]):.3f} / "
                      f"{pct(err[m]):.3f} | {le[m].mean():+.3f} / {le[m].std():.3f}")

    split("true ground distance (m)", [(f"{lo}-{lo + 1}", (cat["dist"] >= lo) & (cat["dist"] < lo + 1))
                                       for lo in range(3, 8)])
    split("camera height (m)", [(f"{lo:.1f}-{lo + 0.5:.1f}", (cat["cam_h"] >= lo) & (cat["cam_h"] < lo + 0.5))
                                for lo in np.arange(1.0, 3.01, 0.5)])
    ratio = cat["cam_h"] / cat["dist"]
    split("camera height / distance (tan of the ankle ray's depression, roughly)",
          [(f"{lo:.2f}-{hi:.2f}", (ratio >= lo) & (ratio < hi)) for lo, hi in
           ((0, 0.2), (0.2, 0.3), (0.3, 0.45), (0.45, 2))])
    split("motion (true pelvis speed > 0.3 m/s = walking)", [("walking", cat["walking"]), ("still", ~cat["walking"])])
    split("activity label", [(str(lab), cat["label"] == lab) for lab in np.unique(cat["label"])])
    split("the frame's own anchor (per-frame choice)", [(c, cat["choice"] == c) for c in np.unique(cat["choice"])])
    split("was the frame's single ankle the truly lower foot (truth, 3 cm)",
          [(c, cat["truly_lower"] == c) for c in np.unique(cat["truly_lower"])])
    fe = cat["frame_log_err"]
    print("\n## per-frame (unfiltered) factor log error by the frame's own choice: mean / sd / p95 of |.|")
    for c in np.unique(cat["truly_lower"]):
        m = cat["truly_lower"] == c
        print(f"{c:>8}: {m.mean():.3f} of frames, {fe[m].mean():+.3f} / {fe[m].std():.3f} / {pct(np.abs(fe[m])):.3f}")

    # time structure of the applied factor's log error
    pl = cat["placement"]
    bias = np.zeros_like(le)
    slow = np.zeros_like(le)
    for q in np.unique(pl):
        m = pl == q
        bias[m] = le[m].mean()
        slow[m] = _moving_average(le[m] - bias[m], SMOOTH_FRAMES)
    fast = le - bias - slow
    v = le.var()
    print(f"\n## applied factor's log error (sd {le.std():.3f}, mean {le.mean():+.3f}): variance shares: "
          f"per-placement bias {bias.var() / v:.2f}, slow (1-s average) {slow.var() / v:.2f}, "
          f"frame-to-frame {fast.var() / v:.2f}")
    fle = cat["frame_log_err"]
    fb = np.array([fle[pl == q].mean() for q in pl])
    print(f"   per-frame factor's log error sd {fle.std():.3f}; its per-placement bias share {fb.var() / fle.var():.2f}")
    # tail frames: placements and runs
    per_pl = {q: tail[pl == q].sum() for q in np.unique(pl)}
    counts = np.sort(np.array(list(per_pl.values())))[::-1]
    n_pl = len(counts)
    print(f"   tail frames in the worst 10% / 25% of placements: {counts[:max(1, n_pl // 10)].sum() / tail.sum():.2f} / "
          f"{counts[:max(1, n_pl // 4)].sum() / tail.sum():.2f} (placements with no tail frame: {np.mean(counts == 0):.2f})")
    runs = []
    for q in np.unique(pl):
        t = tail[pl == q].astype(int)
        edges = np.flatnonzero(np.diff(np.r_[0, t, 0]))
        runs += list(edges[1::2] - edges[::2])
    runs = np.array(runs)
    print(f"   tail runs (consecutive frames over p95): {len(runs)}, median length {np.median(runs):.0f} frames; "
          f"share of tail frames in runs of <= 3 frames {runs[runs <= 3].sum() / runs.sum():.3f}, of >= 30 frames "
          f"{runs[runs >= 30].sum() / runs.sum():.3f}")
    # how much of a tail frame's error is its placement's bias: the error with the bias removed
    print(f"   tail frames' factor log error: mean |total| {np.abs(le[tail]).mean():.3f}, |bias| "
          f"{np.abs(bias[tail]).mean():.3f}, |slow| {np.abs(slow[tail]).mean():.3f}, |fast| {np.abs(fast[tail]).mean():.3f}; "
          f"sign: factor too large (placed farther from the camera) in {np.mean(le[tail] > 0):.2f} of them")


if __name__ == "__main__":
    main()
