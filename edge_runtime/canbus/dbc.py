"""DBC files, loaded with cantools: the single source of truth for every frame the box sends
(``assets/vehicle_alerts.dbc``, ``assets/robot_link.dbc``)."""
from __future__ import annotations

from pathlib import Path

import cantools

from edge_runtime.canbus.bus import CanLinkError


def load_dbc(path: str | Path) -> cantools.database.can.Database:
    """The DBC at ``path``; any parse error becomes one line (CanLinkError) naming the file."""
    try:
        return cantools.database.load_file(str(path))
    except Exception as exc:  # noqa: BLE001 - any parse error becomes one line
        raise CanLinkError(f"{path}: cannot load DBC: {exc}") from exc
