"""Pooled figures of the shipped anchoring and the stance candidate (``Calibration.anchor_stance_frames``) on
cached placements: the product's own ``to_robot`` replayed, as the head-error tool runs it (s17 headtail).

    PYTHONPATH=. python reports/robot/s17_headtail/pooled.py --cache /tmp/headtail --seeds 4 13 17 19 --method pnp
"""
from __future__ import annotations

from common import cache_arguments, load, replay, summary


def main() -> None:
    ap = cache_arguments(__doc__)
    ap.add_argument("--stance-frames", type=int, nargs="+", default=[0, 90])
    a = ap.parse_args()
    placements = [p for s in a.seeds for p in load(a.cache, s, a.method)]
    for n in a.stance_frames:
        for p in placements:
            p["cal"].anchor_stance_frames = n
        rs = [replay(p) for p in placements]
        print(f"anchor_stance_frames {n}: {summary([r['err'] for r in rs], [r['farther'] for r in rs])}")


if __name__ == "__main__":
    main()
