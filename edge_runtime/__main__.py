"""``python -m edge_runtime <command>``: the programs that run on the box.

wearable   IMU -> detector -> ConvLSTM -> alert decisions on CAN (docs/design.md section 7)
lift       2D keypoints -> streaming pose lifter -> 3D joints
robot      camera keypoints -> lifter -> hazard zones -> commands to the arm (CAN or MAVLink)

This module is the command table only. Each command lives in its own module, which
defines ``add_arguments(parser)``, ``cmd(args) -> int`` and ``BAD_INPUT`` (the exception
types, beyond the error tree's, that mean "the user's input was bad"); error handling is
:func:`edge_runtime.cli.run_command`'s.
"""
from __future__ import annotations

import argparse
import sys

from edge_runtime.cli import add_module_commands, make_parser, run_command

COMMANDS = (
    ("wearable", "wearable.command", "run the wearable distraction loop"),
    ("lift", "robot.lift_command", "lift 2D keypoints (JSON lines, camera or simulator) to 3D joints"),
    ("robot", "robot.command", "the robot-side safety loop against a real or simulated arm"),
)
"""(name, module of this package, help), in the order ``--help`` lists them."""
EXTRAS = {"wearable": "serial-imu", "lift": "robot", "robot": "robot"}
"""The setup.cfg extra each command needs beyond the base install (the wearable only for a
serial IMU: a replay or a simulated IMU runs on the base install)."""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command table; with ``only`` (a command's name) that command alone, so that a run
    imports its own modules and not the other products' (the wearable's start-up does not pay
    for the robot's lifter, camera and link modules)."""
    parser, sub = make_parser("python -m edge_runtime", __doc__.splitlines()[0])
    add_module_commands(sub, __package__, [c for c in COMMANDS if only in (None, c[0])], EXTRAS)
    return parser


def load_all_sections() -> None:
    """Import every module of the runtime, so that every component declares its configuration
    section (for ``box.example.toml``; a command loads only the components it runs)."""
    import importlib
    import pkgutil

    import edge_runtime

    for info in pkgutil.walk_packages(edge_runtime.__path__, "edge_runtime."):
        if not info.name.endswith("__main__"):
            importlib.import_module(info.name)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    named = argv[0] if argv and argv[0] in {c[0] for c in COMMANDS} else None
    if named == "wearable":  # before anything imports numpy
        from edge_runtime.wearable import limit_blas_threads

        limit_blas_threads()
    return run_command(build_parser(named).parse_args(argv))


# Console entry points (setup.cfg, the bundle's wheel). One per product, beside the
# `edge-runtime` command table: a systemd unit's ExecStart and the journal's identifier
# (`journalctl -t edge-wearable`) then name the product, and neither can run the other's loop
# by a mistyped subcommand.
def wearable_main() -> int:
    return main(["wearable", *sys.argv[1:]])


def robot_main() -> int:
    return main(["robot", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
