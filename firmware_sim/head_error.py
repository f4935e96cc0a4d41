"""Placeholder: being built this session (see the issue that owns it)."""
from edge_runtime.cli import CliError


def add_arguments(parser) -> None:
    pass


def cmd(args) -> int:
    raise CliError("this command is not built yet")
