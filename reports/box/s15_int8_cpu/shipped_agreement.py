import sys, time, numpy as np
sys.path.insert(0, ".")
from edge_runtime.core.manifest import ASSETS_DIR, verify_all, select_model
from edge_runtime.wearable.classifier import preprocess
from export.assets import cohort_of, calibration_windows
from export.quantize import probs_of
t=time.time()
m = verify_all(ASSETS_DIR)
fp32, int8 = select_model(m, "convlstm-fp32"), select_model(m, "convlstm-int8")
train, test = cohort_of(fp32, "/tmp/s15_int8_cohort", log=print)
print("cohort", time.time()-t, flush=True)
Xte = preprocess(test.X).astype(np.float32)

p32 = probs_of(ASSETS_DIR/fp32["file"], Xte); p8 = probs_of(ASSETS_DIR/int8["file"], Xte)
print("shipped int8 agreement", (p32.argmax(1)==p8.argmax(1)).mean(), "maxabs", np.abs(p32-p8).max(), flush=True)
