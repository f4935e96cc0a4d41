"""DBC files, loaded with cantools: the single source of truth for every frame the box sends
(``assets/vehicle_alerts.dbc``, ``assets/robot_link.dbc``)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from edge_runtime.canbus.bus import CanLinkError

if TYPE_CHECKING:
    import cantools


def load_dbc(path: str | Path) -> cantools.database.can.Database:
    """The DBC at ``path``; any parse error becomes one line (CanLinkError) naming the file."""
    import cantools  # here: cantools (which imports python-can) is loaded only by what parses a DBC

    try:
        return cantools.database.load_file(str(path))
    except Exception as exc:  # noqa: BLE001 - any parse error becomes one line
        raise CanLinkError(f"{path}: cannot load DBC: {exc}") from exc
