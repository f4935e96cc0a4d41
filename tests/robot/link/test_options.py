"""edge_runtime.robot.link.options: the bus options both ends' command lines declare."""
import argparse

import pytest

from edge_runtime.robot.link.options import BUS_OPTIONS, add_bus_arguments, tcp_port


def parser(**kw) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(exit_on_error=False)
    add_bus_arguments(p, **kw)
    return p


def test_config_overrides_default_to_none_and_leave_the_range_to_the_configuration():
    p = parser(config_section="robot_link")
    args = p.parse_args([])
    assert (args.can_interface, args.can_channel, args.can_host, args.can_port) == (None, None, None, None)
    args = p.parse_args(["--can-port", "70000", "--can-channel", "vcan1"])
    assert args.can_port == 70000 and args.can_channel == "vcan1"  # [robot_link] port says no, not argparse
    helps = {a.dest: a.help for a in p._actions if a.dest.startswith("can_")}
    assert helps["can_host"] == "socketcand hub address [robot_link] host" and len(helps) == len(BUS_OPTIONS)


def test_a_standalone_command_gets_defaults_its_own_channel_flag_and_a_checked_port():
    p = parser(defaults={"interface": "socketcand", "host": "127.0.0.1", "channel": "vcan0"}, channel_flag="--channel")
    args = p.parse_args(["--can-port", "29536"])
    assert (args.can_interface, args.channel, args.can_host, args.can_port) == ("socketcand", "vcan0", "127.0.0.1",
                                                                                 29536)
    with pytest.raises(argparse.ArgumentError, match="1..65535"):
        p.parse_args(["--can-port", "0"])
    with pytest.raises(argparse.ArgumentError, match="not a TCP port"):
        p.parse_args(["--can-port", "http"])
    assert tcp_port("65535") == 65535
