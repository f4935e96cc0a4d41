"""s10-step2: the step as the live loop now calls it (Engine.advance -> StepModel.step, batch 1 through the IOBinding)
against the public session.run (what an onnxruntime without the private calls gets), on every test capture of the
shipped model (/work/s9-runs/assets-seed0/data/test.npz), one capture at a time through S = 1..6: probabilities
compared bit for bit, decisions counted. s11-replay: the loop's call is now Engine.advance -> StepModel.step_stream
(the state kept in the bound buffers, ``call_path`` below); the public engine has every private path turned off."""
import json, os, sys
import numpy as np
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.classifier import Engine, needed_frames
from models.dataset import load_npz
X = load_npz(sys.argv[1]).X.astype(np.float32)
out = {"data": sys.argv[1], "captures": int(len(X))}
for p in ("fp32", "int8"):
    bound, public = Engine.from_manifest(ASSETS_DIR, p), Engine.from_manifest(ASSETS_DIR, p)
    assert bound.step_model.bound
    public.step_model._run, public.step_model._step_one = public.step_model.session.run, None
    public.step_model._chain = None
    out["call_path"] = bound.step_model.call_path
    equal = changed = 0
    for x in X:
        sb, sp = bound.new_stream(), public.new_stream()
        for s in range(1, 7):
            a, b = bound.advance(sb, x[:needed_frames(s)], s), public.advance(sp, x[:needed_frames(s)], s)
            equal += bool(np.array_equal(a, b))
            changed += int(a.argmax() != b.argmax())
    out[p] = {"decisions": 6 * len(X), "bit_identical": equal, "class_changed": changed}
    print(p, out[p])
out["load_average"] = os.getloadavg()
json.dump(out, open(sys.argv[2], "w"), indent=1)
