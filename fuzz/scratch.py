"""One scratch file per target and process: the parsers under test read paths, not bytes."""
from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

_DIR: Path | None = None


def scratch_file(name: str, data: bytes) -> Path:
    """``data`` written to a file called ``name`` in this process's scratch directory."""
    global _DIR
    if _DIR is None:
        _DIR = Path(tempfile.mkdtemp(prefix="fuzz-"))
        atexit.register(shutil.rmtree, _DIR, True)
    path = _DIR / name
    path.write_bytes(data)
    return path
