"""Session 21 (issue 12): the alert policy over the streaming model's outputs, scored by drive-eval's own scorer.

    PYTHONPATH=. python reports/wearable/stream_s21/policy.py sweep MODEL.pt SEED OUT.json
    PYTHONPATH=. python reports/wearable/stream_s21/policy.py one MODEL.pt SEED OUT.json --choice CHOICE.json

The policy, every hop (a multiple of the cached 0.12 s):

* score: ``top``, the largest distraction probability, or ``any``, 1 - P(Other) (the sum over distractions);
* an alert event opens when the score is >= ``thr`` on ``k`` consecutive hops; its class is the distraction with
  the largest summed probability over those k hops. The alert's frame goes out at the last of them (t_alert_s: the
  time of the last raw frame the decision saw);
* the event is one distraction: no new alert while it is open. It closes when P(Other) >= 0.5 on every hop of
  ``off_s`` seconds; only then can a new alert open.

Scoring: :class:`firmware_sim.scenarios.drive_eval.ModeScore`, attribution "frame" (drive-eval's headline), on the
drives cached by ``data.py`` (drive-eval's 20 h of that seed). A streaming alert has no detector trigger; its
decision dict gets ``t_trigger_s = t_alert_s + MATCH_BEFORE_S``, so that the scorer's trigger rule ("the trigger
falls 1 s before the start to the end") credits an alert to a distraction exactly when its frame goes out between
the distraction's start and its end - 1 s, and the frame rule (start + 1.155 s to the end) covers the rest: an
alert is the distraction's iff it went out while the distraction lasted. An alert before the onset is a false alert
(it cannot have seen the distraction), one after the end too.

``sweep`` writes every (W, hop, score, k, thr, off_s) point; ``one`` scores a frozen choice (seed 5: the check).
Selection rule (fixed before the first sweep, applied on seed 1 only; :func:`choose`).
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import DEFAULT_DIR, load_streams  # noqa: E402
from probs import probs_path  # noqa: E402

from edge_runtime.wearable.detector import DetectorConfig  # noqa: E402
from edge_runtime.wearable.labels import CLASSES, OTHER  # noqa: E402
from firmware_sim.scenarios.drive_eval import MATCH_BEFORE_S, Drive, ModeScore  # noqa: E402

I_OTHER = CLASSES.index(OTHER)
BASE_HOP_S = 0.12
MUST = {"median_s": 2.0, "p95_s": 3.5, "recall": 0.95, "class": 0.90, "false_per_h": 0.5}


@dataclass(frozen=True)
class Policy:
    window_s: float
    hop_mult: int
    score: str
    k: int
    thr: float
    off_s: float = 1.0

    @property
    def hop_s(self) -> float:
        return round(self.hop_mult * BASE_HOP_S, 3)


def runs_at_least(mask: np.ndarray, n: int) -> np.ndarray:
    """True at i when mask[i - n + 1 .. i] are all True."""
    if n <= 1:
        return mask.copy()
    c = np.concatenate([[0], np.cumsum(mask)])
    out = np.zeros_like(mask)
    out[n - 1:] = (c[n:] - c[:-n]) == n
    return out


def alerts(t: np.ndarray, p: np.ndarray, pol: Policy) -> list[dict]:
    """The alert decisions (drive-eval's decision dicts) of one drive; ``t``, ``p``: the cached outputs."""
    t, p = t[::pol.hop_mult], p[::pol.hop_mult]
    dis = p[:, :I_OTHER]
    score = dis.max(1) if pol.score == "top" else 1.0 - p[:, I_OTHER]
    opens = np.flatnonzero(runs_at_least(score >= pol.thr, pol.k))
    closes = np.flatnonzero(runs_at_least(p[:, I_OTHER] >= 0.5, max(1, int(np.ceil(pol.off_s / pol.hop_s)))))
    out, i = [], 0
    while True:
        j = np.searchsorted(opens, i)
        if j >= len(opens):
            return out
        o = opens[j]
        label = CLASSES[int(dis[o - pol.k + 1:o + 1].sum(0).argmax())]
        ta = round(float(t[o]), 3)
        out.append({"status": "preliminary", "alerted": True, "alert_seq": len(out) + 1, "event_start_s": ta,
                    "t_trigger_s": ta + MATCH_BEFORE_S, "t_alert_s": ta, "label": label, "steps": 0,
                    "confidence": round(float(score[o]), 3)})
        c = np.searchsorted(closes, o + 1)
        # the event's end (its close, or the drive's end): the hybrid merges the shipped alerts inside it
        out[-1]["event_end_s"] = round(float(t[closes[c]] if c < len(closes) else t[-1]), 3)
        if c >= len(closes):
            return out
        i = closes[c] + 1


def figures(score: ModeScore) -> dict:
    d = score.as_dict()
    return {"recall": d["event_recall"], "class": d["first_alert_class_accuracy"],
            "median_s": d["onset_to_first_alert_s"]["median"], "p95_s": d["onset_to_first_alert_s"]["p95"],
            "false_per_h": d["false_alerts_per_hour"], "false": d["false_alerts"], "repeat": d["repeat_alerts"],
            "late": d["first_alerts_after_the_distraction_ended"], "distractions": d["distractions"],
            "hours": d["driving_hours"]}


def meets(f: dict) -> dict:
    return {"median_s": f["median_s"] is not None and f["median_s"] <= MUST["median_s"],
            "p95_s": f["p95_s"] is not None and f["p95_s"] <= MUST["p95_s"],
            "recall": f["recall"] >= MUST["recall"], "class": (f["class"] or 0) >= MUST["class"],
            "false_per_h": f["false_per_h"] <= MUST["false_per_h"]}


def score_drives(drives: list[dict], decisions: list[list[dict]]) -> tuple[dict, list[float]]:
    """drive-eval's ModeScore (frame) over the drives; also every first alert's onset -> alert (s)."""
    s = ModeScore(attribution="frame", detector=DetectorConfig())
    for d, dec in zip(drives, decisions):
        s.add(Drive(d["name"], d["acc_mps2"], d["events"], d["kind"]), dec)
    return figures(s), list(s.onset_to_alert_s)


def choose(points: list[dict]) -> dict:
    """Fixed before the first sweep: among the points with false alerts <= 0.5 / h and first-alert class >= 0.90
    (the alert-quality must-holds), the one meeting most of the other three must-holds (recall, median, p95),
    then the lowest p95, then the highest recall. If none has both, the point meeting most must-holds, then the
    fewest false alerts per hour, then the lowest p95."""
    def n_met(f):
        return sum(meets(f).values())
    ok = [q for q in points if meets(q["figures"])["false_per_h"] and meets(q["figures"])["class"]]
    if ok:
        return min(ok, key=lambda q: (-n_met(q["figures"]), q["figures"]["p95_s"], -q["figures"]["recall"]))
    return min(points, key=lambda q: (-n_met(q["figures"]), q["figures"]["false_per_h"], q["figures"]["p95_s"]))


def load_probs(model: str, seed: int, window_s: float, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The cached outputs of ``model``; "A.pt+B.pt": the mean of several models' probabilities (an ensemble)."""
    zs = [np.load(probs_path(m, seed, window_s)) for m in model.split("+")]
    return [(zs[0][f"t{k}"], np.mean([z[f"p{k}"] for z in zs], axis=0)) for k in range(n)]


GRID = {"window_s": (2.0, 3.0, 4.0), "hop_mult": (2, 3, 4), "score": ("top", "any"), "k": (1, 2, 3),
        "thr": (0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98), "off_s": (1.0, 2.0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("sweep", "one"))
    ap.add_argument("model")
    ap.add_argument("seed", type=int)
    ap.add_argument("out")
    ap.add_argument("--choice", help="one: the JSON whose 'chosen' policy is scored")
    ap.add_argument("--windows", default=None, help="sweep: W values (default the grid's)")
    a = ap.parse_args(argv)
    drives = load_streams(DEFAULT_DIR / f"drives_seed{a.seed}")
    if a.what == "one":
        pol = Policy(**json.loads(Path(a.choice).read_text())["chosen"]["policy"])
        cache = load_probs(a.model, a.seed, pol.window_s, len(drives))
        f, lat = score_drives(drives, [alerts(t, p, pol) for t, p in cache])
        # the threshold trade-off around the frozen choice: every other setting as chosen
        trade = []
        for thr in GRID["thr"]:
            q = Policy(**{**pol.__dict__, "thr": thr})
            trade.append({"thr": thr, "figures": score_drives(drives, [alerts(t, p, q) for t, p in cache])[0]})
        res = {"seed": a.seed, "model": a.model, "policy": pol.__dict__, "figures": f, "meets": meets(f),
               "onset_to_alert_lt_0_3_s": int(sum(x < 0.3 for x in lat)), "tradeoff_thr": trade}
        Path(a.out).write_text(json.dumps(res, indent=1))
        print(json.dumps({k: res[k] for k in ("policy", "figures", "meets")}, indent=1))
        return 0
    windows = GRID["window_s"] if a.windows is None else tuple(float(v) for v in a.windows.split(","))
    points = []
    for w in windows:
        cache = load_probs(a.model, a.seed, w, len(drives))
        for hop, sc, k, thr, off in itertools.product(*(GRID[g] for g in ("hop_mult", "score", "k", "thr", "off_s"))):
            pol = Policy(w, hop, sc, k, thr, off)
            f, _ = score_drives(drives, [alerts(t, p, pol) for t, p in cache])
            points.append({"policy": pol.__dict__, "figures": f})
        print(f"W {w:g}: {len(points)} points", flush=True)
    best = choose(points)
    Path(a.out).write_text(json.dumps({"seed": a.seed, "model": a.model, "rule": choose.__doc__,
                                       "chosen": best, "points": points}, indent=1))
    print("chosen:", json.dumps(best, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
