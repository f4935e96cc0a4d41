"""Lost robot links: the hub vanishes and comes back, the controller's pty closes.

The runtime's end reports the outage (``link_ok`` false, ``stats.outages``), keeps
polling without raising, and reopens the transport with backoff.
"""
from __future__ import annotations

from support.robot import InProcessController, can_link, pump

from edge_runtime.robot.link.base import open_link
from firmware_sim.devices.can_hub import CanHub
from firmware_sim.robot.controller import SawyerProcess


def test_a_vanished_hub_is_reported_and_retried_until_it_is_back():
    hub = CanHub(port=0, seed=5).start()
    port = hub.port
    with InProcessController(hub) as ctl:
        link = can_link(hub)
        try:
            hub.stop()
            assert pump(link, 2.0, lambda: not link.link_ok)
            pump(link, 1.0)  # polling a dead link: no exception, retries with backoff
            assert link.stats.outages >= 1 and link.stats.send_errors > 0 and link.last_error
            assert link.stats.reconnects == 0
            hub = CanHub(port=port, seed=6).start()
            assert pump(link, 8.0, lambda: link.link_ok)
            assert link.stats.reconnects >= 1 and ctl.port.counters.get("reconnects", 0) >= 1
        finally:
            link.close()
            hub.stop()


def test_mavlink_link_reports_a_closed_pty_and_keeps_polling():
    with SawyerProcess("mavlink") as proc:
        link = open_link("mavlink", path=proc.endpoint)
        assert pump(link, 5.0, lambda: link.link_ok)
    try:
        assert pump(link, 2.0, lambda: not link.link_ok)
        pump(link, 0.5)
        assert link.stats.outages >= 1 and link.last_error
        assert link.stop() > 0  # commands on a dead link are counted, not raised
        assert link.stats.send_errors >= 1
    finally:
        link.close()
