"""Session 17's hazard module (main 4e7d563), importable next to this tree's, for in-process A/B timing.

Written to /tmp/perfC/old/hazard_base.py from git (its [tracker]/[zones] section registrations dropped: the
config refuses a section declared twice) and imported as ``hazard_base``."""
import importlib.util
import subprocess
import sys
from pathlib import Path

BASE_COMMIT = "4e7d563"
PATH = Path("/tmp/perfC/old/hazard_base.py")


def load_base():
    if not PATH.exists():
        PATH.parent.mkdir(parents=True, exist_ok=True)
        text = subprocess.run(["git", "show", f"{BASE_COMMIT}:edge_runtime/robot/hazard.py"], check=True,
                              capture_output=True, text=True).stdout
        PATH.write_text(text.replace('@config.section("tracker")\n', "").replace('@config.section("zones")\n', ""))
    spec = importlib.util.spec_from_file_location("hazard_base", PATH)
    module = importlib.util.module_from_spec(spec)
    sys.modules["hazard_base"] = module
    spec.loader.exec_module(module)
    return module
