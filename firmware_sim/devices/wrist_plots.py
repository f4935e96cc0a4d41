"""PNG of a simulated drive: the wrist IMU trace, truth events shaded, detector triggers marked."""
from __future__ import annotations

import os

import numpy as np

from edge_runtime.wearable.labels import CLASSES
from firmware_sim.devices.wrist import Recording

_COLOURS = {"Phone": "tab:red", "Texting": "tab:orange", "TouchScreen": "tab:purple", "Drink": "tab:blue",
            "Marker": "tab:green", "Other": "tab:gray"}


def plot_drive(rec: Recording, triggers: np.ndarray, path: str | os.PathLike, threshold_mps2: float = 5.0) -> None:
    import matplotlib  # lazily: only --plot needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    t = rec.t_s
    a = rec.acc_mps2
    width = float(np.clip(rec.duration_s / 30.0, 10, 40))
    fig, axes = plt.subplots(3, 1, figsize=(width, 7), sharex=True)
    for k, (ax, name) in enumerate(zip(axes, ("ax", "ay", "az"))):
        ax.plot(t, a[:, k], lw=0.5, color="k")
        ax.set_ylabel(f"{name} (m/s²)")
        for e in rec.events:
            ax.axvspan(e.start_s, e.end_s, color=_COLOURS.get(e.label, "tab:gray"), alpha=0.25, lw=0)
        for tr in np.asarray(triggers) / rec.sample_rate_hz:
            ax.axvline(tr, color="red", lw=0.8, ls="--")
    axes[0].set_title(f"simulated wrist IMU: subject {rec.subject_id}, {rec.trial}; "
                      f"dashed: detector triggers (|Δax over 2 s| > {threshold_mps2:g} m/s²)")
    axes[-1].set_xlabel("t (s)")
    handles = [Patch(color=_COLOURS[c], alpha=0.4, label=c) for c in CLASSES]
    axes[0].legend(handles=handles, loc="upper right", ncol=6, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
