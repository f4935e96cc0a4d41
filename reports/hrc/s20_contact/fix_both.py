"""fix_predicted (the escape planned against everyone now and SHIFTS_S ahead) with ../s14_h110/fix_sphere (the
sweep rule per body part)."""
import importlib.util
from pathlib import Path


def _load(path):
    spec = importlib.util.spec_from_file_location(Path(path).stem, str(path))
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m


def apply(EV, **kw):
    here = Path(__file__).parent
    _load(here / "fix_predicted.py").apply(EV, **kw)
    _load(here.parent / "s14_h110" / "fix_sphere.py").apply(EV, **kw)
