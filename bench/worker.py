"""One bench measurement in a process of its own: ``python -m bench.worker TASK CONFIG.json OUT.json``.

A fresh process per configuration keeps peak resident memory (VmHWM) from
mixing across models and runtimes, and keeps torch out of the processes that
measure onnxruntime. :func:`run_child` starts it from the parent (CPU pinning
from ``--cpus`` is inherited) and returns the JSON result.

Tasks: ``inference`` (:func:`bench.inference.measure`), ``wearable``
(:func:`bench.loops.measure_wearable`), ``robot`` (:func:`bench.robot_cycle.measure_robot`).
"""
from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


class ChildFailed(RuntimeError):
    """A measurement process exited with an error; the message holds its last stderr line."""


TASKS = {"inference": ("bench.inference", "InferenceConfig", "measure"),
         "wearable": ("bench.loops", "WearableConfig", "measure_wearable"),
         "robot": ("bench.robot_cycle", "RobotConfig", "measure_robot")}
"""task -> (module, config dataclass, function); only the task's module is imported in the child."""
PRODUCT_FIRST = {"wearable": ("edge_runtime.wearable", "limit_blas_threads")}
"""task -> the product's process settings, applied before anything imports numpy as its command applies
them (``edge_runtime.wearable.limit_blas_threads``: OpenBLAS on one thread)."""


def run_child(task: str, config: dict, timeout_s: float = 900.0) -> dict:
    """Run ``task`` with ``config`` (the fields of its config dataclass) in a new Python process."""
    with tempfile.TemporaryDirectory(prefix="bench-") as tmp:
        cfg_path, out_path = Path(tmp) / "config.json", Path(tmp) / "out.json"
        cfg_path.write_text(json.dumps(config))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO_ROOT), env.get("PYTHONPATH")]))
        r = subprocess.run([sys.executable, "-m", "bench.worker", task, str(cfg_path), str(out_path)],
                           capture_output=True, text=True, env=env, timeout=timeout_s)
        if r.returncode != 0 or not out_path.exists():
            last = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise ChildFailed(f"bench.worker {task} {config.get('entry', '')}: exit {r.returncode}: {last}")
        return json.loads(out_path.read_text())


def main(argv: list[str]) -> int:
    task, cfg_path, out_path = argv
    module, cfg_name, func_name = TASKS[task]
    if task in PRODUCT_FIRST:
        package, setting = PRODUCT_FIRST[task]
        getattr(importlib.import_module(package), setting)()
    mod = importlib.import_module(module)
    result = getattr(mod, func_name)(getattr(mod, cfg_name)(**json.loads(Path(cfg_path).read_text())))
    Path(out_path).write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
