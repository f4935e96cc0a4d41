"""Phone onsets split by the simulator's look_first, Texting by position: the 1D CNN prefix model and the ConvLSTM.
PYTHONPATH=/work/main python /work/notes/s12-w/lookfirst.py > /work/notes/s12-w/lookfirst.md"""
import json

import numpy as np

z = np.load("/tmp/s12w/sel.npz")
y, rep = z["y"], z["repeat"]
det = [json.loads(d) for d in z["detail"]]
onset = (y != 5) & (rep == 0)
P = dict(np.load("/work/notes/s12-w/prefix_latency_probs.npz"))
cnn, conv = P["1D CNN (prefix, 25 Hz)"], np.load("/work/notes/s12-w/per_s_probs.npz")["probs"]
groups = {"Phone, look_first": [i for i in np.flatnonzero(onset & (y == 0)) if det[i].get("look_first")],
          "Phone, straight to ear/speaker": [i for i in np.flatnonzero(onset & (y == 0)) if not det[i].get("look_first")],
          "Texting, front": [i for i in np.flatnonzero(onset & (y == 1)) if det[i].get("position") == "front"],
          "Texting, side": [i for i in np.flatnonzero(onset & (y == 1)) if det[i].get("position") == "side"]}
print("# Phone / Texting onsets by what the simulator did: right / called the other phone class\n")
cols = [("CNN 1.0 s", cnn[2]), ("CNN 1.62 s", cnn[4]), ("CNN 2.0 s", cnn[5]), ("CNN 2.78 s", cnn[6]), ("CNN 3.93 s", cnn[7]),
        ("CNN 5.99 s", cnn[8]), ("ConvLSTM S=2", conv[1]), ("ConvLSTM S=3", conv[2]), ("ConvLSTM S=4", conv[3]), ("ConvLSTM S=6", conv[5])]
print("| group | n | " + " | ".join(c for c, _ in cols) + " |")
print("|---|---:|" + "---|" * len(cols))
for g, idx in groups.items():
    idx = np.asarray(idx)
    other_phone = 1 if g.startswith("Phone") else 0
    print(f"| {g} | {len(idx)} | " + " | ".join(f"{np.mean(p[idx].argmax(1) == y[idx]):.2f} / {np.mean(p[idx].argmax(1) == other_phone):.2f}"
                                            for _, p in cols) + " |")
dur = np.array([det[i]["duration_s"] for i in groups["Phone, look_first"]])
print(f"\nShare of Phone onsets with look_first: {len(groups['Phone, look_first'])} of "
      f"{len(groups['Phone, look_first']) + len(groups['Phone, straight to ear/speaker'])}")
