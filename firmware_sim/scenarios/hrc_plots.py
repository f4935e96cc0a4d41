"""Fig. 3.8 of the dissertation for ``python -m firmware_sim hrc --plot``: top-down (x-z) paths.

One panel per scenario (up to 6): every worker's true head path coloured by the runtime's state
(green NORMAL, orange LEVEL1, red LEVEL2, grey FAULT), the end effector's path (black, arrow at
its end), the base (a square at the origin), and, for the head zones, both zone radii (R1
dashed, R2 solid) drawn around the end effector where it was when the worker started. Below
each panel, the hand's speed over time and its speed limit while it works (whole-body speed and
separation monitoring). With more scenarios, one panel overlays every head path (faint;
collisions in red). matplotlib with the Agg backend.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

STATE_COLOURS = {0: "tab:green", 1: "tab:orange", 2: "0.6", 3: "tab:red"}
MAX_PANELS = 6


def _panel(ax, res, zones: dict) -> None:
    import matplotlib.patches as mpatches

    s = res.summary
    heads, ee = res.head_xz_m, res.ee_xz_m
    if len(heads):
        colours = [STATE_COLOURS.get(int(k), "k") for k in res.state]
        for w in range(heads.shape[1]):
            head = heads[:, w]
            seen = ~np.isnan(head[:, 0])
            ax.scatter(head[seen, 0], head[seen, 1], c=[c for c, k in zip(colours, seen) if k], s=3,
                       label="worker heads" if w == 0 else None)
            last = np.flatnonzero(seen)
            if len(last):
                ax.annotate(f"{w + 1}", head[last[-1]], fontsize=8, color="tab:blue")
        ax.plot(ee[:, 0], ee[:, 1], "k-", lw=1.5, label="end effector")
        ax.annotate("", ee[-1], ee[max(0, len(ee) - 5)], arrowprops=dict(arrowstyle="->"))
        if zones.get("separation", "head") == "head":
            for r, ls in ((zones["r1_m"], "--"), (zones["r2_m"], "-")):
                ax.add_patch(mpatches.Circle(ee[0], r, fill=False, ls=ls, color="tab:purple", lw=0.8))
    ax.add_patch(mpatches.Rectangle((-0.15, -0.15), 0.3, 0.3, color="0.3"))
    if s["min_separation_m"] is None:
        verdict = s.get("not_run", "not run")
    else:
        verdict = f"{'COLLISION' if s['collision'] else 'no collision'}, min sep {s['min_separation_m']:.2f} m"
    ax.set_title(f"{s['name']} ({s['speed_mps']:.1f} m/s): {verdict}", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.grid(alpha=0.3)


def _speed(ax, res) -> None:
    """The hand's true speed and its speed limit while the arm works (0: held), over time."""
    if len(res.speed_mps):
        top = max(0.65, float(np.max(res.speed_mps)) * 1.05)
        for k, colour in STATE_COLOURS.items():  # the runtime's state behind the curves, as in the panel above
            if k:
                ax.fill_between(res.t_s, 0, top, where=res.state == k, color=colour, alpha=0.15, lw=0)
        ax.plot(res.t_s, res.speed_mps, "k-", lw=1.0, label="hand speed")
        ax.plot(res.t_s, res.limit_mps, color="tab:green", lw=1.0, ls="--", label="speed limit at work (0: held)")
        ax.legend(fontsize=6, loc="upper right")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("m/s")
    ax.grid(alpha=0.3)


def _overlay(ax, results, zones: dict) -> None:
    import matplotlib.patches as mpatches

    for res in results:
        if len(res.head_xz_m):
            hit = res.summary["collision"]
            for w in range(res.head_xz_m.shape[1]):
                ax.plot(res.head_xz_m[:, w, 0], res.head_xz_m[:, w, 1], color="tab:red" if hit else "tab:blue",
                        alpha=0.9 if hit else 0.25, lw=1.2 if hit else 0.6)
            ax.plot(res.ee_xz_m[:, 0], res.ee_xz_m[:, 1], "k-", lw=0.5, alpha=0.4)
    for r, ls in ((zones["r1_m"], "--"), (zones["r2_m"], "-")):
        ax.add_patch(mpatches.Circle((0.0, 1.0), r, fill=False, ls=ls, color="tab:purple", lw=0.8))
    ax.add_patch(mpatches.Rectangle((-0.15, -0.15), 0.3, 0.3, color="0.3"))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.grid(alpha=0.3)
    ax.set_title(f"{len(results)} approaches: head paths (red: collision), end effector (black)", fontsize=8)


def plot_runs(results, out: dict, path) -> Path:
    """Write the figure for ``results`` (RunResult list) of run ``out`` (the JSON) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    zones = out["zones"]
    if len(results) <= MAX_PANELS:
        fig, axes = plt.subplots(2, len(results), figsize=(max(4.6 * len(results), 8.0), 6.6), squeeze=False,
                                 gridspec_kw={"height_ratios": [3, 1]})
        for ax, sp, res in zip(axes[0], axes[1], results):
            _panel(ax, res, zones)
            _speed(sp, res)
        axes[0][0].legend(fontsize=7, loc="lower left")
    else:
        fig, ax = plt.subplots(figsize=(7, 7))
        _overlay(ax, results, zones)
    radii = (f"R1 {zones['r1_m']:.1f} m (dashed), R2 {zones['r2_m']:.1f} m" if zones.get("separation") == "head"
             else f"whole-body separation, {out.get('protection', '')}")
    fig.suptitle(f"hrc: {out['link']} link, camera {out['camera_hz']:g} Hz, perception {out['perception']}, "
                 f"runtime {'on' if out['runtime'] else 'off'}; {radii}", fontsize=9)
    fig.tight_layout()
    p = Path(path)
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p
