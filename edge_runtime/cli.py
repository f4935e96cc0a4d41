"""What every ``python -m <package>`` tool shares: one-line errors, exit status 2.

A safety product's tools never answer bad input with a traceback: argparse
errors, and every exception type a command declares as "the user's input was
bad", become one line on stderr naming the file, line or field, and exit 2.
Anything else is a bug and keeps its traceback.
"""
from __future__ import annotations

import argparse
import sys
from typing import Callable, Iterable

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """Bad input found by a command itself; the message is the whole story."""


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
