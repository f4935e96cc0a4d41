"""What every ``python -m <package>`` tool shares: one-line errors, exit status 2.

A safety product's tools never answer bad input with a traceback: argparse
errors, and every exception type a command declares as "the user's input was
bad", become one line on stderr naming the file, line or field, and exit 2.
Anything else is a bug and keeps its traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Callable, Iterable

from edge_runtime.errors import BAD_INPUT, CliError, LinkError

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit status 2."""

    def error(self, message: str):  # noqa: D401 - argparse's signature
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_BAD_INPUT)


def make_parser(prog: str, description: str) -> tuple[OneLineParser, argparse._SubParsersAction]:
    """A parser with required subcommands that all report errors in one line."""
    parser = OneLineParser(prog=prog, description=description)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=OneLineParser)
    return parser, sub


def add_module_commands(sub: argparse._SubParsersAction, package: str,
                        commands: Iterable[tuple[str, str, str]]) -> None:
    """Subcommands that live in their own module of ``package``: (name, module, help) each.

    The module defines ``add_arguments(parser)``, ``cmd(args) -> int`` and optionally
    ``BAD_INPUT`` (exception types meaning "the user's input was bad"); they land in the
    parsed arguments as ``func`` and ``bad_input``."""
    for name, module, help_text in commands:
        mod = importlib.import_module(f".{module}", package)
        p = sub.add_parser(name, help=help_text)
        mod.add_arguments(p)
        p.set_defaults(func=mod.cmd, bad_input=tuple(getattr(mod, "BAD_INPUT", ())))


def run(func: Callable[[], int | None], bad_input: Iterable[type[BaseException]] = ()) -> int:
    """Run ``func``; exceptions in ``bad_input`` (and CliError) become one line + exit 2."""
    errors = (CliError, *bad_input)
    try:
        return int(func() or 0)
    except errors as e:
        print(f"error: {' '.join(str(e).split())}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def run_command(args: argparse.Namespace) -> int:
    """Run the subcommand ``args`` were parsed for (``args.func``, see :func:`add_module_commands`).

    One line and exit status 2 for the error tree's bad input (``errors.BAD_INPUT``), for
    the command's own ``BAD_INPUT``, and for a ``LinkError`` (a bus or line that cannot be
    opened is named in one line too, not shown as a traceback)."""
    return run(lambda: args.func(args), bad_input=(*BAD_INPUT, LinkError, *getattr(args, "bad_input", ())))


def _number(s: str, cast, what: str, ok) -> float:
    try:
        v = cast(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not {what}: {s!r}") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(f"must be {what}, got {s}")
    return v


def positive_float(s: str) -> float:
    """argparse type: a finite number > 0."""
    return _number(s, float, "a positive number", lambda v: 0 < v < float("inf"))


def positive_int(s: str) -> int:
    """argparse type: an integer >= 1."""
    return _number(s, int, "an integer of at least 1", lambda v: v >= 1)


def probability(s: str) -> float:
    """argparse type: a number in [0, 1]."""
    return _number(s, float, "a probability in [0, 1]", lambda v: 0.0 <= v <= 1.0)
