"""The step path as the box runs it (Engine.classify_prefixes: sub-window s from the first needed_frames(s) frames, then
the step model), on the shipped model's test captures (/work/s9-runs/assets-seed0/data/test.npz, the manifest's
cohort): int8 vs fp32 macro-F1 and class agreement after every S; and the stream vs the one-shot model on the
same prefixes (fp32: the difference is sub-window 1's mean-padded frames, fixed when it arrived)."""
import json, os, sys
import numpy as np
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.classifier import Engine, needed_frames
from export.quantize import _macro_f1
from models.dataset import load_npz
test = load_npz(sys.argv[1])
X, y = test.X.astype(np.float32), test.y
E = {(p, st): Engine.from_manifest(ASSETS_DIR, p, stream=st) for p in ("fp32", "int8") for st in (True, False)}
out = {"data": sys.argv[1], "n": int(len(X)), "by_steps": {}}
for s in range(1, 7):
    P = {k: np.concatenate([e.classify_prefixes(X[i:i + 256, :needed_frames(s)], s) for i in range(0, len(X), 256)]).argmax(1) for k, e in E.items()}
    r = {"macro_f1": {f"{p}_{'stream' if st else 'one_shot'}": round(_macro_f1(y, P[p, st]), 4) for p, st in P},
         "int8_vs_fp32_agreement_stream": round(float(np.mean(P["int8", True] == P["fp32", True])), 4),
         "int8_vs_fp32_agreement_one_shot": round(float(np.mean(P["int8", False] == P["fp32", False])), 4),
         "stream_vs_one_shot_agreement_fp32": round(float(np.mean(P["fp32", True] == P["fp32", False])), 4),
         "stream_vs_one_shot_agreement_int8": round(float(np.mean(P["int8", True] == P["int8", False])), 4)}
    r["int8_minus_fp32_macro_f1_stream"] = round(r["macro_f1"]["int8_stream"] - r["macro_f1"]["fp32_stream"], 4)
    out["by_steps"][s] = r
    print(s, json.dumps(r))
out["load_average"] = os.getloadavg()
json.dump(out, open(sys.argv[2], "w"), indent=1)
